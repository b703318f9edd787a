// Error and size targets: see jobs/targets.h.
#include "jobs/targets.h"

#include <algorithm>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <map>
#include <string>

#include "engine/quantize.h"
#include "jobs/cleanup.h"
#include "jobs/file_io.h"
#include "spatial/surface_index.h"

namespace scanpress {
namespace {

namespace fs = std::filesystem;

// The coarsest global knob a size target tries, in grid cells: a deviation of the whole grid's extent is as far as
// any simplification can go.
double maxKnobCells(int bits) { return std::ldexp(1.0, bits); }

std::string number(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", x);
  return buf;
}

double errorOf(const EncodeResult& r, ErrorMetric metric) {
  if (!r.measured || r.diagonal <= 0) return -1;
  const ErrorStats sym = symmetricOf(statsOf(r.forward), statsOf(r.backward));
  return (metric == ErrorMetric::kMax ? sym.max : sym.rms) / r.diagonal;
}

class TargetSearch {
 public:
  TargetSearch(const EncodeSettings& s, ProgressListener* progress, std::shared_ptr<EmbreeDevice> device,
               const PipelineHooks* hooks)
      : s_(s), progress_(progress), device_(std::move(device)), hooks_(hooks) {
    report_.target = s.target;
    const CodecInfo* codec = findCodec(s.codec);
    knob_ = (hooks && hooks->knob_stage) || (codec && errorKnobOf(codec->id));
  }

  Result<EncodeResult> run() {
    Status st = s_.target.kind == TargetKind::kMaxError ? searchError() : searchSize();
    if (!st.isOk()) {
      removeAll();
      return st;
    }
    return finish();
  }

  // For auto: the kept container stays under its tracked temporary name (kept()) instead of being renamed into
  // place; the caller renames or removes it.
  void keepInPlace() { keep_in_place_ = true; }
  struct Kept {
    std::string path;  // empty: nothing was kept
    uint64_t tracked = 0;
  };
  const Kept& kept() const { return kept_; }

 private:
  struct Pass {
    Status status;  // a setting the pipeline refuses (kLimitExceeded: degenerate triangles) counts as a miss
    EncodeResult result;
    std::string path;
    uint64_t tracked = 0;  // cleanup registration of the pass's container
    bool met = false;
  };

  // One encode at `bits` and the knob settings, into its own temporary container.
  Result<Pass*> pass(int bits, double tile_error, double knob_cells, bool measure) {
    EncodeSettings p = s_;
    p.target = EncodeTarget{};
    p.bits = bits;
    p.tile_error = tile_error;
    p.tile_metric = s_.target.metric;
    p.knob_cells = knob_cells;
    p.measure.enabled = measure;
    // Under an error target, triangles that quantization makes degenerate (zero area at these bits) may be dropped:
    // the measured error of the result, which the target bounds, accounts for them, and the report counts them.
    // Refusing such bits kept the horse at 11 bits for a 2e-4 RMS target that 10 bits meets.
    if (s_.target.kind == TargetKind::kMaxError) p.allow_degenerate = true;
    // Named as AtomicFile names its temporaries (`.NAME.tmp-PID-N`), so that the next job run in the directory
    // removes them after a SIGKILL (removeStaleTemporaries), and tracked, so that SIGINT's cleanup removes them.
    const fs::path target(s_.output);
    std::string name = ".";  // appended piecewise: GCC 12 warns (-Wrestrict) on "." + std::string
    name += target.filename().string();
    name += ".";
    name += s_.codec;  // distinct per codec: --codec auto keeps one search's result while the next runs
    name += ".target";
    name += std::to_string(passes_.size());
    name += ".tmp-";
    name += std::to_string(::getpid());
    name += "-";
    name += std::to_string(passes_.size());
    p.output = (target.has_parent_path() ? target.parent_path() / name : fs::path(name)).string();
    auto r = encodeFileOnce(p, progress_, device_, hooks_);
    Pass& out = passes_.emplace_back();
    out.path = p.output;
    if (r.isOk()) out.tracked = createTracked(TrackedKind::kFile, [&] { return out.path; });
    if (!r.isOk()) {
      if (r.status().code() != ErrorCode::kLimitExceeded) return r.status();
      out.status = r.status();
    } else {
      out.result = std::move(r).value();
    }
    TargetAttempt a;
    a.codec = s_.codec;
    a.bits = bits;
    a.knob_cells = knob_cells;
    if (out.status.isOk()) {
      a.bytes = out.result.bytes;
      a.vertices = out.result.vertices;
      a.error = errorOf(out.result, s_.target.metric);
      out.met = meets(out.result);
    }
    a.met = out.met;
    if (!out.status.isOk()) a.refused = out.status.message();
    report_.attempts.push_back(a);
    return &out;
  }

