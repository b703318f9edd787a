// Error and size targets (jobs/targets.h): the chosen bits meet the target as measured independently (the whole
// decoded container against the input, not the pipeline's per-tile numbers) and are minimal (one bit fewer
// misses); size targets fit and the next finer setting does not; impossible targets and bad options fail
// clearly. The per-tile knob search runs on a test transformation injected through PipelineHooks::knob_stage,
// standing in for a lossy codec until `pm` lands.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "engine/quantize.h"
#include "engine/shapes.h"
#include "jobs/cleanup.h"
#include "jobs/commands.h"
#include "jobs/config.h"
#include "jobs/measure.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs/pipeline.h"
#include "jobs/targets.h"
#include "jobs_util.h"
#include "spatial_util.h"

namespace scanpress {
namespace {

namespace fs = std::filesystem;

// The decoded container measured against the input as a whole (as `scanpress measure` does), relative to the
// input's diagonal, in `metric`.
double independentError(const std::string& input, const std::string& container, ErrorMetric metric) {
  auto original = readMeshFile(input);
  EXPECT_TRUE(original.isOk());
  ContainerHeader header;
  auto decoded_q = decodeContainer(container, std::nullopt, &header);
  EXPECT_TRUE(decoded_q.isOk()) << decoded_q.status().toString();
  if (!original.isOk() || !decoded_q.isOk()) return 1e9;
  const Mesh decoded = dequantizeMesh(*decoded_q, header.grid, header.layout);
  MeasureSettings ms;
  ms.seed = 7;  // not the pipeline's sampling
  auto m = measureMeshes(*original, decoded, ms, testing::device());
  EXPECT_TRUE(m.isOk());
  if (!m.isOk()) return 1e9;
  return (metric == ErrorMetric::kMax ? m->symmetric.max : m->symmetric.rms) / m->diagonal;
}

std::string sphereFile(const testing::TempDir& dir, int levels = 5) {  // 20 * 4^levels triangles
  const std::string path = dir.file("sphere" + std::to_string(levels) + ".ply");
  Mesh m = icosphere(levels);
  EXPECT_TRUE(writePly(path, m).isOk());
  return path;
}

// The sphere the --codec auto tests use: 20480 triangles, 1280 in the sanitizer build (each case runs several
// measured pm searches, minutes there at full size).
#if defined(__SANITIZE_ADDRESS__)
constexpr int kAutoSphereLevels = 3;
#else
constexpr int kAutoSphereLevels = 5;
#endif

EncodeSettings targetSettings(const std::string& input, const std::string& output, ErrorMetric metric, double e) {
  EncodeSettings s;
  s.input = input;
  s.output = output;
  s.codec = "kdtree";
  s.tile_triangles = 8192;
  s.target.kind = TargetKind::kMaxError;
  s.target.max_error = e;
  s.target.metric = metric;
  return s;
}

// The chosen bits meet the target (independently measured), and one bit fewer misses it (or is refused, or is
// below the grid's minimum).
void checkErrorTarget(const std::string& input, ErrorMetric metric, double e) {
  SCOPED_TRACE(std::string(errorMetricName(metric)) + " " + std::to_string(e));
  testing::TempDir dir;
  EncodeSettings s = targetSettings(input, dir.file("t.spz"), metric, e);
  auto r = encodeFile(s, nullptr, testing::device());
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  ASSERT_TRUE(r->target.has_value());
  EXPECT_TRUE(r->target->met) << r->target->status.toString();
  EXPECT_TRUE(r->target->status.isOk());
  const int bits = r->target->bits;
  EXPECT_EQ(bits, r->grid.bits);
  const double achieved = independentError(input, s.output, metric);
  EXPECT_LE(achieved, e) << "at " << bits << " bits";
  EXPECT_LE(r->target->error, e);
  // No temporary containers of the search are left, nor registered for cleanup.
  size_t files = 0;
  for (const auto& f : fs::directory_iterator(dir.path()))
    files += f.path().filename().string().find(".tmp-") != std::string::npos;
  EXPECT_EQ(files, 0u);
  EXPECT_EQ(trackedCount(), 0u);
  if (bits == kMinGridBits) return;
  // One bit fewer misses: as the search measures it (the pipeline's measurement, against E less the margin)...
  EncodeSettings fewer = s;
  fewer.target = EncodeTarget{};
  fewer.bits = bits - 1;
  fewer.measure.enabled = true;
  fewer.output = dir.file("fewer.spz");
  auto f = encodeFile(fewer, nullptr, testing::device());
  if (!f.isOk()) {
    EXPECT_EQ(f.status().code(), ErrorCode::kLimitExceeded) << f.status().toString();
    return;
  }
  const ErrorStats sym = symmetricOf(statsOf(f->forward), statsOf(f->backward));
  const double fewer_error = (metric == ErrorMetric::kMax ? sym.max : sym.rms) / f->diagonal;
  EXPECT_GT(fewer_error, (1 - measureMargin(metric)) * e) << "one bit fewer (" << bits - 1 << ") meets it too";
  // ... and for RMS independently too, within the sampling noise the margin covers. Not for the max: the per-tile
  // measurement looks for the closest point within the tile only, so near tile borders of a coarse grid (where
  // quantization folds triangles and the closest decoded point can lie in the neighbouring tile) its max is
  // larger than the whole mesh's (sphere, max, 1e-3: 0.94e-3 per tile against 0.78e-3 whole at 9 bits). The
  // search is conservative there: it can keep one bit more than a whole-mesh measurement would need.
  if (metric == ErrorMetric::kRms) {
    EXPECT_GT(independentError(input, fewer.output, metric), (1 - 2 * measureMargin(metric)) * e);
  }
}

TEST(Targets, ErrorTargetOnASphereChoosesTheFewestBits) {
  testing::TempDir dir;
  const std::string sphere = sphereFile(dir);
  for (ErrorMetric metric : {ErrorMetric::kRms, ErrorMetric::kMax})
    for (double e : {1e-3, 1e-4}) checkErrorTarget(sphere, metric, e);
}

TEST(Targets, ErrorTargetOnARealScanChoosesTheFewestBits) {
  const std::string path = testing::sharedDataDir() + "/bun_zipper.ply.zst";
  if (!fs::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
  for (ErrorMetric metric : {ErrorMetric::kRms, ErrorMetric::kMax})
    for (double e : {1e-3, 1e-4}) checkErrorTarget(path, metric, e);
}

// Through the CLI, measured by `scanpress decode` and `scanpress measure`: the report names the target, the bits,
// the achieved error overall and per tile.
TEST(Targets, CliErrorTargetReportAndIndependentMeasure) {
  const std::string path = testing::sharedDataDir() + "/bun_zipper.ply.zst";
  if (!fs::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
  testing::TempDir dir;
  std::string out;
  ASSERT_EQ(testing::runScanpress("encode '" + path + "' '" + dir.file("b.spz") +
                                      "' --codec kdtree --max-error 1e-4 --error max --tile-triangles 16384 --report '" +
                                      dir.file("b.json") + "'",
                                  &out),
            0)
      << out;
  EXPECT_NE(out.find("target max_error: met"), std::string::npos) << out;
  std::ifstream f(dir.file("b.json"));
  const auto j = nlohmann::json::parse(f);
  ASSERT_TRUE(j.contains("target"));
  EXPECT_EQ(j["target"]["kind"], "max_error");
  EXPECT_EQ(j["target"]["error"], "max");
  EXPECT_EQ(j["target"]["met"], true);
  EXPECT_EQ(j["target"]["bits"], j["grid"]["bits"]);
  EXPECT_LE(j["target"]["achieved_error"].get<double>(), 1e-4);
  EXPECT_GE(j["target"]["attempts"].size(), 2u);
  EXPECT_GE(j["tiles"].size(), 2u);
  for (const auto& t : j["tiles"]) {
    EXPECT_TRUE(t.contains("error"));
    EXPECT_TRUE(t.contains("within_target"));
  }
  ASSERT_EQ(testing::runScanpress("decode '" + dir.file("b.spz") + "' '" + dir.file("b.ply") + "'", &out), 0) << out;
  ASSERT_EQ(testing::runScanpress("measure '" + path + "' '" + dir.file("b.ply") + "' --json", &out), 0) << out;
  const auto m = nlohmann::json::parse(out);
  EXPECT_LE(m["symmetric"]["max_relative"].get<double>(), 1e-4);
}

TEST(Targets, SizeTargetsFitAndTheNextFinerBitDoesNot) {
  testing::TempDir dir;
  const std::string sphere = sphereFile(dir);
  // Budgets from real encodes: between 11 and 12 bits, the choice is 11.
  EncodeSettings base;
  base.input = sphere;
  base.codec = "kdtree";
  uint64_t bytes[25] = {};
  for (int b : {11, 12}) {
    base.bits = b;
    base.output = dir.file("b" + std::to_string(b) + ".spz");
    auto r = encodeFile(base);
    ASSERT_TRUE(r.isOk());
    bytes[b] = r->bytes;
  }
  ASSERT_LT(bytes[11], bytes[12]);
  EncodeSettings s = base;
  s.output = dir.file("t.spz");
  s.target.kind = TargetKind::kMaxBytes;
  s.target.max_bytes = (bytes[11] + bytes[12]) / 2;
  auto r = encodeFile(s);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_TRUE(r->target->met);
  EXPECT_EQ(r->target->bits, 11);
  EXPECT_EQ(fs::file_size(s.output), bytes[11]);
  // Exactly at the budget fits.
  s.target.max_bytes = bytes[12];
  r = encodeFile(s);
  ASSERT_TRUE(r.isOk());
  EXPECT_EQ(r->target->bits, 12);
  EXPECT_LE(fs::file_size(s.output), s.target.max_bytes);
  // Bits per vertex: the same choice.
  s.target = EncodeTarget{};
  s.target.kind = TargetKind::kBitsPerVertex;
  const double bpv11 = 8.0 * double(bytes[11]) / double(r->vertices),
               bpv12 = 8.0 * double(bytes[12]) / double(r->vertices);
  s.target.bpv = (bpv11 + bpv12) / 2;
  r = encodeFile(s);
  ASSERT_TRUE(r.isOk());
  EXPECT_TRUE(r->target->met);
  EXPECT_EQ(r->target->bits, 11);
  EXPECT_LE(r->bitsPerVertex(), s.target.bpv);
}

TEST(Targets, ImpossibleTargetsFailClearly) {
  testing::TempDir dir;
  const std::string sphere = sphereFile(dir);
  EncodeSettings s;
  s.input = sphere;
  s.output = dir.file("t.spz");
  s.codec = "kdtree";
  s.target.kind = TargetKind::kMaxBytes;
  s.target.max_bytes = 100;
  auto r = encodeFile(s);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  ASSERT_TRUE(r->target);
  EXPECT_FALSE(r->target->met);
  EXPECT_EQ(r->target->status.code(), ErrorCode::kLimitExceeded);
  EXPECT_NE(r->target->status.message().find("target not met"), std::string::npos);
  EXPECT_NE(r->target->status.message().find("--max-bytes 100"), std::string::npos) << r->target->status.message();
  EXPECT_FALSE(fs::exists(s.output)) << "a missed target writes no container";
  EXPECT_TRUE(fs::is_empty(dir.path()) || std::distance(fs::directory_iterator(dir.path()), {}) == 1);

  // Through the CLI: exit 2, the message names achieved and target, the report says not met.
  std::string out;
  EXPECT_EQ(testing::runScanpress("encode '" + sphere + "' '" + dir.file("c.spz") +
                                      "' --codec kdtree --max-error 1e-9 "
                                      "--report '" +
                                      dir.file("c.json") + "'",
                                  &out),
            2)
      << out;
  EXPECT_NE(
      out.find("target not met: --max-error 1e-09 (/codec/target/max_error; rms, relative to the diagonal): achieved"),
      std::string::npos)
      << out;
  EXPECT_NE(out.find("at 24 bits"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir.file("c.spz")));
  std::ifstream f(dir.file("c.json"));
  const auto j = nlohmann::json::parse(f);
  EXPECT_EQ(j["complete"], false);
  EXPECT_EQ(j["target"]["met"], false);
  EXPECT_TRUE(j["target"].contains("failure"));
  // Fixed bits that cannot meet an error target: one attempt, a miss.
  EXPECT_EQ(testing::runScanpress("encode '" + sphere + "' '" + dir.file("d.spz") +
                                      "' --codec store --bits 8 --max-error 1e-5",
                                  &out),
            2)
      << out;
  EXPECT_NE(out.find("at 8 bits (fixed by --bits"), std::string::npos) << out;
  // A point cloud has no surface to measure: an error target is refused, naming the option and the key.
  Mesh points = icosphere(2);
  points.triangles.clear();
  ASSERT_TRUE(writePly(dir.file("points.ply"), points).isOk());
  EXPECT_EQ(testing::runScanpress("encode '" + dir.file("points.ply") + "' '" + dir.file("p.spz") +
                                      "' --codec kdtree --max-error 1e-3",
                                  &out),
            2)
      << out;
  EXPECT_NE(out.find("an error target (--max-error, /codec/target/max_error) needs triangles"), std::string::npos)
      << out;
  EXPECT_FALSE(fs::exists(dir.file("p.spz")));
  // The output must not be the input, with a target as without.
  const auto before = fs::file_size(sphere);
  EXPECT_EQ(testing::runScanpress("encode '" + sphere + "' '" + sphere + "' --codec kdtree --max-error 1e-3", &out), 1)
      << out;
  EXPECT_EQ(fs::file_size(sphere), before);
}

// A job file's target: met (summary ok, report with the target), then a budget no setting meets (exit 2, the
// input failed naming the target, its report not complete so a resume redoes it).
TEST(Targets, JobFileTargets) {
  testing::TempDir dir;
  const std::string sphere = sphereFile(dir);
  auto job = [&](const std::string& target) {
    std::ofstream(dir.file("j.json")) << R"({"inputs": [")" << sphere
                                      << R"("], "output": {"directory": "out"}, "codec": {"name": "kdtree", "target": )"
                                      << target << "}}";
  };
  auto read = [&](const std::string& name) {
    std::ifstream f(dir.file("out/" + name));
    return nlohmann::json::parse(f);
  };
  std::string out;
  job(R"({"max_error": 2e-4, "error": "max"})");
  ASSERT_EQ(testing::runScanpress("run '" + dir.file("j.json") + "' --quiet", &out), 0) << out;
  auto report = read("sphere5.report.json");
  EXPECT_EQ(report["complete"], true);
  EXPECT_EQ(report["target"]["met"], true);
  EXPECT_EQ(report["target"]["error"], "max");
  EXPECT_LE(independentError(sphere, dir.file("out/sphere5.spz"), ErrorMetric::kMax), 2e-4);
  job(R"({"max_bytes": 500})");
  EXPECT_EQ(testing::runScanpress("run '" + dir.file("j.json") + "' --quiet", &out), 2) << out;
  const auto summary = read("summary.json");
  EXPECT_EQ(summary["files"][0]["status"], "failed");
  EXPECT_NE(summary["files"][0]["error"].get<std::string>().find("target not met: --max-bytes 500"), std::string::npos);
  report = read("sphere5.report.json");
  EXPECT_EQ(report["complete"], false);
  EXPECT_EQ(report["target"]["met"], false);
}

TEST(TargetOptions, CommandLineConflictsAndBadValuesNameTheOption) {
  testing::TempDir dir;
  const std::string sphere = sphereFile(dir);
  const std::string head = "encode '" + sphere + "' '" + dir.file("o.spz") + "' ";
  struct Case {
    const char* args;
    const char* message;
  } cases[] = {
      {"--max-error 1e-4 --max-bytes 1000", "--max-error and --max-bytes conflict"},
      {"--max-bytes 1000 --bpv 3", "--max-bytes and --bpv conflict"},
      {"--max-error 1e-4 --bpv 3", "--max-error and --bpv conflict"},
      {"--max-error 0", "--max-error"},
      {"--max-error -1e-4", "--max-error"},
      {"--max-error 2", "--max-error"},
      {"--max-error abc", "--max-error"},
      {"--max-error 1e-4 --error median", "--error: must be rms or max, got 'median'"},
      {"--max-bytes 1000 --error max", "--error applies to --max-error only"},
      {"--max-bytes 0", "--max-bytes: must be at least 1"},
      {"--bpv 0", "--bpv"},
  };
  for (const Case& c : cases) {
    std::string out;
    EXPECT_EQ(testing::runScanpress(head + c.args, &out), 1) << c.args << ": " << out;
    EXPECT_NE(out.find(c.message), std::string::npos) << c.args << ": " << out;
    EXPECT_FALSE(fs::exists(dir.file("o.spz")));
  }
}

TEST(TargetOptions, JobKeysAndErrorsNamingThePointer) {
  auto job = parseJobConfig(R"({"inputs": ["a.ply"], "codec": {"target": {"max_error": 1e-4, "error": "max"}}})",
                            "/x/j.json");
  ASSERT_TRUE(job.isOk()) << job.status().toString();
  EXPECT_EQ(job->encode.target.kind, TargetKind::kMaxError);
  EXPECT_EQ(job->encode.target.max_error, 1e-4);
  EXPECT_EQ(job->encode.target.metric, ErrorMetric::kMax);
  EXPECT_FALSE(job->encode.target.fixed_bits);
  job = parseJobConfig(R"({"inputs": ["a.ply"], "codec": {"bits": 12, "target": {"max_bytes": 2e6}}})", "/x/j.json");
  ASSERT_TRUE(job.isOk()) << job.status().toString();
  EXPECT_EQ(job->encode.target.kind, TargetKind::kMaxBytes);
  EXPECT_EQ(job->encode.target.max_bytes, 2000000u);
  EXPECT_TRUE(job->encode.target.fixed_bits);
  job = parseJobConfig(R"({"inputs": ["a.ply"], "codec": {"target": {"bpv": 4.5, "max_error": null}}})", "/x/j.json");
  ASSERT_TRUE(job.isOk()) << job.status().toString();
  EXPECT_EQ(job->encode.target.kind, TargetKind::kBitsPerVertex);
  EXPECT_EQ(job->encode.target.bpv, 4.5);
  job = parseJobConfig(R"({"inputs": ["a.ply"], "codec": {"target": {"max_error": null, "error": "rms"}}})",
                       "/x/j.json");
  ASSERT_TRUE(job.isOk());
  EXPECT_FALSE(job->encode.target.active());

  struct Case {
    const char* target;
    const char* message;
  } cases[] = {
      {R"({"max_error": 1e-4, "max_bytes": 1000})", "/codec/target/max_bytes: conflicts with /codec/target/max_error"},
      {R"({"max_bytes": 1000, "bpv": 2})", "/codec/target/bpv: conflicts with /codec/target/max_bytes"},
      {R"({"max_error": 0})", "/codec/target/max_error"},
      {R"({"max_error": 2})", "/codec/target/max_error"},
      {R"({"max_error": "1e-4"})", "/codec/target/max_error: must be a number"},
      {R"({"max_error": 1e-4, "error": "median"})", "/codec/target/error: must be \"rms\" or \"max\""},
      {R"({"max_bytes": 10, "error": "max"})", "/codec/target/error: applies to /codec/target/max_error only"},
      {R"({"max_bytes": 0})", "/codec/target/max_bytes: must be at least 1"},
      {R"({"max_bytes": -5})", "/codec/target/max_bytes"},
      {R"({"bpv": 0})", "/codec/target/bpv"},
      {R"({"max_eror": 1e-4})", "/codec/target/max_eror: unknown key"},
      {R"([1])", "/codec/target: must be an object"},
  };
  for (const Case& c : cases) {
    auto r =
        parseJobConfig(std::string(R"({"inputs": ["a.ply"], "codec": {"target": )") + c.target + "}}", "/x/j.json");
    ASSERT_FALSE(r.isOk()) << c.target;
    EXPECT_EQ(r.status().code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(r.status().message().find(c.message), std::string::npos) << c.target << ": " << r.status().message();
  }
}

// The prediction against its closed form: cell = ratio * diagonal / 2^bits, RMS cell/sqrt(24), max cell*sqrt(3)/2.
TEST(TargetOptions, PredictedBitsAreTheFewestWhoseModelMeetsTheTarget) {
  for (ErrorMetric metric : {ErrorMetric::kRms, ErrorMetric::kMax})
    for (double ratio : {1.0, 0.6, 1 / std::sqrt(3.0)})
      for (double e : {1e-3, 3e-4, 1e-4, 5e-5}) {
        const double per_cell = metric == ErrorMetric::kMax ? std::sqrt(3.0) / 2 : 1 / std::sqrt(24.0);
        const int b = predictBits(e, metric, ratio);
        auto model = [&](int bits) { return per_cell * ratio / std::ldexp(1.0, bits); };
        EXPECT_LE(model(b), e);
        if (b > kMinGridBits) {
          EXPECT_GT(model(b - 1), e);
        }
        if (b > kMinGridBits) {  // a quarter of the budget: exactly two more bits
          EXPECT_EQ(predictBits(e, metric, ratio, kKnobQuantizationShare), std::min(b + 2, kMaxGridBits));
        }
      }
  EXPECT_EQ(predictBits(1e-12, ErrorMetric::kRms, 1), kMaxGridBits);
  EXPECT_EQ(predictBits(0.5, ErrorMetric::kRms, 1), kMinGridBits);
}

// A stand-in for a lossy codec's knob: every unlocked vertex moves `cells` grid cells (rounded) along +z, so the
// error grows with the knob and the borders stay.
Result<StagedTile> shiftStage(const TileContext& ctx, const TileView& tile, double cells) {
  StagedTile out{tile.mesh, std::vector<uint8_t>(tile.locked.begin(), tile.locked.end())};
  const uint32_t d = static_cast<uint32_t>(std::lround(cells));
  const uint32_t top = (uint32_t(1) << ctx.bits) - 1;
  for (size_t v = 0; v < out.mesh.positions.size(); ++v)
    if (out.locked.empty() || !out.locked[v])
      out.mesh.positions[v][2] = std::min<uint64_t>(top, uint64_t(out.mesh.positions[v][2]) + d);
  return out;
}

TEST(Targets, PerTileKnobSearchMeetsTheTargetInEveryTile) {
  testing::TempDir dir;
  const std::string sphere = sphereFile(dir);
  PipelineHooks hooks;
  hooks.knob_stage = shiftStage;
  for (ErrorMetric metric : {ErrorMetric::kRms, ErrorMetric::kMax}) {
    SCOPED_TRACE(errorMetricName(metric));
    const double e = 1e-3;
    EncodeSettings s = targetSettings(sphere, dir.file("k.spz"), metric, e);
    s.tile_triangles = 2048;
    // The bits of the prediction for E/4, fixed: the knob search is what this test is about (with the bits free,
    // the search may trade the knob's budget for fewer bits).
    s.target.fixed_bits = true;
    s.bits = predictBits(e, metric, 1.0, kKnobQuantizationShare);
    auto r = encodeFile(s, nullptr, testing::device(), &hooks);
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    ASSERT_TRUE(r->target);
    EXPECT_TRUE(r->target->met) << r->target->status.toString();
    // A quarter of the budget to quantization: the bits of the prediction for E/4.
    EXPECT_EQ(r->target->bits, r->grid.bits);
    EXPECT_GT(r->target->tile_error, 0);
    ASSERT_GE(r->tiles.size(), 4u);
    int moved = 0;
    for (const TileReport& t : r->tiles) {
      const ErrorStats sym = symmetricOf(t.forward, t.backward);
      EXPECT_LE(metric == ErrorMetric::kMax ? sym.max : sym.rms, e * r->diagonal) << "tile " << t.id;
      EXPECT_TRUE(t.target_met);
      EXPECT_GE(t.knob_cells, 0);
      EXPECT_GE(t.knob_trials, 2u);
      moved += t.knob_cells >= 1;
    }
    EXPECT_GE(moved, int(r->tiles.size()) / 2) << "the search used the budget";
    // Overall: implied by the tiles, and measured independently.
    EXPECT_LE(independentError(sphere, s.output, metric), e);
  }
}

// A stand-in for a simplifying codec's knob under a size target: the z of every unlocked vertex snaps to a multiple
// of 2^floor(log2(cells)) grid cells, so the bytes shrink and the error grows with the knob.
Result<StagedTile> snapStage(const TileContext&, const TileView& tile, double cells) {
  StagedTile out{tile.mesh, std::vector<uint8_t>(tile.locked.begin(), tile.locked.end())};
  const int k = cells < 1 ? 0 : std::min(20, static_cast<int>(std::floor(std::log2(cells))));
  for (size_t v = 0; v < out.mesh.positions.size(); ++v)
    if (out.locked.empty() || !out.locked[v]) out.mesh.positions[v][2] = out.mesh.positions[v][2] >> k << k;
  return out;
}

TEST(Targets, SizeTargetWithAKnobBisectsOneGlobalThreshold) {
  testing::TempDir dir;
  const std::string sphere = sphereFile(dir);
  PipelineHooks hooks;
  hooks.knob_stage = snapStage;
  EncodeSettings s;
  s.input = sphere;
  s.codec = "kdtree";
  s.bits = 14;
  s.tile_triangles = 4096;
  s.knob_cells = 0;
  s.output = dir.file("k0.spz");
  auto fine = encodeFile(s, nullptr, nullptr, &hooks);
  ASSERT_TRUE(fine.isOk()) << fine.status().toString();
  s.knob_cells = 64;
  s.output = dir.file("k64.spz");
  auto coarse = encodeFile(s, nullptr, nullptr, &hooks);
  ASSERT_TRUE(coarse.isOk());
  ASSERT_LT(coarse->bytes, fine->bytes);
  s.knob_cells = -1;
  s.output = dir.file("t.spz");
  s.target.kind = TargetKind::kMaxBytes;
  s.target.fixed_bits = true;
  s.target.max_bytes = (fine->bytes + coarse->bytes) / 2;
  auto r = encodeFile(s, nullptr, nullptr, &hooks);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  ASSERT_TRUE(r->target);
  EXPECT_TRUE(r->target->met);
  EXPECT_EQ(r->target->bits, 14);
  EXPECT_LE(fs::file_size(s.output), s.target.max_bytes);
  const double t = r->target->knob_cells;
  EXPECT_GT(t, 1);
  EXPECT_LE(t, 64);
  for (const TileReport& tile : r->tiles) EXPECT_EQ(tile.knob_cells, t);
  // The next finer setting tried (within 5% of the chosen knob, or the knob a power of two lower, where the snap
  // changes) does not fit.
  bool finer_missed = false;
  for (const TargetAttempt& a : r->target->attempts) {
    if (a.knob_cells < t) {
      EXPECT_GT(a.bytes, s.target.max_bytes) << "knob " << a.knob_cells << " fits and is finer";
    }
    finer_missed |= a.knob_cells < t && !a.met &&
                    (a.knob_cells * 1.05 >= t || std::floor(std::log2(a.knob_cells)) == std::floor(std::log2(t)) - 1);
  }
  EXPECT_TRUE(finer_missed);
  // Impossible: below what the coarsest knob gives.
  s.target.max_bytes = 200;
  s.output = dir.file("impossible.spz");
  r = encodeFile(s, nullptr, nullptr, &hooks);
  ASSERT_TRUE(r.isOk());
  EXPECT_FALSE(r->target->met);
  EXPECT_NE(r->target->status.message().find("and the coarsest knob"), std::string::npos)
      << r->target->status.message();
  EXPECT_FALSE(fs::exists(s.output));
}

}  // namespace
}  // namespace scanpress

namespace scanpress {
namespace {

// pm under error targets on a real scan, several tiles: every tile's measured error is within the target, the
// whole decoded scan measured independently is too, and (RMS) simplifying pays: smaller than kdtree at the same
// target.
TEST(Targets, PmMeetsErrorTargetsOnARealScan) {
  testing::TempDir dir;
  const std::string bunny = std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
#if defined(__SANITIZE_ADDRESS__)
  // Each case is tens of measured pm encodes: minutes in the unoptimized sanitizer build, so one case there; the
  // Release suite runs two.
  for (ErrorMetric metric : {ErrorMetric::kRms})
    for (double e : {5e-4}) {
#else
  // Each metric at one level (the four pairs took 70 s of CI's Release lane): RMS at the tighter one, where pm must
  // beat kdtree, max at the looser.
  for (ErrorMetric metric : {ErrorMetric::kRms, ErrorMetric::kMax})
    for (double e : {metric == ErrorMetric::kRms ? 2e-4 : 5e-4}) {
#endif
      SCOPED_TRACE(std::string(errorMetricName(metric)) + " " + std::to_string(e));
      EncodeSettings s = targetSettings(bunny, dir.file("pm.spz"), metric, e);
      s.codec = "pm";
      s.tile_triangles = 16384;
      auto r = encodeFile(s, nullptr, testing::device());
      ASSERT_TRUE(r.isOk()) << r.status().toString();
      ASSERT_TRUE(r->target);
      EXPECT_TRUE(r->target->met) << r->target->status.toString();
      ASSERT_GE(r->tiles.size(), 3u);
      for (const TileReport& t : r->tiles) {
        const ErrorStats sym = symmetricOf(t.forward, t.backward);
        EXPECT_LE(metric == ErrorMetric::kMax ? sym.max : sym.rms, e * r->diagonal) << "tile " << t.id;
      }
      EXPECT_LE(independentError(bunny, s.output, metric), e);
      EncodeSettings k = targetSettings(bunny, dir.file("kd.spz"), metric, e);
      k.tile_triangles = s.tile_triangles;
      auto kd = encodeFile(k, nullptr, testing::device());
      ASSERT_TRUE(kd.isOk() && kd->target && kd->target->met);
      // Under the RMS metric simplifying pays. Under the max metric it does not yet: a tile's max is measured within
      // the tile (its borders count against it) and pm's knob stays near 0, where pm v1 costs more than kdtree.
      if (metric == ErrorMetric::kRms) {
        EXPECT_LT(r->bytes, kd->bytes) << "pm " << r->bytes << " B, kdtree " << kd->bytes << " B";
      }
      std::printf("bunny %s %.0e: pm %llu B (%d bits, knob %.3g), kdtree %llu B (%d bits)\n", errorMetricName(metric),
                  e, static_cast<unsigned long long>(r->bytes), r->target->bits, r->target->knob_cells,
                  static_cast<unsigned long long>(kd->bytes), kd->target->bits);
    }
}

// pm under a size target: fits, and simplifies no more than it must (a finer threshold tried did not fit).
TEST(Targets, PmMeetsASizeTarget) {
  testing::TempDir dir;
  const std::string bunny = std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
  EncodeSettings s;
  s.input = bunny;
  s.output = dir.file("pm.spz");
  s.codec = "pm";
  s.bits = 12;
  s.target.kind = TargetKind::kMaxBytes;
  s.target.fixed_bits = true;
  s.target.max_bytes = 20000;  // kdtree at 12 bits needs about 73 KB
  auto r = encodeFile(s, nullptr, testing::device());
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  ASSERT_TRUE(r->target);
  EXPECT_TRUE(r->target->met) << r->target->status.toString();
  EXPECT_LE(fs::file_size(s.output), s.target.max_bytes);
  bool finer_missed = false;
  for (const TargetAttempt& a : r->target->attempts) {
    if (a.knob_cells < r->target->knob_cells) {
      EXPECT_GT(a.bytes, s.target.max_bytes);
    }
    finer_missed |= a.knob_cells < r->target->knob_cells && !a.met;
  }
  EXPECT_TRUE(finer_missed);
}

// --codec auto: both searches run, and the kept result is the smaller of what pm and edgebreaker each choose on
// their own; every attempt of both is in the report, no temporary is left. Under a tight max target the sphere keeps
// edgebreaker (simplifying leaves too little of a max budget: pm's file is twice the size); under a loose RMS
// target it keeps pm. (The bunny showed the same under max, but its two pm searches took 50 of the test's 70 s:
// pm's search on the bunny runs in PmMeetsErrorTargetsOnARealScan.) The sanitizer build
// runs the RMS case on a smaller sphere.
TEST(Targets, AutoKeepsTheBetterOfPmAndEdgebreaker) {
  testing::TempDir dir;
  const std::string sphere = sphereFile(dir, kAutoSphereLevels);
  struct Case {
    std::string input;
    ErrorMetric metric;
    double e;
    const char* expect;  // the codec that must win, or nullptr: whichever measured smaller
  };
#if defined(__SANITIZE_ADDRESS__)
  const std::vector<Case> cases = {{sphere, ErrorMetric::kRms, 1e-3, nullptr}};
#else
  const std::vector<Case> cases = {{sphere, ErrorMetric::kMax, 2e-4, "edgebreaker"},
                                   {sphere, ErrorMetric::kRms, 1e-3, "pm"}};
#endif
  for (const auto& [input, metric, e, expect] : cases) {
    SCOPED_TRACE(input + " " + errorMetricName(metric) + " " + std::to_string(e));
    std::map<std::string, uint64_t> alone;
    for (const char* codec : {"pm", "edgebreaker"}) {
      EncodeSettings s = targetSettings(input, dir.file(std::string(codec) + ".spz"), metric, e);
      s.codec = codec;
      s.tile_triangles = 131072;
      auto r = encodeFile(s, nullptr, testing::device());
      ASSERT_TRUE(r.isOk()) << r.status().toString();
      ASSERT_TRUE(r->target && r->target->met) << codec;
      alone[codec] = r->bytes;
    }
    EncodeSettings s = targetSettings(input, dir.file("auto.spz"), metric, e);
    s.codec = kAutoCodec;
    s.tile_triangles = 131072;
    auto r = encodeFile(s, nullptr, testing::device());
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    ASSERT_TRUE(r->target && r->target->met) << r->target->status.toString();
    const std::string smaller = alone["pm"] < alone["edgebreaker"] ? "pm" : "edgebreaker";
    EXPECT_EQ(r->codec, smaller);
    EXPECT_EQ(r->bytes, std::min(alone["pm"], alone["edgebreaker"]));
    EXPECT_EQ(fs::file_size(s.output), r->bytes);
    EXPECT_LE(independentError(input, s.output, metric), e);
    std::set<std::string> codecs;
    for (const TargetAttempt& a : r->target->attempts) codecs.insert(a.codec);
    EXPECT_EQ(codecs, (std::set<std::string>{"pm", "edgebreaker"}));
    size_t temporaries = 0;
    for (const auto& f : fs::directory_iterator(dir.path()))
      temporaries += f.path().filename().string().find(".tmp-") != std::string::npos;
    EXPECT_EQ(temporaries, 0u);
    EXPECT_EQ(trackedCount(), 0u);
    if (expect) {
      EXPECT_EQ(r->codec, expect);
    }
    std::printf("%s %.0e: auto kept %s, %llu B (pm %llu B, edgebreaker %llu B)\n", errorMetricName(metric), e,
                r->codec.c_str(), static_cast<unsigned long long>(r->bytes),
                static_cast<unsigned long long>(alone["pm"]), static_cast<unsigned long long>(alone["edgebreaker"]));
  }
}

// --codec auto under a size target keeps, of the two that fit, the one with less RMS error; without a target it is
// edgebreaker; the CLI and job files accept it.
TEST(Targets, AutoUnderASizeTargetAndWithoutOne) {
  testing::TempDir dir;
  const std::string input = sphereFile(dir, kAutoSphereLevels);
  EncodeSettings s;
  s.input = input;
  s.output = dir.file("auto.spz");
  s.codec = kAutoCodec;
  s.bits = 12;
  s.target.kind = TargetKind::kMaxBytes;
  s.target.fixed_bits = true;
  s.target.max_bytes = 6000;
  auto r = encodeFile(s, nullptr, testing::device());
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  ASSERT_TRUE(r->target && r->target->met) << r->target->status.toString();
  EXPECT_LE(fs::file_size(s.output), s.target.max_bytes);
  std::map<std::string, double> error;
  for (const char* codec : {"pm", "edgebreaker"}) {
    EncodeSettings c = s;
    c.codec = codec;
    c.output = dir.file(std::string(codec) + ".spz");
    c.measure.enabled = true;
    auto one = encodeFile(c, nullptr, testing::device());
    ASSERT_TRUE(one.isOk()) << one.status().toString();
    if (!one->target->met) continue;
    const ErrorStats sym = symmetricOf(statsOf(one->forward), statsOf(one->backward));
    error[codec] = sym.rms;
  }
  ASSERT_FALSE(error.empty());
  std::string best = error.begin()->first;
  for (const auto& [codec, e] : error)
    if (e < error[best]) best = codec;
  EXPECT_EQ(r->codec, best);
  EXPECT_EQ(trackedCount(), 0u);

  EncodeSettings plain;
  plain.input = input;
  plain.output = dir.file("plain.spz");
  plain.codec = kAutoCodec;
  auto p = encodeFile(plain, nullptr, testing::device());
  ASSERT_TRUE(p.isOk()) << p.status().toString();
  EXPECT_EQ(p->codec, "edgebreaker");
  EXPECT_EQ(testing::runScanpress("encode '" + input + "' '" + dir.file("cli.spz") + "' --codec auto --quiet"), 0);
  auto job = parseJobConfig(R"({"inputs": ["a.ply"], "codec": {"name": "auto"}})", "/x/j.json");
  EXPECT_TRUE(job.isOk()) << job.status().toString();
  job = parseJobConfig(R"({"inputs": ["a.ply"], "codec": {"name": "automatic"}})", "/x/j.json");
  ASSERT_FALSE(job.isOk());
  EXPECT_NE(job.status().message().find("auto"), std::string::npos);
}

}  // namespace
}  // namespace scanpress
