// One tile's work: see jobs/tile_work.h.
#include "jobs/tile_work.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include "engine/stages/stage.h"
#include "jobs/errors.h"
#include "jobs/measure.h"
#include "spatial/surface_index.h"

namespace scanpress {

namespace {
#ifdef NDEBUG
constexpr bool kDebugBuild = false;
#else
constexpr bool kDebugBuild = true;
#endif
}  // namespace

TileEncoder::TileEncoder(const EncodeSettings& settings, const CodecInfo& codec, const TileScanFacts& scan,
                         std::shared_ptr<EmbreeDevice> device, const PipelineHooks* hooks)
    : s_(settings), codec_(codec), scan_(scan), device_(std::move(device)), hooks_(hooks) {}

TileResult tileAsBuilt(const TileMesh& tm, Status status) {
  TileResult r;
  r.tile = tm.tile_id;
  r.status = std::move(status);
  r.input_vertices = static_cast<uint32_t>(tm.mesh.positions.size());
  r.input_faces = static_cast<uint32_t>(tm.mesh.triangles.size());
  r.border = static_cast<uint32_t>(std::count(tm.border.begin(), tm.border.end(), 1));
  return r;
}

TileResult TileEncoder::run(const TileMesh& tm, const std::vector<Vec3d>& originals) const {
  TileResult r = tileAsBuilt(tm);
  try {
    r.status = encodeTile(tm, originals, r);
  } catch (...) {
    r.status = statusFromException();
  }
  if (!r.status.isOk()) r.encoded = EncodedTile{};
  return r;
}

// Measures one tile: its original triangles against the decoded tile, both ways. Near tile borders the other
// tile's surface is not considered, which can only make a distance larger (never hide an error).
Status TileEncoder::measureTile(const TileContext& ctx, const TileMesh& tm, const std::vector<Vec3d>& originals,
                                TileResult& r) const {
  SP_ASSIGN_OR_RETURN(QuantizedMesh decoded_q, codec_.decode(ctx, payloadVersion(codec_, r.encoded), r.encoded.payload,
                                                             limitsOf(r.encoded.decoded)));
  std::vector<Vec3d> decoded(decoded_q.positions.size());
  for (size_t i = 0; i < decoded.size(); ++i) {
    decoded[i] = scan_.grid.dequantize(decoded_q.positions[i]);
    for (int a = 0; a < 3; ++a) decoded[i][a] -= scan_.grid.origin[a];  // same frame as the originals
  }
  return measureSurfaces(originals, tm.mesh.triangles, decoded, decoded_q.triangles, s_.measure, scan_.density,
                         2 * uint64_t(tm.tile_id), device_, r.forward, r.backward);
}

// The stages in order, each checked against the border contract; then the codec; then the measurement.
Status TileEncoder::encodeTile(const TileMesh& tm, const std::vector<Vec3d>& originals, TileResult& r) const {
  const TileContext ctx{scan_.grid.bits, scan_.layout};
  if (hooks_ && hooks_->fail_tile) SP_RETURN_IF_ERROR(hooks_->fail_tile(tm.tile_id));
  const bool thorough = kDebugBuild || hooks_ != nullptr;
  // The tile as the next stage sees it: the built tile, then each stage's output.
  std::optional<StagedTile> staged;
  auto view = [&] { return staged ? staged->view() : TileView{tm.mesh, tm.border}; };
  for (const StageSpec& spec : s_.stages) {
    SP_ASSIGN_OR_RETURN(StagedTile next, runStage(ctx, view(), spec, thorough));
    staged = std::move(next);
  }
  if (hooks_ && hooks_->extra_stage) {
    SP_ASSIGN_OR_RETURN(StagedTile next, hooks_->extra_stage(ctx, view(), tm.tile_id));
    SP_RETURN_IF_ERROR(checkBorderContract(ctx, view(), next.view(), true).withContext("test stage"));
    staged = std::move(next);
  }
  const bool knob = (hooks_ && hooks_->knob_stage) || errorKnobOf(codec_.id);
  if (knob && s_.tile_error > 0 && scan_.measured) return searchKnob(ctx, view(), tm, originals, r);
  SP_RETURN_IF_ERROR(encodeAt(ctx, view(), knob ? s_.knob_cells : -1, r));
  if (scan_.measured)  // decode in memory, measure against the original triangles, discard
    SP_RETURN_IF_ERROR(measureTile(ctx, tm, originals, r));
  return Status::ok();
}

// The codec's encode with its error knob at `cells` grid cells (< 0: the knob as configured).
Status TileEncoder::encodeAt(const TileContext& ctx, const TileView& tile, double cells, TileResult& r) const {
  CodecOptions options = s_.codec_options;
  r.knob_cells = cells;
  if (cells < 0) {
    SP_ASSIGN_OR_RETURN(r.encoded, codec_.encode(ctx, tile, options));
    return Status::ok();
  }
  if (hooks_ && hooks_->knob_stage) {
    SP_ASSIGN_OR_RETURN(StagedTile lossy, hooks_->knob_stage(ctx, tile, cells));
    SP_RETURN_IF_ERROR(checkBorderContract(ctx, tile, lossy.view(), true).withContext("test knob stage"));
    SP_ASSIGN_OR_RETURN(r.encoded, codec_.encode(ctx, lossy.view(), options));
    return Status::ok();
  }
  errorKnobOf(codec_.id)(options, cells);
  SP_ASSIGN_OR_RETURN(r.encoded, codec_.encode(ctx, tile, options));
  return Status::ok();
}

// The measured error of the tile as encoded in `r`, in the per-tile target's metric (absolute units).
double TileEncoder::tileError(const TileResult& r) const {
  const ErrorStats sym = symmetricOf(statsOf(r.forward), statsOf(r.backward));
  return s_.tile_metric == ErrorMetric::kMax ? sym.max : sym.rms;
}

// The per-tile knob search: the largest knob t (grid cells) whose decoded tile, measured against the tile's
// original triangles, stays within s_.tile_error. Each trial is a full encode, decode and measurement, so the
// error is the codec's real error, not its own estimate.
//
// t = 0 (no simplification) is the floor: its error is the quantization's, which the bits were chosen to keep
// well inside the target. The first trial is a prediction: the target in grid cells (for RMS twice that, as a
// simplification's RMS is well below its bound on the worst point). Then a bracket: while the trial meets the
// target, t doubles (the error grows with t, roughly in proportion, so doubling finds the failing side in a
// trial or two); once a trial misses, bisection between the largest t that met and the smallest that missed (in
// the log of t, since t spans orders of magnitude). kKnobTrials encodes in all; the tile keeps the encoding of
// the largest t that met. (prm keeps the smaller of the tile as it is and its remeshing, so a small t, a lattice
// finer than the tile, cannot make it larger than t = 0.) The error need not be monotone in t: only trials that
// were measured to meet are kept, so a non-monotone codec can cost bytes, never the target.
//
// Per-tile bounds imply the overall one: the overall RMS is the area-weighted mean of the tiles' squared
// errors (each side samples by area, and the tiles partition the original's triangles and the decoded ones),
// so RMS <= E in every tile gives RMS <= E overall. The overall max is the max over the tiles' samples; a tile's
// measurement ignores its neighbours' surfaces, which can only make a distance near a border larger, and the
// border vertices are locked (never moved), so max <= E in every tile gives max <= E overall.
Status TileEncoder::searchKnob(const TileContext& ctx, const TileView& tile, const TileMesh& tm,
                               const std::vector<Vec3d>& originals, TileResult& r) const {
  constexpr uint32_t kKnobTrials = 7;
  const double target = s_.tile_error * scan_.diagonal;
  const double target_cells = target / scan_.grid.cell;
  auto trial = [&](double t, TileResult& out) -> Status {
    out.forward = ErrorAccumulator();
    out.backward = ErrorAccumulator();
    SP_RETURN_IF_ERROR(encodeAt(ctx, tile, t, out));
    ++r.knob_trials;
    return measureTile(ctx, tm, originals, out);
  };
  // The floor first: when even t = 0 misses, the bits are too coarse and the tile reports it (the target search
  // adds a bit).
  SP_RETURN_IF_ERROR(trial(0, r));
  if (tileError(r) > target) {
    r.target_met = false;
    return Status::ok();
  }
  double met = 0, missed = -1;  // largest t that met; smallest t that missed (< 0: none yet)
  double t = s_.tile_metric == ErrorMetric::kRms ? 2 * target_cells : target_cells;
  for (uint32_t i = 1; i < kKnobTrials && t > 0; ++i) {
    TileResult attempt;
    attempt.tile = r.tile;
    SP_RETURN_IF_ERROR(trial(t, attempt));
    if (tileError(attempt) <= target) {
      met = t;
      r.encoded = std::move(attempt.encoded);
      r.forward = attempt.forward;
      r.backward = attempt.backward;
      r.knob_cells = t;
    } else {
      missed = t;
    }
    t = missed < 0 ? 2 * met : met > 0 ? std::sqrt(met * missed) : missed / 4;
    // Within 5% of each other the bracket has converged: another trial would not change the bytes much.
    if (missed > 0 && met > 0 && missed < 1.05 * met) break;
  }
  return Status::ok();
}

}  // namespace scanpress