  bool meets(const EncodeResult& r) const {
    if (r.failed_tiles > 0) return false;
    switch (s_.target.kind) {
      case TargetKind::kMaxError: {
        const double e = errorOf(r, s_.target.metric);
        if (e < 0 || e > (1 - measureMargin(s_.target.metric)) * s_.target.max_error) return false;
        for (const TileReport& t : r.tiles)
          if (!t.target_met) return false;
        return true;
      }
      case TargetKind::kMaxBytes: return r.bytes <= s_.target.max_bytes;
      case TargetKind::kBitsPerVertex: return r.bitsPerVertex() <= s_.target.bpv;
      case TargetKind::kNone: return true;
    }
    return false;
  }

  // Error target. The first pass assumes the worst box shape (extent = diagonal); its result gives the real ratio,
  // and the prediction is redone before stepping, so a cube-like scan does not pay for the guess with a pass per
  // bit.
  Status searchError() {
    const double e = s_.target.max_error;
    const double share = knob_ ? kKnobQuantizationShare : 1.0;
    const double tile_error = knob_ ? (1 - measureMargin(s_.target.metric)) * e : 0;
    if (!device_) {  // one device for every pass
      SP_ASSIGN_OR_RETURN(device_, EmbreeDevice::create());
    }
    int bits = s_.target.fixed_bits ? s_.bits : predictBits(e, s_.target.metric, 1.0, share);
    SP_ASSIGN_OR_RETURN(Pass * p, pass(bits, tile_error, -1, true));
    if (p->status.isOk() && !p->result.measured)  // a point cloud: no surface to measure (jobs/measure.h)
      return makeError(ErrorCode::kUnsupported, s_.input +
                                                    ": an error target (--max-error, /codec/target/max_error) needs "
                                                    "triangles to measure; this scan is a point cloud");
    if (s_.target.fixed_bits) {
      chosen_ = p;
      return Status::ok();
    }
    if (p->status.isOk() && p->result.diagonal > 0) {
      const double ratio = p->result.grid.cell * std::ldexp(1.0, bits) / p->result.diagonal;
      const int better = predictBits(e, s_.target.metric, ratio, share);
      if (p->met && better < bits) {
        best_ = p;
        bits = better;
        SP_ASSIGN_OR_RETURN(p, pass(bits, tile_error, -1, true));
      }
    }
    if (p->met) {
      best_ = p;
      // Fewer bits while they still meet the target. A lossless codec: the fewest that do. A codec with a knob:
      // fewer bits leave less of the budget to the simplification, so the bytes have a minimum over the bits (the
      // prediction's share is a starting point: under the max metric, or where the codec's fine levels cost more
      // than the bits they save, fewer bits win); a bit fewer is kept while it is smaller.
      while (bits > kMinGridBits) {
        SP_ASSIGN_OR_RETURN(Pass * q, pass(bits - 1, tile_error, -1, true));
        if (!q->met || (knob_ && q->result.bytes >= best_->result.bytes)) break;
        best_ = q;
        --bits;
      }
    } else {
      while (!p->met && bits < kMaxGridBits) {
        if (p->status.isOk() && p->result.failed_tiles > 0) break;  // a tile failed: not a question of bits
        if (best_ && best_->result.grid.bits == bits + 1) {         // the first pass, before the jump down
          p = best_;
          break;
        }
        SP_ASSIGN_OR_RETURN(p, pass(++bits, tile_error, -1, true));
      }
      if (p->met) best_ = p;
    }
    chosen_ = best_ ? best_ : p;
    return Status::ok();
  }

