#include "jobs/batch.h"

#include <fnmatch.h>
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <set>

#include "jobs/container_file.h"
#include "jobs/errors.h"
#include "jobs/file_io.h"
#include "jobs/html_report.h"
#include "jobs/numbers.h"
#include "jobs/progress.h"
#include "jobs/render.h"
#include "jobs/report.h"
#include "spatial/surface_index.h"

namespace scanpress {
namespace {

namespace fs = std::filesystem;

constexpr const char* kErrorPictureName = "{stem}.error.png";  // with /measure/render

bool isMeshFile(const fs::path& p) { return formatFromName(p.filename().string()) != MeshFormat::kUnknown; }

bool hasWildcard(const std::string& s) { return s.find_first_of("*?[") != std::string::npos; }

Status writeText(const std::string& path, const std::string& text) {
  return writeFileAtomically(path, std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
}

uint64_t fnv1a(const std::string& s) {
  uint64_t h = 0xcbf29ce484222325ull;
  for (unsigned char c : s) h = (h ^ c) * 0x100000001b3ull;
  return h;
}

// The decoded scan (from the container just written) colored by its distance to the original: whole meshes in
// memory, or a chunk at a time when they would need more than the job's memory budget.
Status renderErrorPicture(const EncodeSettings& s, const std::string& png, std::shared_ptr<EmbreeDevice> device) {
  RenderSettings rs;
  rs.width = s.measure.render_width;
  rs.height = s.measure.render_height;
  rs.azimuth = s.measure.view_azimuth;
  rs.elevation = s.measure.view_elevation;
  rs.scale_max_relative = s.measure.scale_max;
  rs.title = std::filesystem::path(s.input).filename().string();
  const uint64_t budget = s.memory_budget;
  if (budget > 0 && inMemorySurfaceBytes(s.input) + inMemorySurfaceBytes(s.output) > budget) {
    SP_ASSIGN_OR_RETURN(ChunkedSurface original, openSurface(s.input, budget, s.scratch_dir));
    SP_ASSIGN_OR_RETURN(ChunkedSurface decoded, openSurface(s.output, budget, s.scratch_dir));
    SP_ASSIGN_OR_RETURN(RenderResult picture, renderSurface(decoded, rs, device, &original, surfaceCacheBytes(budget)));
    return writePng(png, picture.image);
  }
  SP_ASSIGN_OR_RETURN(Mesh original, readMeshFile(s.input, nullptr, ReadOptions::asInFile()));
  SP_ASSIGN_OR_RETURN(Mesh decoded, readSurfaceFile(s.output));
  SP_ASSIGN_OR_RETURN(RenderResult picture, renderMesh(decoded, rs, device, &original));
  return writePng(png, picture.image);
}

// Refuses a job whose outputs would destroy something, before anything is written: an output (container,
// report, error picture, summary) that is one of the inputs (by path, or by device and inode: hard links,
// symlinks), that another output of the job writes too, or that exists as a FIFO, device or socket. The error
// names the JSON pointer of the name that makes the output (exit 1).
Status checkJobOutputs(const JobSettings& job, const std::vector<JobInput>& inputs) {
  const std::string where = job.config_path.empty() ? "" : job.config_path + ": ";
  auto canonical = [](const std::string& p) {
    std::error_code ec;
    const fs::path c = fs::weakly_canonical(fs::absolute(p, ec), ec);
    return ec ? fs::path(p).lexically_normal().string() : c.string();
  };
  std::map<std::string, std::string> input_paths;            // canonical path -> input
  std::map<std::pair<dev_t, ino_t>, std::string> input_ids;  // existing inputs' identities -> input
  for (const auto& [in, in_dir] : inputs) {
    input_paths.emplace(canonical(in), in);
    struct stat st {};
    if (::stat(in.c_str(), &st) == 0) input_ids.emplace(std::make_pair(st.st_dev, st.st_ino), in);
  }
  std::map<std::string, std::string> written;  // canonical path -> pointer of the name that writes it
  auto plan = [&](const std::string& path, const std::string& pointer) -> Status {
    const std::string c = canonical(path);
    std::string input;
    if (auto it = input_paths.find(c); it != input_paths.end()) input = it->second;
    struct stat st {};
    if (input.empty() && ::stat(path.c_str(), &st) == 0)
      if (auto it = input_ids.find({st.st_dev, st.st_ino}); it != input_ids.end()) input = it->second;
    if (!input.empty())
      return makeError(ErrorCode::kInvalidArgument, where + pointer + ": the output '" + path + "' is the input '" +
                                                        input + "'; refusing to overwrite it");
    if (auto [it, fresh] = written.emplace(c, pointer); !fresh)
      return makeError(ErrorCode::kInvalidArgument,
                       where + pointer + ": " +
                           (it->second == pointer ? std::string("two inputs map to the output '")
                                                  : "writes the same file as " + it->second + ": '") +
                           path + "'");
    const Status kind = checkOutputPath(path, {});
    return kind.isOk() ? kind : Status(kind.code(), where + pointer + ": " + kind.message());
  };
  const fs::path dir(job.output_directory);
  for (const auto& [in, sub] : inputs) {
    SP_RETURN_IF_ERROR(plan((dir / outputName(job.output_name, in, sub)).string(), "/output/name"));
    if (!job.report_name.empty())
      SP_RETURN_IF_ERROR(plan((dir / outputName(job.report_name, in, sub)).string(), "/output/report"));
    if (job.encode.measure.enabled && job.encode.measure.render)
      SP_RETURN_IF_ERROR(plan((dir / outputName(kErrorPictureName, in, sub)).string(), "/measure/render"));
  }
  if (!job.summary_name.empty()) SP_RETURN_IF_ERROR(plan((dir / job.summary_name).string(), "/output/summary"));
  if (!job.html_name.empty()) SP_RETURN_IF_ERROR(plan((dir / job.html_name).string(), "/output/html"));
  return Status::ok();
}

// Whether resume may trust the container at `path`: it opens (header, footer, index and their checksums) and
// every tile chunk matches its checksums. Not a full decode: that would cost as much as encoding again.
bool verifiedContainer(const std::string& path) {
  auto file = ContainerFile::open(path);
  return file.isOk() && file->verifyChecksums().isOk();
}

}  // namespace

int BatchResult::exitCode() const {
  // Severity: internal (4) > environment (3) > bad data (2). A usage code cannot come from a file.
  int worst = 0;
  for (const auto& f : files)
    if (f.state == FileOutcome::State::kFailed)
      worst = std::max(worst, f.error.isOk() ? 2 : std::max(2, exitCodeFor(f.error.code())));
  return worst;
}

namespace {

// Adds to `out` the files under `base` that match components [i, end) of a glob (see expandInputs).
void globWalk(const fs::path& base, const std::vector<std::string>& comps, size_t i, std::vector<fs::path>& out) {
  std::error_code ec;
  if (i == comps.size()) {
    if (fs::is_regular_file(base, ec)) out.push_back(base);
    return;
  }
  const std::string& c = comps[i];
  if (c == "**") {
    globWalk(base, comps, i + 1, out);  // no directory
    for (fs::directory_iterator it(base, ec), end; !ec && it != end; it.increment(ec))
      if (it->is_directory(ec) && !it->is_symlink(ec) && it->path().filename().string()[0] != '.')
        globWalk(it->path(), comps, i, out);
    return;
  }
  if (!hasWildcard(c)) return globWalk(base / c, comps, i + 1, out);
  std::vector<fs::path> entries;  // sorted, so that the walk is deterministic
  for (fs::directory_iterator it(base, ec), end; !ec && it != end; it.increment(ec))
    if (::fnmatch(c.c_str(), it->path().filename().c_str(), FNM_PERIOD) == 0) entries.push_back(it->path());
  std::sort(entries.begin(), entries.end());
  for (const auto& e : entries) globWalk(e, comps, i + 1, out);
}

// The subfolder of `file` under `root` ("" when it is directly in it).
std::string subfolder(const fs::path& file, const fs::path& root) {
  const fs::path rel = file.parent_path().lexically_relative(root);
  const std::string s = rel.lexically_normal().string();
  return s == "." || s.empty() ? "" : s;
}

}  // namespace

Result<std::vector<JobInput>> expandInputs(const JobSettings& job) {
  std::map<std::string, std::string> files;  // path -> subfolder
  const std::string where = job.config_path.empty() ? "inputs" : job.config_path;
  for (size_t i = 0; i < job.inputs.size(); ++i) {
    const std::string& in = job.inputs[i];
    const std::string pointer = where + ": /inputs/" + std::to_string(i);
    std::error_code ec;
    const fs::path p = fs::path(in).lexically_normal();
    size_t found = 0;
    if (hasWildcard(in)) {
      // The root: the components before the first wildcard.
      std::vector<std::string> comps;
      fs::path root;
      bool wild = false;
      for (const auto& c : p) {
        const std::string s = c.string();
        if (!wild && (hasWildcard(s) || s == "**")) wild = true;
        if (wild) {
          if (s == "..") return makeError(ErrorCode::kInvalidArgument, pointer + ": no '..' after a wildcard");
          comps.push_back(s);
        } else {
          root /= c;
        }
      }
      if (comps.back() == "**")
        return makeError(ErrorCode::kInvalidArgument, pointer + ": '**' must be followed by a file name pattern");
      if (root.empty()) root = ".";
      std::vector<fs::path> matched;
      globWalk(root, comps, 0, matched);
      for (const auto& m : matched) {
        files.emplace(m.lexically_normal().string(), subfolder(m, root));
        ++found;
      }
      if (found == 0) return makeError(ErrorCode::kInvalidArgument, pointer + ": '" + in + "' matches no file");
    } else if (fs::is_directory(p, ec)) {
      auto add = [&](const fs::directory_entry& e) {
        std::error_code e2;
        if (e.is_regular_file(e2) && isMeshFile(e.path())) {
          files.emplace(e.path().lexically_normal().string(), subfolder(e.path(), p));
          ++found;
        }
      };
      if (job.recursive) {
        for (fs::recursive_directory_iterator it(p, ec), end; !ec && it != end; it.increment(ec)) add(*it);
      } else {
        for (fs::directory_iterator it(p, ec), end; !ec && it != end; it.increment(ec)) add(*it);
      }
      if (found == 0)
        return makeError(ErrorCode::kInvalidArgument, pointer + ": directory '" + in + "' holds no mesh file");
    } else {
      files.emplace(p.string(), "");  // a missing file fails as its own entry
    }
  }
  std::vector<JobInput> out;
  for (auto& [path, dir] : files) out.push_back({path, dir});
  return out;
}

std::string outputName(const std::string& pattern, const std::string& input, const std::string& dir) {
  const std::string name = fs::path(input).filename().string();
  std::string stem = name;
  auto strip = [&](const char* ext) {
    const size_t n = std::string(ext).size();
    if (stem.size() > n) {
      std::string tail = stem.substr(stem.size() - n);
      std::transform(tail.begin(), tail.end(), tail.begin(), [](unsigned char c) { return std::tolower(c); });
      if (tail == ext) {
        stem.resize(stem.size() - n);
        return true;
      }
    }
    return false;
  };
  strip(".zst");
  for (const char* ext : {".ply", ".obj", ".stl", ".off"})
    if (strip(ext)) break;
  std::string out;
  for (size_t i = 0; i < pattern.size(); ++i) {
    if (pattern.compare(i, 6, "{dir}/") == 0 && dir.empty()) i += 5;
    else if (pattern.compare(i, 5, "{dir}") == 0) out += dir, i += 4;
    else if (pattern.compare(i, 6, "{stem}") == 0) out += stem, i += 5;
    else if (pattern.compare(i, 6, "{name}") == 0) out += name, i += 5;
    else out += pattern[i];
  }
  return out;
}

std::string settingsFingerprint(const EncodeSettings& s) {
  // `scalars` is always written: an earlier build's container of a scan with scalar channels lacks them, so no
  // fingerprint of a run before this build matches (those inputs are encoded again).
  std::string key = "scanpress-v1|codec=" + s.codec + "|bits=" + std::to_string(s.bits) +
                    "|normal_bits=" + std::to_string(s.normal_bits) + "|normals=" + std::to_string(s.keep_normals) +
                    (s.color_bits != 8 ? "|color_bits=" + std::to_string(s.color_bits) : std::string()) +
                    (s.uv_bits != 0 ? "|uv_bits=" + std::to_string(s.uv_bits) : std::string()) +
                    (s.lossless_normals ? "|lossless_normals=1" : std::string()) +
                    "|colors=" + std::to_string(s.keep_colors) + "|scalars=" + std::to_string(s.keep_scalars) +
                    "|tile=" + std::to_string(effectiveTileTarget(s)) +
                    "|input=" + fs::absolute(s.input).lexically_normal().string();
  // Allowing degenerate triangles turns a failure into an output; written only when set, so the fingerprints of
  // earlier runs stay valid.
  if (s.allow_degenerate) key += "|allow_degenerate=1";
  if (s.strict) key += "|strict";
  // pm, prm and the remesh stage carry scalar channels from this build on (earlier builds' containers of theirs
  // lack them): written only for those, so other fingerprints stay valid and theirs are encoded again.
  const bool resamples =
      std::any_of(s.stages.begin(), s.stages.end(), [](const StageSpec& st) { return st.kind == StageKind::kRemesh; });
  if (s.keep_scalars && (s.codec == "pm" || s.codec == "prm" || s.codec == "auto" || resamples))
    key += "|lossy_scalars=1";
  if (s.codec == "prm") {  // prm's remeshing options change the bytes
    char buf[96];
    std::snprintf(buf, sizeof buf, "|prm=%.17g,%.17g", s.codec_options.prm.grid, s.codec_options.prm.tau);
    key += buf;
  }
  if (s.target.active()) {  // a target decides the bits (and a lossy codec's knob); written only when set
    char buf[128];
    std::snprintf(buf, sizeof buf, "|target=%s,%.17g,%s,%llu,%.17g,%d", targetKindName(s.target.kind),
                  s.target.max_error, errorMetricName(s.target.metric),
                  static_cast<unsigned long long>(s.target.max_bytes), s.target.bpv, int(s.target.fixed_bits));
    key += buf;
  }                                       // a complete output made without it may have dropped what strict refuses
  for (const StageSpec& st : s.stages) {  // every option of every stage changes the bytes
    key += "|stage=" + std::string(findStage(st.kind)->name);
    if (st.kind == StageKind::kSmooth) {
      char buf[96];
      std::snprintf(buf, sizeof buf, ",%d,%.17g,%.17g", st.smooth.iterations, st.smooth.lambda, st.smooth.mu);
      key += buf;
    }
    if (st.kind == StageKind::kRemesh) {
      char buf[96];
      std::snprintf(buf, sizeof buf, ",%.17g,%.17g", st.remesh.grid, st.remesh.tau);
      key += buf;
    }
  }
  const MeasureSettings& m = s.measure;  // changes the report, not the container
  if (m.enabled)
    key += "|measure=" + std::to_string(m.samples_per_triangle) + "," + std::to_string(m.samples) + "," +
           std::to_string(m.seed) + "," + std::to_string(m.stratified) + "," + std::to_string(m.vertices) +
           (m.render ? ",render=" + std::to_string(m.render_width) + "x" + std::to_string(m.render_height) + "@" +
                           std::to_string(m.view_azimuth) + "," + std::to_string(m.view_elevation)
                     : "");
  if (m.enabled && m.render && m.scale_max > 0) {  // appended only when set, so earlier runs' keys still match
    char buf[48];
    std::snprintf(buf, sizeof buf, ",scale_max=%.17g", m.scale_max);
    key += buf;
  }
  struct stat st {};
  if (::stat(s.input.c_str(), &st) == 0)
    key += "|size=" + std::to_string(st.st_size) + "|mtime=" + std::to_string(st.st_mtim.tv_sec) + "." +
           std::to_string(st.st_mtim.tv_nsec);
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(fnv1a(key)));
  return hex;
}

// "in -> out: 69451 triangles, 124415 bytes (5.0:1 of 625 KB), 28.57 bpv, rms 1.2e-05 d, max 8.1e-05 d, 1 tiles,
// 0.52 s": what a person scanning a batch's output wants per file.
static std::string fileLine(const FileOutcome& f) {
  const FileOutcome::Counts c = f.counts.value_or(FileOutcome::Counts{});
  char buf[512];
  std::snprintf(buf, sizeof buf, "%s -> %s: %llu triangles, %llu bytes (%.1f:1), %.3f bpv", f.input.c_str(),
                f.output.c_str(), static_cast<unsigned long long>(c.faces), static_cast<unsigned long long>(c.bytes),
                c.bytes ? double(c.input_bytes) / c.bytes : 0.0, c.vertices ? 8.0 * c.bytes / c.vertices : 0.0);
  std::string line = buf;
  if (c.rms_relative >= 0) {
    std::snprintf(buf, sizeof buf, ", error rms %.2e d, max %.2e d", c.rms_relative, c.max_relative);
    line += buf;
  }
  std::snprintf(buf, sizeof buf, ", %llu tiles, %.2f s", static_cast<unsigned long long>(c.tiles), f.seconds);
  return line + buf;
}

// "3 files: 2 ok, 1 skipped, 0 failed; 12.3 MB -> 2.1 MB (5.9:1), 14.2 bpv, 3.4 s".
static std::string totalsLine(const BatchResult& batch) {
  uint64_t ok = 0, skipped = 0, failed = 0, in = 0, out = 0, vertices = 0;
  double seconds = 0;
  for (const auto& f : batch.files) {
    ok += f.state == FileOutcome::State::kOk;
    skipped += f.state == FileOutcome::State::kSkipped;
    failed += f.state == FileOutcome::State::kFailed;
    if (f.counts) in += f.counts->input_bytes, out += f.counts->bytes, vertices += f.counts->vertices;
    seconds += f.seconds;
  }
  char buf[256];
  std::snprintf(buf, sizeof buf, "%zu files: %llu ok, %llu skipped, %llu failed; %s -> %s (%.1f:1), %.3f bpv, %.2f s",
                batch.files.size(), static_cast<unsigned long long>(ok), static_cast<unsigned long long>(skipped),
                static_cast<unsigned long long>(failed), humanBytes(in).c_str(), humanBytes(out).c_str(),
                out ? double(in) / out : 0.0, vertices ? 8.0 * out / vertices : 0.0, seconds);
  return buf;
}

// Encodes one input of a job into `f`: the container, the error picture and the report.
static void encodeOne(const JobSettings& job, const EncodeSettings& s, const std::string& fingerprint,
                      const std::shared_ptr<EmbreeDevice>& device, TerminalProgress& progress,
                      const PipelineHooks* hooks, FileOutcome& f) {
  auto result = encodeFile(s, progress.enabled() ? &progress : nullptr, device, hooks);
  if (result.isOk()) {
    f.has_result = true;
    f.result = std::move(result).value();
    f.counts = FileOutcome::Counts{f.result.vertices, f.result.faces, f.result.bytes, f.result.tiles.size(),
                                   f.result.failed_tiles};
    std::error_code ec;
    f.counts->input_bytes = fs::file_size(f.input, ec);
    if (ec) f.counts->input_bytes = 0;
    if (f.result.measured && f.result.diagonal > 0) {
      const ErrorStats sym = symmetricOf(statsOf(f.result.forward), statsOf(f.result.backward));
      f.counts->rms_relative = sym.rms / f.result.diagonal;
      f.counts->max_relative = sym.max / f.result.diagonal;
    }
    f.state = f.result.failed_tiles == 0 ? FileOutcome::State::kOk : FileOutcome::State::kFailed;
    if (f.result.target && !f.result.target->status.isOk()) {  // a missed target: no container, a failure
      f.state = FileOutcome::State::kFailed;
      f.error = f.result.target->status;
      f.counts.reset();  // the summary's totals count containers that exist
    }
    if (f.result.failed_tiles)
      for (const auto& t : f.result.tiles)
        if (!t.status.isOk()) {
          f.error = t.status.withContext(f.input + ": tile " + std::to_string(t.id) + " (" +
                                         std::to_string(f.result.failed_tiles) + " tiles failed)");
          break;
        }
    if (s.measure.render && f.state == FileOutcome::State::kOk) {
      const std::string png =
          (fs::path(job.output_directory) / outputName(kErrorPictureName, f.input, f.subfolder)).string();
      Status w = renderErrorPicture(s, png, device);
      if (!w.isOk()) f.state = FileOutcome::State::kFailed, f.error = w;
      if (w.isOk()) f.picture = png;
    }
    if (!f.report.empty()) {
      Status w = writeText(f.report, encodeReportJson(s, f.result, fingerprint));
      f.report_written = w.isOk();
      if (!w.isOk()) f.state = FileOutcome::State::kFailed, f.error = w;
    }
  } else {
    f.state = FileOutcome::State::kFailed;
    f.error = result.status();
  }
}

Result<BatchResult> runJob(const JobSettings& job, const RunOptions& options, const PipelineHooks* hooks) {
  SP_ASSIGN_OR_RETURN(std::vector<JobInput> inputs, expandInputs(job));
  SP_RETURN_IF_ERROR(checkJobOutputs(job, inputs));  // the whole job's: every shard refuses the same mistakes
  if (options.shard) {
    std::vector<uint64_t> sizes;
    for (const auto& in : inputs) {
      std::error_code e;
      const uint64_t size = fs::file_size(in.path, e);
      sizes.push_back(e ? 0 : size);
    }
    inputs = shardInputs(inputs, sizes, *options.shard);
  }
  std::error_code ec;
  fs::create_directories(job.output_directory, ec);
  if (ec) return makeError(ErrorCode::kIo, job.output_directory + ": cannot create output directory: " + ec.message());
  // Temporaries of runs that died without cleaning up (SIGKILL, a crash): their PID is no live process.
  if (const size_t stale = removeStaleTemporaries(job.output_directory); stale > 0 && !options.quiet)
    std::printf("%s: removed %zu temporary file(s) of runs that did not finish\n", job.output_directory.c_str(), stale);

  BatchResult batch;
  TerminalProgress progress(options.quiet);
  std::shared_ptr<EmbreeDevice> device;  // one per job, for measuring
  if (job.encode.measure.enabled) {
    SP_ASSIGN_OR_RETURN(device, EmbreeDevice::create());
  }
  for (size_t i = 0; i < inputs.size(); ++i) {
    FileOutcome f;
    f.input = inputs[i].path;
    f.subfolder = inputs[i].dir;
    f.output = (fs::path(job.output_directory) / outputName(job.output_name, f.input, inputs[i].dir)).string();
    if (!job.report_name.empty())
      f.report = (fs::path(job.output_directory) / outputName(job.report_name, f.input, inputs[i].dir)).string();
    // {dir} names subfolders of the output directory: created as needed (a failure fails this input).
    for (const std::string* path : {&f.output, &f.report})
      if (!path->empty()) fs::create_directories(fs::path(*path).parent_path(), ec);
    EncodeSettings s = job.encode;
    s.input = f.input;
    s.output = f.output;
    if (options.threads >= 0) s.threads = options.threads;
    const std::string fingerprint = settingsFingerprint(s);
    const auto start = std::chrono::steady_clock::now();
    const std::optional<CompleteReport> previous =
        job.resume && !options.force && !f.report.empty() ? readCompleteReport(f.report) : std::nullopt;
    if (previous && previous->fingerprint == fingerprint && verifiedContainer(f.output)) {
      f.state = FileOutcome::State::kSkipped;
      f.counts =
          FileOutcome::Counts{previous->vertices,    previous->faces,        previous->bytes,       previous->tiles, 0,
                              previous->input_bytes, previous->rms_relative, previous->max_relative};
      f.report_written = true;
      if (s.measure.enabled && s.measure.render) {  // the picture of the run that made the output, if still there
        const std::string png =
            (fs::path(job.output_directory) / outputName(kErrorPictureName, f.input, f.subfolder)).string();
        if (fs::exists(png, ec)) f.picture = png;
      }
      batch.files.push_back(std::move(f));
      continue;
    }
    progress.file(i, inputs.size(), fs::path(f.input).filename().string());
    try {
      encodeOne(job, s, fingerprint, device, progress, hooks, f);
    } catch (...) {  // the input fails, as a report entry; the batch goes on
      f.has_result = false;
      f.state = FileOutcome::State::kFailed;
      f.error = statusFromException().withContext(f.input);
    }
    f.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    progress.clear();
    if (!options.quiet) {
      if (f.has_result && !f.result.read.dropped.empty())
        std::fprintf(stderr, "scanpress: warning: %s: dropped %s (not kept by scanpress; /strict fails instead)\n",
                     f.input.c_str(), describeDropped(f.result.read.dropped).c_str());
      if (f.state == FileOutcome::State::kFailed)
        std::fprintf(stderr, "scanpress: error: %s\n", f.error.toString().c_str());
      else std::printf("%s\n", fileLine(f).c_str());
    }
    batch.files.push_back(std::move(f));
  }
  if (!options.quiet && !batch.files.empty()) std::printf("%s\n", totalsLine(batch).c_str());
  if (!job.summary_name.empty()) {
    const std::string name = options.shard ? shardSummaryName(job.summary_name, *options.shard) : job.summary_name;
    const std::string path = (fs::path(job.output_directory) / name).string();
    // Another job's summary in this directory is replaced, but not without a word (a warning even under --quiet:
    // that job's record is lost).
    if (const auto other = summaryJobPath(path); other && *other != job.config_path)
      std::fprintf(stderr,
                   "scanpress: warning: %s: replacing the summary of another job (%s); give each job its own "
                   "/output/summary or directory\n",
                   path.c_str(), other->c_str());
    SP_RETURN_IF_ERROR(writeText(path,
                                 batchSummaryJson(job.config_path, batch, options.shard ? &*options.shard : nullptr)));
    // The page shows the whole job: a shard leaves it to `run --merge`.
    if (!job.html_name.empty() && !options.shard)
      SP_RETURN_IF_ERROR(writeHtmlReport(path, (fs::path(job.output_directory) / job.html_name).string(), {}, device));
  }
  return batch;
}

Result<MergedSummary> mergeJobShards(const JobSettings& job) {
  if (job.summary_name.empty())
    return makeError(ErrorCode::kInvalidArgument, job.config_path + ": /output/summary is \"\": nothing to merge");
  // The shard summaries present: NAME.shard-I-of-N.EXT.
  const Shard probe{0, 1};
  const std::string sample = shardSummaryName(job.summary_name, probe);  // NAME.shard-0-of-1.EXT
  const size_t tag = sample.find(".shard-0-of-1");
  const std::string prefix = sample.substr(0, tag) + ".shard-", suffix = sample.substr(tag + 13);
  std::set<uint32_t> counts;
  std::error_code ec;
  for (fs::directory_iterator it(job.output_directory, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.size() <= prefix.size() + suffix.size() || name.rfind(prefix, 0) != 0 ||
        name.compare(name.size() - suffix.size(), suffix.size(), suffix) != 0)
      continue;
    std::string middle = name.substr(prefix.size(), name.size() - prefix.size() - suffix.size());  // I-of-N
    if (const size_t of = middle.find("-of-"); of != std::string::npos) middle.replace(of, 4, "/");
    if (auto shard = parseShard(middle, name); shard.isOk()) counts.insert(shard->count);
  }
  if (counts.empty())
    return makeError(ErrorCode::kInvalidArgument, job.output_directory + ": no shard summaries (" + prefix + "I-of-N" +
                                                      suffix + ") to merge: run the shards first");
  if (counts.size() > 1)
    return makeError(ErrorCode::kInvalidArgument, job.output_directory + ": shard summaries of several splits (of " +
                                                      std::to_string(*counts.begin()) + " and of " +
                                                      std::to_string(*counts.rbegin()) +
                                                      "): remove those of the split not used");
  const uint32_t n = *counts.begin();
  std::vector<std::string> paths;
  for (uint32_t i = 0; i < n; ++i)
    paths.push_back((fs::path(job.output_directory) / shardSummaryName(job.summary_name, Shard{i, n})).string());
  SP_ASSIGN_OR_RETURN(std::vector<JobInput> inputs, expandInputs(job));
  std::vector<std::string> expected;
  for (const auto& in : inputs) expected.push_back(in.path);
  SP_ASSIGN_OR_RETURN(MergedSummary merged, mergeShardSummaries(job.config_path, paths, expected));
  const std::string summary = (fs::path(job.output_directory) / job.summary_name).string();
  SP_RETURN_IF_ERROR(writeText(summary, merged.json));
  if (!job.html_name.empty())
    SP_RETURN_IF_ERROR(writeHtmlReport(summary, (fs::path(job.output_directory) / job.html_name).string(), {}));
  return merged;
}

}  // namespace scanpress
