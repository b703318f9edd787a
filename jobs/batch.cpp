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

// The decoded scan (whole, from the container just written) colored by its distance to the original.
Status renderErrorPicture(const EncodeSettings& s, const std::string& png, std::shared_ptr<EmbreeDevice> device) {
  SP_ASSIGN_OR_RETURN(Mesh original, readMeshFile(s.input));
  ContainerHeader header;
  SP_ASSIGN_OR_RETURN(QuantizedMesh q, decodeContainer(s.output, std::nullopt, &header));
  const Mesh decoded = dequantizeMesh(q, header.grid, header.layout);
  RenderSettings rs;
  rs.width = s.measure.render_width;
  rs.height = s.measure.render_height;
  rs.azimuth = s.measure.view_azimuth;
  rs.elevation = s.measure.view_elevation;
  SP_ASSIGN_OR_RETURN(RenderResult picture, renderMesh(decoded, rs, device, &original));
  return writePng(png, picture.image);
}

// Refuses a job whose outputs would destroy something, before anything is written: an output (container,
// report, error picture, summary) that is one of the inputs (by path, or by device and inode: hard links,
// symlinks), that another output of the job writes too, or that exists as a FIFO, device or socket. The error
// names the JSON pointer of the name that makes the output (exit 1).
Status checkJobOutputs(const JobSettings& job, const std::vector<std::string>& inputs) {
  const std::string where = job.config_path.empty() ? "" : job.config_path + ": ";
  auto canonical = [](const std::string& p) {
    std::error_code ec;
    const fs::path c = fs::weakly_canonical(fs::absolute(p, ec), ec);
    return ec ? fs::path(p).lexically_normal().string() : c.string();
  };
  std::map<std::string, std::string> input_paths;            // canonical path -> input
  std::map<std::pair<dev_t, ino_t>, std::string> input_ids;  // existing inputs' identities -> input
  for (const std::string& in : inputs) {
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
  for (const std::string& in : inputs) {
    SP_RETURN_IF_ERROR(plan((dir / outputName(job.output_name, in)).string(), "/output/name"));
    if (!job.report_name.empty())
      SP_RETURN_IF_ERROR(plan((dir / outputName(job.report_name, in)).string(), "/output/report"));
    if (job.encode.measure.enabled && job.encode.measure.render)
      SP_RETURN_IF_ERROR(plan((dir / outputName(kErrorPictureName, in)).string(), "/measure/render"));
  }
  if (!job.summary_name.empty()) SP_RETURN_IF_ERROR(plan((dir / job.summary_name).string(), "/output/summary"));
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

Result<std::vector<std::string>> expandInputs(const JobSettings& job) {
  std::set<std::string> files;
  const std::string where = job.config_path.empty() ? "inputs" : job.config_path;
  for (size_t i = 0; i < job.inputs.size(); ++i) {
    const std::string& in = job.inputs[i];
    const std::string pointer = where + ": /inputs/" + std::to_string(i);
    std::error_code ec;
    const fs::path p(in);
    size_t found = 0;
    if (hasWildcard(p.filename().string())) {
      if (hasWildcard(p.parent_path().string()))
        return makeError(ErrorCode::kInvalidArgument, pointer + ": wildcards are allowed in the file name only");
      const fs::path dir = p.has_parent_path() ? p.parent_path() : fs::path(".");
      for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
        if (!it->is_regular_file(ec)) continue;
        if (::fnmatch(p.filename().c_str(), it->path().filename().c_str(), 0) == 0) {
          files.insert(it->path().lexically_normal().string());
          ++found;
        }
      }
      if (found == 0) return makeError(ErrorCode::kInvalidArgument, pointer + ": '" + in + "' matches no file");
    } else if (fs::is_directory(p, ec)) {
      auto add = [&](const fs::directory_entry& e) {
        std::error_code e2;
        if (e.is_regular_file(e2) && isMeshFile(e.path())) {
          files.insert(e.path().lexically_normal().string());
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
      files.insert(p.lexically_normal().string());  // a missing file fails as its own entry
    }
  }
  return std::vector<std::string>(files.begin(), files.end());
}

std::string outputName(const std::string& pattern, const std::string& input) {
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
    if (pattern.compare(i, 6, "{stem}") == 0) out += stem, i += 5;
    else if (pattern.compare(i, 6, "{name}") == 0) out += name, i += 5;
    else out += pattern[i];
  }
  return out;
}

std::string settingsFingerprint(const EncodeSettings& s) {
  std::string key = "scanpress-v1|codec=" + s.codec + "|bits=" + std::to_string(s.bits) +
                    "|normal_bits=" + std::to_string(s.normal_bits) + "|normals=" + std::to_string(s.keep_normals) +
                    "|colors=" + std::to_string(s.keep_colors) + "|tile=" + std::to_string(effectiveTileTarget(s)) +
                    "|input=" + fs::absolute(s.input).lexically_normal().string();
  // Allowing degenerate triangles turns a failure into an output; written only when set, so the fingerprints of
  // earlier runs stay valid.
  if (s.allow_degenerate) key += "|allow_degenerate=1";
  if (s.strict) key += "|strict";
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
  }
  const MeasureSettings& m = s.measure;  // changes the report, not the container
  if (m.enabled)
    key += "|measure=" + std::to_string(m.samples_per_triangle) + "," + std::to_string(m.samples) + "," +
           std::to_string(m.seed) + "," + std::to_string(m.stratified) + "," + std::to_string(m.vertices) +
           (m.render ? ",render=" + std::to_string(m.render_width) + "x" + std::to_string(m.render_height) + "@" +
                           std::to_string(m.view_azimuth) + "," + std::to_string(m.view_elevation)
                     : "");
  struct stat st {};
  if (::stat(s.input.c_str(), &st) == 0)
    key += "|size=" + std::to_string(st.st_size) + "|mtime=" + std::to_string(st.st_mtim.tv_sec) + "." +
           std::to_string(st.st_mtim.tv_nsec);
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(fnv1a(key)));
  return hex;
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
      Status w = renderErrorPicture(s,
                                    (fs::path(job.output_directory) / outputName(kErrorPictureName, f.input)).string(),
                                    device);
      if (!w.isOk()) f.state = FileOutcome::State::kFailed, f.error = w;
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
  SP_ASSIGN_OR_RETURN(std::vector<std::string> inputs, expandInputs(job));
  SP_RETURN_IF_ERROR(checkJobOutputs(job, inputs));
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
    f.input = inputs[i];
    f.output = (fs::path(job.output_directory) / outputName(job.output_name, f.input)).string();
    if (!job.report_name.empty())
      f.report = (fs::path(job.output_directory) / outputName(job.report_name, f.input)).string();
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
      f.counts = FileOutcome::Counts{previous->vertices, previous->faces, previous->bytes, previous->tiles, 0};
      f.report_written = true;
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
      else
        std::printf("%s -> %s: %llu triangles, %llu bytes, %.3f bpv, %zu tiles, %.2f s\n", f.input.c_str(),
                    f.output.c_str(), static_cast<unsigned long long>(f.result.faces),
                    static_cast<unsigned long long>(f.result.bytes), f.result.bitsPerVertex(), f.result.tiles.size(),
                    f.seconds);
    }
    batch.files.push_back(std::move(f));
  }
  if (!job.summary_name.empty()) {
    const std::string path = (fs::path(job.output_directory) / job.summary_name).string();
    // Another job's summary in this directory is replaced, but not without a word (a warning even under --quiet:
    // that job's record is lost).
    if (const auto other = summaryJobPath(path); other && *other != job.config_path)
      std::fprintf(stderr,
                   "scanpress: warning: %s: replacing the summary of another job (%s); give each job its own "
                   "/output/summary or directory\n",
                   path.c_str(), other->c_str());
    SP_RETURN_IF_ERROR(writeText(path, batchSummaryJson(job.config_path, batch)));
  }
  return batch;
}

}  // namespace scanpress