  // Size target: the finest setting that fits (the least error), assuming the bytes grow with the bits and shrink
  // with the knob.
  Status searchSize() {
    const bool measure = s_.measure.enabled;
    if (knob_) return searchSizeKnob(measure);
    if (s_.target.fixed_bits) {
      SP_ASSIGN_OR_RETURN(chosen_, pass(s_.bits, 0, -1, measure));
      return Status::ok();
    }
    // Bisection over the bits: `fit` fits, `over` does not (sentinels outside the range are not encoded).
    std::map<int, Pass*> at;
    int fit = kMinGridBits - 1, over = kMaxGridBits + 1;
    int bits = std::clamp(s_.bits, kMinGridBits, kMaxGridBits);
    while (over - fit > 1) {
      SP_ASSIGN_OR_RETURN(Pass * p, pass(bits, 0, -1, measure));
      if (p->status.isOk() && p->result.failed_tiles > 0) return chosen_ = p, Status::ok();
      at[bits] = p;
      (p->met ? fit : over) = bits;
      bits = (fit + over) / 2;
    }
    chosen_ = fit >= kMinGridBits ? at[fit] : at[kMinGridBits];
    if (fit >= kMinGridBits) best_ = chosen_;
    return Status::ok();
  }

  // One global knob t for every tile, at the bits as set: t = 0 first (the least error); then t grows by 4x until
  // a pass fits (or t reaches the coarsest, the whole grid); then bisection in the log of t between the largest t
  // that did not fit and the smallest that did, kSizeBisections passes. The smallest t that fit is kept.
  Status searchSizeKnob(bool measure) {
    constexpr int kSizeBisections = 6;
    const int bits = s_.bits;
    SP_ASSIGN_OR_RETURN(Pass * p, pass(bits, 0, 0, measure));
    if (p->met) return chosen_ = best_ = p, Status::ok();
    double over = 0, fit = -1;
    for (double t = 1; t <= maxKnobCells(bits); t *= 4) {
      SP_ASSIGN_OR_RETURN(p, pass(bits, 0, t, measure));
      if (p->met) {
        fit = t;
        best_ = p;
        break;
      }
      over = t;
    }
    if (fit < 0) return chosen_ = p, Status::ok();
    for (int i = 0; i < kSizeBisections && fit > 1.05 * over; ++i) {
      const double t = over > 0 ? std::sqrt(over * fit) : fit / 2;
      SP_ASSIGN_OR_RETURN(p, pass(bits, 0, t, measure));
      if (p->met) {
        fit = t;
        best_ = p;
      } else {
        over = t;
      }
    }
    chosen_ = best_;
    report_.knob_cells = fit;
    return Status::ok();
  }

  void remove(const Pass& p) {
    std::error_code ec;
    fs::remove(p.path, ec);
    untrack(p.tracked);
  }
  void removeAll() {
    for (const Pass& p : passes_) remove(p);
  }

  // Moves the chosen pass's container into place and fills the report; a miss removes every container.
  Result<EncodeResult> finish() {
    if (!chosen_->status.isOk()) {
      removeAll();
      return missed(chosen_->status.message());
    }
    EncodeResult result = std::move(chosen_->result);
    const bool met = chosen_->met;
    std::error_code ec;
    for (const Pass& p : passes_)
      if (&p != chosen_ || !(met || result.failed_tiles > 0)) remove(p);
    if ((met || result.failed_tiles > 0) && keep_in_place_) {
      kept_ = {chosen_->path, chosen_->tracked};
    } else if (met || result.failed_tiles > 0) {  // failed tiles: the container is kept, as without a target
      fs::rename(chosen_->path, s_.output, ec);
      untrack(chosen_->tracked);
      if (ec)
        return makeError(ErrorCode::kIo, s_.output + ": cannot rename the chosen pass into place: " + ec.message());
    }
    report_.bits = result.grid.bits;
    report_.met = met;
    report_.error = errorOf(result, s_.target.metric);
    if (knob_ && s_.target.kind == TargetKind::kMaxError)
      report_.tile_error = (1 - measureMargin(s_.target.metric)) * s_.target.max_error * result.diagonal;
    if (s_.target.kind == TargetKind::kMaxError)
      for (TileReport& t : result.tiles) {
        const ErrorStats sym = symmetricOf(t.forward, t.backward);
        const double e = s_.target.metric == ErrorMetric::kMax ? sym.max : sym.rms;
        t.target_met = t.target_met && result.diagonal > 0 && e <= s_.target.max_error * result.diagonal;
      }
    if (!met && result.failed_tiles == 0) report_.status = missStatus(result);
    result.target = report_;
    return result;
  }

