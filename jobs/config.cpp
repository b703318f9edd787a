#include "jobs/config.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "jobs/file_io.h"
#include "jobs/numbers.h"

namespace scanpress {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

// Reads one JSON object, tracking which keys were consumed so the rest can be reported as unknown.
class ObjectReader {
 public:
  ObjectReader(const json& j, std::string pointer, const std::string& file, Status& error)
      : j_(j), pointer_(std::move(pointer)), file_(file), error_(error) {
    if (!j_.is_object()) fail(pointer_.empty() ? "/" : pointer_, "must be an object");
  }

  bool ok() const { return error_.isOk(); }

  // Numbers go through jobs/numbers.h as their JSON text, so that a job file accepts what the command line
  // does (an integer may be written 1e6 or 16.0).
  template <typename T>
  void integer(const char* key, int64_t lo, int64_t hi, T& out) {
    numberAt(take(key), path(key), "an integer", out,
             [&](const std::string& t, const std::string& where) { return parseInteger(t, lo, hi, where); });
  }
  void unsignedInteger(const char* key, uint64_t hi, uint64_t& out) {
    numberAt(take(key), path(key), "an integer", out,
             [&](const std::string& t, const std::string& where) { return parseUnsigned(t, hi, where); });
  }
  void number(const char* key, double lo, double hi, double& out) {
    numberAt(take(key), path(key), "a number", out,
             [&](const std::string& t, const std::string& where) { return parseNumber(t, lo, hi, where); });
  }
  // [a, b] with both in range.
  template <typename T>
  void integerPair(const char* key, int64_t lo, int64_t hi, T& a, T& b) {
    pair(key, "an integer", a, b,
         [&](const std::string& t, const std::string& where) { return parseInteger(t, lo, hi, where); });
  }
  void numberPair(const char* key, double lo, double hi, double& a, double& b) {
    pair(key, "a number", a, b,
         [&](const std::string& t, const std::string& where) { return parseNumber(t, lo, hi, where); });
  }
  void boolean(const char* key, bool& out) {
    const json* v = take(key);
    if (!v) return;
    if (!v->is_boolean()) return fail(path(key), "must be true or false, got " + typeName(*v));
    out = v->get<bool>();
  }
  void string(const char* key, std::string& out, bool allow_empty = true) {
    const json* v = take(key);
    if (!v) return;
    if (!v->is_string()) return fail(path(key), "must be a string, got " + typeName(*v));
    out = v->get<std::string>();
    if (!allow_empty && out.empty()) fail(path(key), "must not be empty");
    noNul(out, path(key));
  }
  void stringList(const char* key, std::vector<std::string>& out) {
    const json* v = take(key);
    if (!v) return;
    if (v->is_string()) {
      out = {v->get<std::string>()};
      return noNul(out[0], path(key));
    }
    if (!v->is_array()) return fail(path(key), "must be a string or an array of strings, got " + typeName(*v));
    out.clear();
    for (size_t i = 0; i < v->size(); ++i) {
      if (!(*v)[i].is_string())
        return fail(path(key) + "/" + std::to_string(i), "must be a string, got " + typeName((*v)[i]));
      out.push_back((*v)[i].get<std::string>());
      noNul(out.back(), path(key) + "/" + std::to_string(i));
    }
  }
  // A nested object; returns nullptr when absent.
  const json* object(const char* key) { return take(key); }
  std::string path(const std::string& key) const { return pointer_ + "/" + escape(key); }

  // Reports the first key that nobody asked for.
  void finish() {
    if (!ok() || !j_.is_object()) return;
    for (auto it = j_.begin(); it != j_.end(); ++it)
      if (!taken_.count(it.key())) return fail(path(it.key()), "unknown key");
  }
  void fail(const std::string& pointer, const std::string& message) {
    if (error_.isOk()) error_ = makeError(ErrorCode::kInvalidArgument, file_ + ": " + pointer + ": " + message);
  }