  Status missStatus(const EncodeResult& r) const {
    const EncodeTarget& t = s_.target;
    const std::string where = " at " + std::to_string(r.grid.bits) + " bits" +
                              (s_.target.fixed_bits ? " (fixed by --bits, /codec/bits)" : "");
    std::string msg = s_.input + ": target not met: ";
    switch (t.kind) {
      case TargetKind::kMaxError:
        msg += std::string("--max-error ") + number(t.max_error) + " (/codec/target/max_error; " +
               errorMetricName(t.metric) + ", relative to the diagonal): achieved " + number(errorOf(r, t.metric)) +
               where;
        if (!t.fixed_bits && r.grid.bits >= kMaxGridBits) msg += ", the finest grid";
        msg += " (accepted: at most " + number((1 - measureMargin(t.metric)) * t.max_error) +
               ", a margin for the sampled measurement)";
        break;
      case TargetKind::kMaxBytes:
        msg += "--max-bytes " + std::to_string(t.max_bytes) +
               " (/codec/target/max_bytes): the coarsest setting needs " + std::to_string(r.bytes) + " bytes" + where;
        break;
      case TargetKind::kBitsPerVertex:
        msg += "--bpv " + number(t.bpv) + " (/codec/target/bpv): the coarsest setting needs " +
               number(r.bitsPerVertex()) + " bpv" + where;
        break;
      case TargetKind::kNone: break;
    }
    if (knob_ && t.kind != TargetKind::kMaxError) msg += " and the coarsest knob";
    return makeError(ErrorCode::kLimitExceeded, msg + "; the container was not written");
  }

  Result<EncodeResult> missed(const std::string& why) const {
    return makeError(ErrorCode::kLimitExceeded, s_.input + ": target not met: no setting could be encoded (" + why +
                                                    "); the container was not written");
  }