 private:
  // JSON strings may hold "\u0000"; as a path, everything after it would be cut off silently by the system
  // calls.
  void noNul(const std::string& s, const std::string& pointer) {
    if (s.find('\0') != std::string::npos) fail(pointer, "must not contain a NUL byte (\\u0000)");
  }
  // The number `v` at `pointer` (nothing when absent), parsed by `parse` from its JSON text into `out`.
  template <typename T, typename Parse>
  void numberAt(const json* v, const std::string& pointer, const char* kind, T& out, Parse parse) {
    if (!v) return;
    if (!v->is_number()) return fail(pointer, std::string("must be ") + kind + ", got " + typeName(*v));
    auto x = parse(v->dump(), pointer);
    if (!x.isOk()) return fail(x.status());
    out = static_cast<T>(*x);
  }
  template <typename T, typename Parse>
  void pair(const char* key, const char* kind, T& a, T& b, Parse parse) {
    const json* v = take(key);
    if (!v) return;
    if (!v->is_array() || v->size() != 2)
      return fail(path(key), std::string("must be an array of two values, each ") + kind);
    T* out[2] = {&a, &b};
    for (size_t i = 0; i < 2; ++i) numberAt(&(*v)[i], path(key) + "/" + std::to_string(i), kind, *out[i], parse);
  }
  void fail(const Status& status) {
    if (error_.isOk()) error_ = status.withContext(file_);
  }
  const json* take(const char* key) {
    if (!ok() || !j_.is_object()) return nullptr;
    taken_.insert(key);
    auto it = j_.find(key);
    return it == j_.end() ? nullptr : &*it;
  }
  static std::string escape(const std::string& key) {  // RFC 6901
    std::string out;
    for (char c : key) {
      if (c == '~') out += "~0";
      else if (c == '/') out += "~1";
      else out += c;
    }
    return out;
  }
  static std::string typeName(const json& v) {
    if (v.is_null()) return "null";
    if (v.is_boolean()) return "a boolean";
    if (v.is_number()) return "a number";
    if (v.is_string()) return "a string";
    if (v.is_array()) return "an array";
    return "an object";
  }