  const EncodeSettings& s_;
  ProgressListener* progress_;
  std::shared_ptr<EmbreeDevice> device_;
  const PipelineHooks* hooks_;
  bool knob_ = false;
  bool keep_in_place_ = false;
  Kept kept_;
  std::deque<Pass> passes_;  // stable addresses
  Pass* chosen_ = nullptr;   // the pass reported (and kept when met)
  Pass* best_ = nullptr;     // the pass that meets the target at the finest setting (or fewest bits)
  TargetReport report_;
};

}  // namespace

double measureMargin(ErrorMetric metric) { return metric == ErrorMetric::kMax ? 0.12 : 0.02; }

int predictBits(double max_error, ErrorMetric metric, double extent_over_diagonal, double share) {
  // RMS: a surface sample's displacement blends its triangle's three independent vertex displacements with its
  // barycentric weights, and the mean of sum(b_i^2) over a triangle is 1/2: cell/sqrt(24). (Measured on
  // bun_zipper at 11 bits: 6.20e-5 of the diagonal, predicted 6.2e-5.) Max: vertices are samples, so a vertex's
  // worst case, half the cell's diagonal.
  const double per_cell = metric == ErrorMetric::kMax ? std::sqrt(3.0) / 2 : 1 / std::sqrt(24.0);
  // cell = extent / 2^bits = ratio * diagonal / 2^bits; want per_cell * cell <= share * max_error * diagonal.
  const double need = std::log2(per_cell * extent_over_diagonal / (share * max_error));
  if (!std::isfinite(need)) return kMaxGridBits;
  return std::clamp(static_cast<int>(std::ceil(need - 1e-9)), kMinGridBits, kMaxGridBits);
}

namespace {

// --codec auto under a target: the search for each candidate codec, then the better result that meets the target
// (an error target: the fewest bytes; a size target: the least RMS error, so both are measured). Each search keeps
// its result under its tracked temporary name until one is chosen; every attempt is in the report.
Result<EncodeResult> encodeToTargetAuto(const EncodeSettings& settings, ProgressListener* progress,
                                        std::shared_ptr<EmbreeDevice> device, const PipelineHooks* hooks) {
  if (!device) {
    SP_ASSIGN_OR_RETURN(device, EmbreeDevice::create());
  }
  struct Candidate {
    EncodeResult result;
    TargetSearch::Kept kept;
  };
  std::vector<Candidate> done;
  auto discard = [](const TargetSearch::Kept& k) {
    std::error_code ec;
    if (!k.path.empty()) fs::remove(k.path, ec);
    untrack(k.tracked);
  };
  std::vector<TargetAttempt> attempts;
  for (const char* codec : {"pm", "edgebreaker"}) {
    EncodeSettings c = settings;
    c.codec = codec;
    if (settings.target.kind != TargetKind::kMaxError) c.measure.enabled = true;
    TargetSearch search(c, progress, device, hooks);
    search.keepInPlace();
    auto r = search.run();
    // Under strict, a codec that refuses what it would drop leaves the other alone to compete (pm keeps texture
    // coordinates and corner normals since its version 5, so this is a safeguard).
    if (!r.isOk() && settings.strict && r.status().code() == ErrorCode::kUnsupported && c.codec == "pm") continue;
    if (!r.isOk()) {
      for (auto& d : done) discard(d.kept);
      return r.status();
    }
    if (r->target) attempts.insert(attempts.end(), r->target->attempts.begin(), r->target->attempts.end());
    done.push_back({std::move(r).value(), search.kept()});
  }
  auto metOf = [](const Candidate& c) { return c.result.target && c.result.target->met; };
  auto better = [&](const Candidate& a, const Candidate& b) {  // a is better than b
    if (metOf(a) != metOf(b)) return metOf(a);
    // Of two that meet the target, the one that keeps more scalar channels wins whatever the sizes, then the one
    // whose read dropped less (a count of entries: an OBJ read with wedges may list other `vt` records than the one
    // entry a read without them lists, so the channels come first). Both keep what the other keeps today (pm
    // before its version 5 dropped texture coordinates and corner normals); the rule stays for codecs that drop.
    if (a.result.layout.scalars.size() != b.result.layout.scalars.size())
      return a.result.layout.scalars.size() > b.result.layout.scalars.size();
    if (a.result.read.dropped.size() != b.result.read.dropped.size())
      return a.result.read.dropped.size() < b.result.read.dropped.size();
    if (settings.target.kind == TargetKind::kMaxError) return a.result.bytes < b.result.bytes;
    return errorOf(a.result, ErrorMetric::kRms) < errorOf(b.result, ErrorMetric::kRms);
  };
  size_t best = 0;
  for (size_t i = 1; i < done.size(); ++i)
    if (better(done[i], done[best])) best = i;
  if (!metOf(done[best])) best = done.size() - 1;  // none met: the lossless codec's miss names the finest grid
  for (size_t i = 0; i < done.size(); ++i)
    if (i != best) discard(done[i].kept);
  Candidate& chosen = done[best];
  if (!chosen.kept.path.empty()) {
    std::error_code ec;
    fs::rename(chosen.kept.path, settings.output, ec);
    untrack(chosen.kept.tracked);
    if (ec) {
      fs::remove(chosen.kept.path, ec);
      return makeError(ErrorCode::kIo, settings.output + ": cannot rename the chosen result into place");
    }
  }
  EncodeResult result = std::move(chosen.result);
  if (result.target) result.target->attempts = std::move(attempts);
  return result;
}

}  // namespace

Result<EncodeResult> encodeToTarget(const EncodeSettings& settings, ProgressListener* progress,
                                    std::shared_ptr<EmbreeDevice> device, const PipelineHooks* hooks) {
  // The passes write temporaries next to the output, which the pipeline's own check cannot relate to the input:
  // `encode X X --max-error E` must not replace X when the chosen pass is renamed into place.
  SP_RETURN_IF_ERROR(checkOutputPath(settings.output, {settings.input}));
  if (settings.codec == kAutoCodec) return encodeToTargetAuto(settings, progress, std::move(device), hooks);
  return TargetSearch(settings, progress, std::move(device), hooks).run();
}

}  // namespace scanpress