  const json& j_;
  std::string pointer_;
  const std::string& file_;
  Status& error_;
  std::set<std::string> taken_;
};

// One stage object of /stages (at `pointer`) into `spec`.
void readStage(const json& j, const std::string& pointer, const std::string& file, Status& error, StageSpec& spec) {
  ObjectReader r(j, pointer, file, error);  // fails unless j is an object
  std::string name;
  r.string("name", name, false);
  if (!error.isOk()) return;
  const StageInfo* info = findStage(name);
  if (!info) return r.fail(pointer + "/name", "unknown stage '" + name + "' (available: " + stageNames() + ")");
  spec.kind = info->kind;
  switch (spec.kind) {
    case StageKind::kSmooth:
      r.integer("iterations", 0, kMaxSmoothIterations, spec.smooth.iterations);
      r.number("lambda", -1e9, 1e9, spec.smooth.lambda);
      r.number("mu", -1e9, 1e9, spec.smooth.mu);
      break;
    case StageKind::kRemesh:
      r.number("grid", -1e9, 1e9, spec.remesh.grid);
      r.number("tau", -1e9, 1e9, spec.remesh.tau);
      break;
  }
  r.finish();
  if (!error.isOk()) return;
  const Status valid = validateStage(spec);
  if (!valid.isOk())
    r.fail(pointer + "/" + valid.message().substr(0, valid.message().find(':')),
           valid.message().substr(valid.message().find(':') + 2));
}

// /stages: an array of stage objects.
void readStages(const json& j, const std::string& file, Status& error, std::vector<StageSpec>& out) {
  if (!j.is_array()) {
    error = makeError(ErrorCode::kInvalidArgument, file + ": /stages: must be an array of stage objects");
    return;
  }
  out.assign(j.size(), StageSpec{});
  for (size_t i = 0; i < j.size() && error.isOk(); ++i)
    readStage(j[i], "/stages/" + std::to_string(i), file, error, out[i]);
}

// /codec/target: at most one of max_error (with error), max_bytes and bpv; null is as absent (reference.json lists
// every key so).
void readTarget(const json& given, const std::string& file, Status& error, EncodeTarget& out) {
  json j = given;
  if (j.is_object())
    for (auto it = j.begin(); it != j.end();) it = it->is_null() ? j.erase(it) : std::next(it);
  ObjectReader r(j, "/codec/target", file, error);
  double max_error = -1, bpv = -1;
  uint64_t max_bytes = 0;
  std::string metric;
  r.number("max_error", 1e-12, 1, max_error);
  r.string("error", metric);
  r.unsignedInteger("max_bytes", UINT64_MAX, max_bytes);
  r.number("bpv", 1e-6, 1e6, bpv);
  r.finish();
  if (!error.isOk()) return;
  const bool has_error = j.contains("max_error"), has_bytes = j.contains("max_bytes"), has_bpv = j.contains("bpv");
  if (int(has_error) + int(has_bytes) + int(has_bpv) > 1)
    return r.fail(has_bpv ? "/codec/target/bpv" : "/codec/target/max_bytes",
                  "conflicts with " + std::string(has_error ? "/codec/target/max_error" : "/codec/target/max_bytes") +
                      ": give one target (an error bound or a size budget)");
  if (j.contains("error") && metric != "rms" && metric != "max")
    return r.fail("/codec/target/error", "must be \"rms\" or \"max\", got \"" + metric + "\"");
  if (j.contains("error") && (has_bytes || has_bpv))
    return r.fail("/codec/target/error", "applies to /codec/target/max_error only, not to a size budget");
  if (has_bytes && max_bytes == 0) return r.fail("/codec/target/max_bytes", "must be at least 1");
  out.kind = has_error   ? TargetKind::kMaxError
             : has_bytes ? TargetKind::kMaxBytes
             : has_bpv   ? TargetKind::kBitsPerVertex
                         : TargetKind::kNone;
  out.max_error = has_error ? max_error : 0;
  out.metric = metric == "max" ? ErrorMetric::kMax : ErrorMetric::kRms;
  out.max_bytes = max_bytes;
  out.bpv = has_bpv ? bpv : 0;
}

bool validPattern(const std::string& p) {
  for (size_t i = 0; i < p.size(); ++i)
    if (p[i] == '{') {
      const size_t e = p.find('}', i);
      if (e == std::string::npos) return false;
      const std::string name = p.substr(i + 1, e - i - 1);
      if (name != "stem" && name != "name" && name != "dir") return false;
      i = e;
    }
  return true;
}

}  // namespace

std::vector<std::string> knownConfigKeys() {
  return {"/inputs",
          "/recursive",
          "/output/directory",
          "/output/name",
          "/output/report",
          "/output/summary",
          "/output/html",
          "/codec/name",
          "/codec/bits",
          "/codec/normal_bits",
          "/codec/color_bits",
          "/codec/uv_bits",
          "/codec/normals",
          "/codec/lossless_normals",
          "/codec/colors",
          "/codec/scalars",
          "/codec/allow_degenerate",
          "/codec/grid",
          "/codec/tau",
          "/codec/target/max_error",
          "/codec/target/error",
          "/codec/target/max_bytes",
          "/codec/target/bpv",
          "/stages",
          "/tiling/target_triangles",
          "/strict",
          "/threads",
          "/memory_budget_mb",
          "/scratch_directory",
          "/resume",
          "/measure/enabled",
          "/measure/samples_per_triangle",
          "/measure/samples",
          "/measure/seed",
          "/measure/stratified",
          "/measure/vertices",
          "/measure/render",
          "/measure/render_size",
          "/measure/view",
          "/measure/scale_max"};
}

Result<JobSettings> parseJobConfig(const std::string& text, const std::string& config_path) {
  json root;
  try {
    root = json::parse(text);
  } catch (const json::parse_error& e) {
    return makeError(ErrorCode::kInvalidArgument,
                     config_path + ": byte " + std::to_string(e.byte) + ": invalid JSON: " + e.what());
  } catch (const json::out_of_range& e) {  // a number beyond the double range, e.g. 1e400
    return makeError(ErrorCode::kInvalidArgument, config_path + ": invalid JSON: " + e.what());
  }
  JobSettings s;
  s.config_path = config_path;
  Status error;
  ObjectReader top(root, "", config_path, error);
  top.stringList("inputs", s.inputs);
  top.boolean("recursive", s.recursive);
  if (const json* out = top.object("output")) {
    ObjectReader o(*out, "/output", config_path, error);
    o.string("directory", s.output_directory, false);
    o.string("name", s.output_name, false);
    o.string("report", s.report_name);
    o.string("summary", s.summary_name);
    o.string("html", s.html_name);
    o.finish();
    if (error.isOk() && !s.html_name.empty() && s.summary_name.empty())
      o.fail("/output/html", "needs /output/summary (the page is made from the batch summary)");
    if (error.isOk() && !s.html_name.empty() && lowerExtension(s.html_name) != ".html" &&
        lowerExtension(s.html_name) != ".htm")
      o.fail("/output/html", "must end in .html, got '" + s.html_name + "'");
    if (error.isOk() && !validPattern(s.output_name))
      o.fail("/output/name", "unknown placeholder (use {stem}, {name} or {dir})");
    if (error.isOk())
      if (Status named = checkContainerName(s.output_name); !named.isOk()) o.fail("/output/name", named.message());
    if (error.isOk() && !validPattern(s.report_name))
      o.fail("/output/report", "unknown placeholder (use {stem}, {name} or {dir})");
    // Names of files inside the output directory: no '/' (so none escapes it, `../x`, or names a directory), except
    // right after `{dir}`, the input's subfolder (which never holds `..`: see expandInputs).
    for (auto [pointer, name] : {std::pair<const char*, const std::string*>{"/output/name", &s.output_name},
                                 {"/output/report", &s.report_name},
                                 {"/output/summary", &s.summary_name},
                                 {"/output/html", &s.html_name}}) {
      if (name->empty() && name == &s.html_name) continue;  // none
      std::string plain = *name;
      for (size_t at; (at = plain.find("{dir}/")) != std::string::npos;) plain.erase(at, 6);
      if (error.isOk() && (plain.find('/') != std::string::npos || plain.empty() || plain == "." || plain == ".."))
        o.fail(pointer, std::string("must be a file name (no '/'") +
                            (name == &s.summary_name || name == &s.html_name ? "" : " but after {dir}") +
                            "): files are written inside /output/directory");
      if (error.isOk() && (name == &s.summary_name || name == &s.html_name) && name->find("{dir}") != std::string::npos)
        o.fail(pointer, std::string("must be a file name: the ") + (name == &s.html_name ? "page" : "summary") +
                            " is one file for the whole job");
    }
    if (error.isOk() && s.report_name == s.output_name)
      o.fail("/output/report", "must differ from /output/name: the report would replace the container");
  }
  if (const json* codec_in = top.object("codec")) {
    // prm's keys may be null (as absent), so that a file can list them for any codec (configs/reference.json).
    json codec_copy = *codec_in;
    if (codec_copy.is_object())
      for (const char* key : {"grid", "tau"})
        if (codec_copy.contains(key) && codec_copy[key].is_null()) codec_copy.erase(key);
    const json* codec = &codec_copy;
    ObjectReader c(*codec, "/codec", config_path, error);
    c.string("name", s.encode.codec, false);
    c.integer("bits", kMinGridBits, kMaxGridBits, s.encode.bits);
    c.integer("normal_bits", 4, 16, s.encode.normal_bits);
    c.integer("color_bits", 1, 8, s.encode.color_bits);
    c.integer("uv_bits", 0, kMaxScalarBits, s.encode.uv_bits);
    c.boolean("normals", s.encode.keep_normals);
    c.boolean("lossless_normals", s.encode.lossless_normals);
    c.boolean("colors", s.encode.keep_colors);
    c.boolean("scalars", s.encode.keep_scalars);
    c.boolean("allow_degenerate", s.encode.allow_degenerate);
    // prm's remeshing (engine/codecs/codec.h PrmOptions): the lattice spacing, a fraction of 2^bits, and tau.
    c.number("grid", 1e-6, 1, s.encode.codec_options.prm.grid);
    c.number("tau", 1e-3, 0.577, s.encode.codec_options.prm.tau);
    if (const json* target = c.object("target")) readTarget(*target, config_path, error, s.encode.target);
    // A target chooses the bits unless they are given.
    s.encode.target.fixed_bits = codec->is_object() && codec->contains("bits");
    c.finish();
    if (error.isOk() && !knownCodecName(s.encode.codec)) {
      c.fail("/codec/name", "unknown codec '" + s.encode.codec + "' (available: " + codecNames() + ", auto)");
    }
    for (const char* key : {"grid", "tau"})
      if (error.isOk() && codec->is_object() && codec->contains(key) && s.encode.codec != "prm")
        c.fail(std::string("/codec/") + key, "applies to codec prm only, not " + s.encode.codec);
  }
  if (const json* stages = top.object("stages")) readStages(*stages, config_path, error, s.encode.stages);
  if (const json* tiling = top.object("tiling")) {
    ObjectReader t(*tiling, "/tiling", config_path, error);
    t.integer("target_triangles", kMinTileTriangles, kMaxTileTriangles, s.encode.tile_triangles);
    t.finish();
  }
  if (const json* measure = top.object("measure")) {
    ObjectReader m(*measure, "/measure", config_path, error);
    MeasureSettings& ms = s.encode.measure;
    m.boolean("enabled", ms.enabled);
    m.number("samples_per_triangle", 1e-6, 1e6, ms.samples_per_triangle);
    m.integer("samples", 0, kMaxMeasureSamples, ms.samples);
    m.unsignedInteger("seed", UINT64_MAX, ms.seed);
    m.boolean("stratified", ms.stratified);
    m.boolean("vertices", ms.vertices);
    m.boolean("render", ms.render);
    m.integerPair("render_size", 16, 8192, ms.render_width, ms.render_height);
    m.numberPair("view", -360, 360, ms.view_azimuth, ms.view_elevation);
    m.number("scale_max", 0, 1e6, ms.scale_max);  // 0: each picture's own scale
    m.finish();
    if (error.isOk() && ms.render && !ms.enabled) m.fail("/measure/render", "needs /measure/enabled");
  }
  top.integer("threads", 0, 4096, s.encode.threads);
  int64_t budget_mb = 0;
  top.integer("memory_budget_mb", 0, int64_t(1) << 30, budget_mb);
  if (budget_mb > 0 && budget_mb < 16) top.fail("/memory_budget_mb", "must be 0 (no limit) or at least 16");
  s.encode.memory_budget = static_cast<uint64_t>(budget_mb) << 20;
  top.string("scratch_directory", s.encode.scratch_dir);
  top.boolean("resume", s.resume);
  top.boolean("strict", s.encode.strict);
  top.finish();
  if (error.isOk() && s.inputs.empty()) top.fail("/inputs", "must name at least one file, directory or glob");
  for (size_t i = 0; error.isOk() && i < s.inputs.size(); ++i)
    if (s.inputs[i].empty()) top.fail("/inputs/" + std::to_string(i), "must not be empty");
  if (!error.isOk()) return error;

  // Relative paths are relative to the job file's directory.
  const fs::path base = fs::path(config_path).parent_path();
  auto resolve = [&](std::string& p) {
    if (!p.empty() && fs::path(p).is_relative()) p = (base / p).lexically_normal().string();
  };
  for (auto& in : s.inputs) resolve(in);
  resolve(s.output_directory);
  resolve(s.encode.scratch_dir);
  return s;
}

Result<std::vector<StageSpec>> parseStagesOption(const std::string& text, const std::string& option) {
  // NAME[:KEY=VALUE...][,NAME...] as the JSON array of /stages, read by the same code.
  json stages = json::array();
  size_t start = 0;
  while (start <= text.size()) {
    const size_t comma = std::min(text.find(',', start), text.size());
    const std::string item = text.substr(start, comma - start);
    json stage = json::object();
    size_t at = item.find(':');
    stage["name"] = item.substr(0, at);
    while (at != std::string::npos) {
      const size_t next = item.find(':', at + 1);
      const std::string kv = item.substr(at + 1, next == std::string::npos ? std::string::npos : next - at - 1);
      const size_t eq = kv.find('=');
      if (eq == std::string::npos || eq == 0)
        return makeError(ErrorCode::kInvalidArgument, option + ": expected KEY=VALUE, got '" + kv + "'");
      const json value = json::parse(kv.substr(eq + 1), nullptr, false);
      stage[kv.substr(0, eq)] = value.is_discarded() ? json(kv.substr(eq + 1)) : value;
      at = next;
    }
    stages.push_back(std::move(stage));
    start = comma + 1;
  }
  Status error;
  std::vector<StageSpec> out;
  readStages(stages, option, error, out);
  if (!error.isOk()) return error;
  return out;
}

std::optional<CompleteReport> readCompleteReport(const std::string& report_path) {
  std::ifstream f(report_path, std::ios::binary);
  if (!f) return std::nullopt;
  try {
    const json j = json::parse(f);
    if (!j.is_object() || !j.value("complete", false)) return std::nullopt;
    auto it = j.find("fingerprint");
    if (it == j.end() || !it->is_string() || it->get<std::string>().empty()) return std::nullopt;
    CompleteReport r;
    r.fingerprint = it->get<std::string>();
    r.vertices = j.value("vertices", uint64_t(0));
    r.faces = j.value("faces", uint64_t(0));
    r.bytes = j.value("bytes", uint64_t(0));
    r.tiles = j.value("tiles", json::array()).size();
    r.input_bytes = j.value("input_bytes", uint64_t(0));
    if (auto e = j.find("error"); e != j.end() && e->is_object() && e->contains("symmetric")) {
      r.rms_relative = (*e)["symmetric"].value("rms_relative", -1.0);
      r.max_relative = (*e)["symmetric"].value("max_relative", -1.0);
    }
    return r;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

std::optional<std::string> summaryJobPath(const std::string& summary_path) {
  std::ifstream f(summary_path, std::ios::binary);
  if (!f) return std::nullopt;
  try {
    const json j = json::parse(f);
    auto it = j.find("job");
    if (!j.is_object() || it == j.end() || !it->is_string()) return std::nullopt;
    return it->get<std::string>();
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

Result<JobSettings> loadJobConfig(const std::string& path) {
  // A directory opens as a stream on Linux and reads as nothing ("invalid JSON: byte 1"): say what it is.
  std::error_code ec;
  if (fs::is_directory(path, ec))
    return makeError(ErrorCode::kInvalidArgument, path + ": is a directory, not a job file");
  std::ifstream f(path, std::ios::binary);
  if (!f) return makeError(ErrorCode::kInvalidArgument, path + ": cannot open job file");
  std::stringstream ss;
  ss << f.rdbuf();
  if (f.bad()) return makeError(ErrorCode::kIo, path + ": read failed");
  return parseJobConfig(ss.str(), path);
}

}  // namespace scanpress
