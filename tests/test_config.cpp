// Job files and batch runs.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>

#include "jobs/batch.h"
#include "jobs/config.h"
#include "jobs/shard.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs_util.h"

namespace scanpress {
namespace {

using testing::run;

namespace fs = std::filesystem;

struct BadConfig {
  const char* name;
  std::string json;
  const char* pointer;  // expected in the message
};

TEST(JobConfig, InvalidFilesNameThePointerExitOneWriteNothing) {
  testing::TempDir dir;
  const std::string bunny = std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
  const std::string in = "\"inputs\": [\"" + bunny + "\"], \"output\": {\"directory\": \"out\"}";
  const std::vector<BadConfig> cases = {
      {"syntax", "{\"inputs\": [", "byte "},
      {"not_object", "[1, 2]", "/: must be an object"},
      {"unknown_top_key", "{" + in + ", \"colour\": 1}", "/colour: unknown key"},
      {"missing_inputs", "{\"output\": {\"directory\": \"out\"}}", "/inputs"},
      {"inputs_type", "{\"inputs\": 5, \"output\": {\"directory\": \"out\"}}", "/inputs: must be"},
      {"inputs_element_type", "{\"inputs\": [\"" + bunny + "\", 3], \"output\": {\"directory\": \"out\"}}",
       "/inputs/1"},
      {"inputs_empty_string", "{\"inputs\": [\"\"], \"output\": {\"directory\": \"out\"}}", "/inputs/0"},
      {"bits_too_high", "{" + in + ", \"codec\": {\"bits\": 30}}",
       "/codec/bits: must be an integer in [8, 24], got '30'"},
      {"bits_string", "{" + in + ", \"codec\": {\"bits\": \"16\"}}", "/codec/bits: must be an integer"},
      {"bits_fraction", "{" + in + ", \"codec\": {\"bits\": 12.5}}", "/codec/bits"},
      {"unknown_codec", "{" + in + ", \"codec\": {\"name\": \"zip\"}}", "/codec/name: unknown codec"},
      {"grid_not_prm", "{" + in + ", \"codec\": {\"grid\": 0.01}}", "/codec/grid: applies to codec prm only"},
      {"grid_too_big", "{" + in + ", \"codec\": {\"name\": \"prm\", \"grid\": 2}}", "/codec/grid"},
      {"tau_too_big", "{" + in + ", \"codec\": {\"name\": \"prm\", \"tau\": 0.7}}", "/codec/tau"},
      {"codec_unknown_key", "{" + in + ", \"codec\": {\"level\": 9}}", "/codec/level: unknown key"},
      {"normal_bits_low", "{" + in + ", \"codec\": {\"normal_bits\": 2}}", "/codec/normal_bits"},
      {"normals_not_bool", "{" + in + ", \"codec\": {\"normals\": \"yes\"}}", "/codec/normals: must be true or false"},
      {"output_not_object", "{\"inputs\": [\"" + bunny + "\"], \"output\": \"out\"}", "/output: must be an object"},
      {"output_name_slash", "{" + in.substr(0, in.size() - 1) + ", \"name\": \"a/{stem}.spz\"}}", "/output/name"},
      // Every name is a file inside the output directory; `../` would write outside it.
      {"report_dotdot", "{" + in.substr(0, in.size() - 1) + ", \"report\": \"../{stem}.json\"}}", "/output/report"},
      {"summary_dotdot", "{" + in.substr(0, in.size() - 1) + ", \"summary\": \"../summary.json\"}}", "/output/summary"},
      {"report_is_name", "{" + in.substr(0, in.size() - 1) + ", \"report\": \"{stem}.spz\"}}", "/output/report"},
      // A NUL byte in a path would cut it short silently ("out\u0000x" would write into "out").
      {"nul_in_directory", "{\"inputs\": [\"" + bunny + "\"], \"output\": {\"directory\": \"out\\u0000x\"}}",
       "/output/directory: must not contain a NUL byte"},
      {"nul_in_input", "{\"inputs\": [\"" + bunny + "\\u0000.txt\"], \"output\": {\"directory\": \"out\"}}",
       "/inputs/0: must not contain a NUL byte"},
      {"output_name_placeholder", "{" + in.substr(0, in.size() - 1) + ", \"name\": \"{foo}.spz\"}}", "/output/name"},
      {"tile_target_small", "{" + in + ", \"tiling\": {\"target_triangles\": 10}}", "/tiling/target_triangles"},
      {"threads_negative", "{" + in + ", \"threads\": -1}", "/threads"},
      {"threads_overflow", "{" + in + ", \"threads\": 1e400}", "number overflow parsing '1e400'"},
      {"threads_fraction", "{" + in + ", \"threads\": 2.5}", "/threads: must be an integer in [0, 4096], got '2.5'"},
      {"tile_target_above_limit", "{" + in + ", \"tiling\": {\"target_triangles\": 2147483649}}",
       "/tiling/target_triangles: must be an integer in [1024, 2147483648]"},
      {"seed_negative", "{" + in + ", \"measure\": {\"seed\": -1}}", "/measure/seed"},
      {"seed_beyond_64_bits", "{" + in + ", \"measure\": {\"seed\": 18446744073709551616}}", "/measure/seed"},
      {"budget_too_small", "{" + in + ", \"memory_budget_mb\": 8}", "/memory_budget_mb"},
      {"resume_number", "{" + in + ", \"resume\": 1}", "/resume"},
      {"measure_unknown_key", "{" + in + ", \"measure\": {\"enabled\": true, \"sample\": 3}}",
       "/measure/sample: unknown key"},
      {"measure_density_zero", "{" + in + ", \"measure\": {\"enabled\": true, \"samples_per_triangle\": 0}}",
       "/measure/samples_per_triangle"},
      {"measure_render_size", "{" + in + ", \"measure\": {\"enabled\": true, \"render_size\": [10, 20000]}}",
       "/measure/render_size/0"},
      {"measure_render_without_enabled", "{" + in + ", \"measure\": {\"render\": true}}", "/measure/render"},
      {"escaped_key", "{" + in + ", \"a/b\": 1}", "/a~1b: unknown key"},
      {"stages_not_array", "{" + in + ", \"stages\": {\"name\": \"smooth\"}}", "/stages: must be an array"},
      {"stage_unknown", "{" + in + ", \"stages\": [{\"name\": \"sharpen\"}]}",
       "/stages/0/name: unknown stage 'sharpen' (available: smooth, remesh)"},
      {"stage_without_name", "{" + in + ", \"stages\": [{\"iterations\": 3}]}", "/stages/0/name"},
      {"stage_unknown_key", "{" + in + ", \"stages\": [{\"name\": \"smooth\", \"sigma\": 3}]}",
       "/stages/0/sigma: unknown key"},
      {"stage_bad_mu", "{" + in + ", \"stages\": [{\"name\": \"smooth\"}, {\"name\": \"smooth\", \"mu\": -0.1}]}",
       "/stages/1/mu: must be in (-1, -lambda)"},
      {"stage_iterations", "{" + in + ", \"stages\": [{\"name\": \"smooth\", \"iterations\": 5000}]}",
       "/stages/0/iterations"},
      {"glob_matches_nothing",
       "{\"inputs\": [\"" + dir.path() + "/*.nothing\"], \"output\": {\"directory\": \"out\"}}", "/inputs/0"},
      {"output_collision",
       "{\"inputs\": [\"" + bunny + "\", \"" + dir.path() + "/bun_zipper.obj\"], \"output\": {\"directory\": \"out\"}}",
       "/output/name"},
  };
  ASSERT_GE(cases.size(), 15u);
  testing::writeBytes(dir.file("bun_zipper.obj"), "v 0 0 0\n");
  for (const auto& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string path = dir.file(std::string(c.name) + ".json");
    testing::writeBytes(path, c.json);
    std::string out;
    EXPECT_EQ(run("run '" + path + "'", &out), 1) << out;
    EXPECT_NE(out.find(path), std::string::npos) << out;
    EXPECT_NE(out.find(c.pointer), std::string::npos) << "expected '" << c.pointer << "' in: " << out;
    EXPECT_FALSE(fs::exists(dir.file("out"))) << "something was written";
  }
}

TEST(JobConfig, EveryExampleParsesAndTheReferenceListsEveryKey) {
  size_t parsed = 0;
  for (const auto& e : fs::directory_iterator(SCANPRESS_CONFIGS)) {
    if (e.path().extension() != ".json") continue;
    SCOPED_TRACE(e.path().string());
    auto job = loadJobConfig(e.path().string());
    EXPECT_TRUE(job.isOk()) << job.status().toString();
    ++parsed;
  }
  EXPECT_GE(parsed, 4u);
  const std::string ref_md = testing::readText(std::string(SCANPRESS_CONFIGS) + "/REFERENCE.md");
  const auto ref_json = nlohmann::json::parse(testing::readText(std::string(SCANPRESS_CONFIGS) + "/reference.json"));
  for (const auto& key : knownConfigKeys()) {
    EXPECT_NE(ref_md.find("`" + key + "`"), std::string::npos) << key << " missing from REFERENCE.md";
    EXPECT_TRUE(ref_json.contains(nlohmann::json::json_pointer(key))) << key << " missing from reference.json";
  }
  // Defaults in reference.json are the parser's defaults.
  auto ref = loadJobConfig(std::string(SCANPRESS_CONFIGS) + "/reference.json");
  ASSERT_TRUE(ref.isOk());
  const JobSettings defaults;
  EXPECT_EQ(ref->encode.bits, defaults.encode.bits);
  EXPECT_EQ(ref->encode.normal_bits, defaults.encode.normal_bits);
  EXPECT_EQ(ref->encode.tile_triangles, defaults.encode.tile_triangles);
  EXPECT_EQ(ref->resume, defaults.resume);
  EXPECT_EQ(ref->output_name, defaults.output_name);
  EXPECT_EQ(ref->report_name, defaults.report_name);
  EXPECT_EQ(ref->summary_name, defaults.summary_name);
}

// Stages from a job file and from the CLI's --stages are the same specs, read by the same code.
TEST(JobConfig, StagesFromJobFilesAndTheCommandLine) {
  auto job = parseJobConfig(R"({"inputs": ["a.ply"], "stages": [{"name": "smooth", "iterations": 4, "lambda": 0.5,
                                "mu": -0.53}, {"name": "smooth"}]})",
                            "/x/j.json");
  ASSERT_TRUE(job.isOk()) << job.status().toString();
  ASSERT_EQ(job->encode.stages.size(), 2u);
  EXPECT_EQ(job->encode.stages[0].kind, StageKind::kSmooth);
  EXPECT_EQ(job->encode.stages[0].smooth.iterations, 4);
  EXPECT_EQ(job->encode.stages[0].smooth.lambda, 0.5);
  EXPECT_EQ(job->encode.stages[0].smooth.mu, -0.53);
  EXPECT_EQ(job->encode.stages[1].smooth.iterations, SmoothOptions{}.iterations);
  auto cli = parseStagesOption("smooth:iterations=4:lambda=0.5:mu=-0.53,smooth", "--stages");
  ASSERT_TRUE(cli.isOk()) << cli.status().toString();
  ASSERT_EQ(cli->size(), 2u);
  EXPECT_EQ((*cli)[0].smooth.iterations, 4);
  EXPECT_EQ((*cli)[0].smooth.mu, -0.53);
  EXPECT_NE(parseStagesOption("smooth:iterations", "--stages").status().message().find("KEY=VALUE"), std::string::npos);
  EXPECT_NE(parseStagesOption("smooth:lambda=2", "--stages").status().message().find("--stages: /stages/0/lambda"),
            std::string::npos);
  EXPECT_NE(parseStagesOption("blur", "--stages").status().message().find("unknown stage 'blur'"), std::string::npos);
  auto remesh = parseStagesOption("remesh:grid=0.01:tau=0.15,remesh", "--stages");
  ASSERT_TRUE(remesh.isOk()) << remesh.status().toString();
  EXPECT_EQ((*remesh)[0].kind, StageKind::kRemesh);
  EXPECT_EQ((*remesh)[0].remesh.grid, 0.01);
  EXPECT_EQ((*remesh)[0].remesh.tau, 0.15);
  EXPECT_EQ((*remesh)[1].remesh.grid, RemeshStageOptions{}.grid);
  EXPECT_NE(parseStagesOption("remesh:grid=0", "--stages").status().message().find("/stages/0/grid"),
            std::string::npos);
  EXPECT_NE(parseStagesOption("remesh:tau=0.6", "--stages").status().message().find("/stages/0/tau"),
            std::string::npos);
  EXPECT_NE(parseStagesOption("remesh:lambda=0.5", "--stages").status().message().find("unknown key"),
            std::string::npos);
}

TEST(JobConfig, RelativePathsAreRelativeToTheJobFile) {
  auto job = parseJobConfig(R"({"inputs": ["scans/a.ply"], "output": {"directory": "../out"}})", "/x/jobs/j.json");
  ASSERT_TRUE(job.isOk()) << job.status().toString();
  EXPECT_EQ(job->inputs[0], "/x/jobs/scans/a.ply");
  EXPECT_EQ(job->output_directory, "/x/out");
}

TEST(JobConfig, NumbersParseAsOnTheCommandLine) {
  const char* text = R"({"inputs": ["a.ply"], "threads": 2.0, "tiling": {"target_triangles": 2147483648},
                         "measure": {"seed": 18446744073709551615, "samples": 1e6}})";
  auto job = parseJobConfig(text, "/x/j.json");
  ASSERT_TRUE(job.isOk()) << job.status().toString();
  EXPECT_EQ(job->encode.threads, 2);
  EXPECT_EQ(job->encode.tile_triangles, kMaxTileTriangles);
  EXPECT_EQ(job->encode.measure.seed, UINT64_MAX);
  EXPECT_EQ(job->encode.measure.samples, 1000000u);
}

TEST(Batch, BadFileIsReportedOthersCompleteResumeSkipsForceRedoes) {
  testing::TempDir dir;
  fs::create_directories(dir.file("scans"));
  fs::copy_file(std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst", dir.file("scans/bunny.ply.zst"));
  ASSERT_TRUE(writeObj(dir.file("scans/octa.obj"), testing::octahedron()).isOk());
  testing::writeBytes(dir.file("scans/broken.ply"), "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n");
  testing::writeBytes(dir.file("scans/notes.txt"), "not a mesh");
  const std::string job = dir.file("job.json");
  auto writeJob = [&](int bits) {
    testing::writeBytes(job, "{\"inputs\": [\"scans\"], \"output\": {\"directory\": \"out\"}, \"codec\": {\"bits\": " +
                                 std::to_string(bits) + "}}");
  };
  writeJob(16);
  std::string out;
  EXPECT_EQ(run("run '" + job + "' --quiet", &out), 2) << out;
  auto summary = nlohmann::json::parse(testing::readText(dir.file("out/summary.json")));
  ASSERT_EQ(summary["files"].size(), 3u);
  std::map<std::string, std::string> status;
  for (const auto& f : summary["files"]) status[fs::path(f["input"].get<std::string>()).filename()] = f["status"];
  EXPECT_EQ(status["bunny.ply.zst"], "ok");
  EXPECT_EQ(status["octa.obj"], "ok");
  EXPECT_EQ(status["broken.ply"], "failed");
  for (const auto& f : summary["files"]) {
    if (f["status"] == "failed") {
      EXPECT_NE(f["error"].get<std::string>().find("broken.ply"), std::string::npos);
      EXPECT_EQ(f["exit_code"], 2);
      EXPECT_FALSE(f.contains("report")) << "the summary names a report that was never written";
    } else {
      EXPECT_GT(f["bpv"].get<double>(), 0);
      EXPECT_TRUE(fs::exists(f["report"].get<std::string>()));
    }
  }
  const auto first_totals = summary["totals"];
  EXPECT_GT(first_totals["bytes"].get<uint64_t>(), 0u);
  EXPECT_TRUE(fs::exists(dir.file("out/bunny.spz")));
  EXPECT_TRUE(fs::exists(dir.file("out/octa.report.json")));
  EXPECT_FALSE(fs::exists(dir.file("out/broken.spz")));
  const auto first_time = fs::last_write_time(dir.file("out/bunny.spz"));

  // Resume: complete outputs with the same settings are skipped.
  EXPECT_EQ(run("run '" + job + "' --quiet", &out), 2);
  summary = nlohmann::json::parse(testing::readText(dir.file("out/summary.json")));
  for (const auto& f : summary["files"]) {
    if (fs::path(f["input"].get<std::string>()).filename() != "broken.ply") {
      EXPECT_EQ(f["status"], "skipped");
      EXPECT_GT(f["bpv"].get<double>(), 0);  // from the skipped output's report
      EXPECT_TRUE(f.contains("report"));
    }
  }
  // A resumed run's totals count the skipped outputs: the same bytes and vertices as the run that made them.
  EXPECT_EQ(summary["totals"]["bytes"], first_totals["bytes"]);
  EXPECT_EQ(summary["totals"]["vertices"], first_totals["vertices"]);
  EXPECT_EQ(summary["totals"]["bpv"], first_totals["bpv"]);
  EXPECT_EQ(fs::last_write_time(dir.file("out/bunny.spz")), first_time);

  // A truncated container is not complete: it is redone.
  fs::resize_file(dir.file("out/octa.spz"), 40);
  EXPECT_EQ(run("run '" + job + "' --quiet", &out), 2);
  summary = nlohmann::json::parse(testing::readText(dir.file("out/summary.json")));
  for (const auto& f : summary["files"]) {
    if (fs::path(f["input"].get<std::string>()).filename() == "octa.obj") {
      EXPECT_EQ(f["status"], "ok");
    }
  }

  // Other settings: redone. --force: redone.
  writeJob(12);
  EXPECT_EQ(run("run '" + job + "' --quiet", &out), 2);
  summary = nlohmann::json::parse(testing::readText(dir.file("out/summary.json")));
  EXPECT_EQ(summary["totals"]["ok"], 2);
  EXPECT_EQ(run("run '" + job + "' --quiet --force", &out), 2);
  summary = nlohmann::json::parse(testing::readText(dir.file("out/summary.json")));
  EXPECT_EQ(summary["totals"]["ok"], 2);
  EXPECT_EQ(summary["totals"]["skipped"], 0);
  for (const auto& e : fs::directory_iterator(dir.file("out"))) {
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos);
  }

  // Without the bad file the job succeeds.
  fs::remove(dir.file("scans/broken.ply"));
  EXPECT_EQ(run("run '" + job + "' --quiet", &out), 0) << out;
}

TEST(Batch, OutputNames) {
  EXPECT_EQ(outputName("{stem}.spz", "/a/b/scan.ply.zst"), "scan.spz");
  EXPECT_EQ(outputName("{stem}.spz", "/a/b/SCAN.PLY"), "SCAN.spz");
  EXPECT_EQ(outputName("{name}.spz", "/a/b/scan.obj"), "scan.obj.spz");
  EXPECT_EQ(outputName("x-{stem}-{stem}.spz", "scan.stl"), "x-scan-scan.spz");
  EXPECT_EQ(outputName("{dir}/{stem}.spz", "/a/b/scan.ply", "b"), "b/scan.spz");
  EXPECT_EQ(outputName("{dir}/{stem}.spz", "/a/b/scan.ply", "a/b"), "a/b/scan.spz");
  EXPECT_EQ(outputName("{dir}/{stem}.spz", "scan.ply", ""), "scan.spz");
}

// Archives are often scan_001/mesh.obj, scan_002/mesh.obj: `{dir}` mirrors the input's subfolder (created in the
// output directory), globs match in directory components and `**` spans any depth; without `{dir}` such inputs
// collide, which is an error before anything is written.
TEST(Batch, SubfoldersMirrorInputsAndGlobsSpanDirectories) {
  testing::TempDir dir;
  for (const char* sub : {"archive/scan_001", "archive/scan_002", "archive/deep/x/scan_003", "archive/.hidden"}) {
    fs::create_directories(dir.file(sub));
    ASSERT_TRUE(writeObj(dir.file(std::string(sub) + "/mesh.obj"), testing::octahedron()).isOk());
  }
  const std::string job = dir.file("job.json");
  std::string out;
  auto runWith = [&](const std::string& inputs, const std::string& extra, const std::string& out_dir) {
    testing::writeBytes(job, "{\"inputs\": " + inputs + ", \"output\": {\"directory\": \"" + out_dir +
                                 "\", \"name\": \"{dir}/{stem}.spz\", \"report\": \"{dir}/{stem}.json\"}" + extra +
                                 "}");
    return run("run '" + job + "' --quiet", &out);
  };
  ASSERT_EQ(runWith("[\"archive/**/mesh.obj\"]", "", "o1"), 0) << out;
  for (const char* f : {"o1/scan_001/mesh.spz", "o1/scan_002/mesh.spz", "o1/deep/x/scan_003/mesh.spz",
                        "o1/scan_001/mesh.json", "o1/deep/x/scan_003/mesh.json"})
    EXPECT_TRUE(fs::is_regular_file(dir.file(f))) << f;
  EXPECT_FALSE(fs::exists(dir.file("o1/.hidden"))) << "wildcards do not match hidden names";
  EXPECT_EQ(nlohmann::json::parse(testing::readText(dir.file("o1/summary.json")))["files"].size(), 3u);
  ASSERT_EQ(runWith("[\"archive/scan_*/mesh.obj\"]", "", "o2"), 0) << out;
  EXPECT_TRUE(fs::is_regular_file(dir.file("o2/scan_002/mesh.spz")));
  EXPECT_FALSE(fs::exists(dir.file("o2/deep")));
  ASSERT_EQ(runWith("[\"archive\"]", ", \"recursive\": true", "o3"), 0) << out;
  EXPECT_TRUE(fs::is_regular_file(dir.file("o3/deep/x/scan_003/mesh.spz")));
  EXPECT_TRUE(fs::is_regular_file(dir.file("o3/.hidden/mesh.spz")));  // a directory input takes every mesh file
  // Without {dir} the inputs collide.
  testing::writeBytes(job, R"({"inputs": ["archive/**/mesh.obj"], "output": {"directory": "o4"}})");
  EXPECT_EQ(run("run '" + job + "' --quiet", &out), 1);
  EXPECT_NE(out.find("two inputs map to the output"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir.file("o4/mesh.spz")));
  // `**` must lead to a file name; `{dir}` cannot smuggle `..` or a folder into the summary.
  testing::writeBytes(job, R"({"inputs": ["archive/**"]})");
  EXPECT_EQ(run("run '" + job + "' --quiet", &out), 1);
  EXPECT_NE(out.find("'**' must be followed by a file name pattern"), std::string::npos) << out;
  testing::writeBytes(job, R"({"inputs": ["archive"], "output": {"name": "{dir}/../{stem}.spz"}})");
  EXPECT_EQ(run("run '" + job + "' --quiet", &out), 1);
  EXPECT_NE(out.find("/output/name: must be a file name"), std::string::npos) << out;
  testing::writeBytes(job, R"({"inputs": ["archive"], "output": {"summary": "{dir}/s.json"}})");
  EXPECT_EQ(run("run '" + job + "' --quiet", &out), 1);
  EXPECT_NE(out.find("/output/summary"), std::string::npos) << out;
}

// What people read of a batch: one line per file with the ratio to the input's size and the measured error, a
// totals line; the summary carries per file the input size, the ratio and the error, and totals. A resumed run
// reports the same figures for the files it skips (from their reports).
TEST(Batch, ResultsPeopleRead) {
  testing::TempDir dir;
  fs::create_directories(dir.file("scans"));
  fs::copy_file(std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst", dir.file("scans/bunny.ply.zst"));
  ASSERT_TRUE(writeObj(dir.file("scans/octa.obj"), testing::octahedron()).isOk());
  const std::string job = dir.file("job.json");
  testing::writeBytes(job, R"({"inputs": ["scans"], "output": {"directory": "out"}, "codec": {"name": "kdtree",
                              "bits": 12}, "measure": {"enabled": true}})");
  std::string out;
  ASSERT_EQ(run("run '" + job + "'", &out), 0) << out;
  EXPECT_NE(out.find("bunny.spz: 69451 triangles"), std::string::npos) << out;
  EXPECT_NE(out.find(":1), "), std::string::npos) << out;
  EXPECT_NE(out.find(", error rms "), std::string::npos) << out;
  EXPECT_NE(out.find("2 files: 2 ok, 0 skipped, 0 failed; "), std::string::npos) << out;
  auto check = [&](const nlohmann::json& summary) {
    uint64_t total_in = 0;
    for (const auto& f : summary["files"]) {
      const uint64_t in = fs::file_size(f["input"].get<std::string>());
      EXPECT_EQ(f["input_bytes"], in);
      EXPECT_DOUBLE_EQ(f["ratio"].get<double>(), double(in) / f["bytes"].get<double>());
      EXPECT_EQ(f["bytes"], fs::file_size(f["output"].get<std::string>()));
      EXPECT_GT(f["error_rms_relative"].get<double>(), 0);  // 12 bits: quantization error
      EXPECT_LE(f["error_rms_relative"].get<double>(), f["error_max_relative"].get<double>());
      EXPECT_LT(f["error_max_relative"].get<double>(), 1.0 / 4096);
      total_in += in;
    }
    EXPECT_EQ(summary["totals"]["input_bytes"], total_in);
    EXPECT_GT(summary["totals"]["worst_error_max_relative"].get<double>(), 0);
  };
  const auto first = nlohmann::json::parse(testing::readText(dir.file("out/summary.json")));
  check(first);
  ASSERT_EQ(run("run '" + job + "'", &out), 0) << out;
  EXPECT_NE(out.find("2 files: 0 ok, 2 skipped, 0 failed; "), std::string::npos) << out;
  const auto resumed = nlohmann::json::parse(testing::readText(dir.file("out/summary.json")));
  check(resumed);
  for (size_t i = 0; i < 2; ++i)
    EXPECT_EQ(resumed["files"][i]["error_rms_relative"], first["files"][i]["error_rms_relative"]);
  EXPECT_EQ(resumed["totals"]["ratio"], first["totals"]["ratio"]);
}

TEST(Shards, ParseNameAndSplit) {
  EXPECT_EQ(parseShard("2/4", "--shard")->index, 2u);
  EXPECT_EQ(parseShard("2/4", "--shard")->count, 4u);
  for (const char* bad : {"4/4", "1", "-1/3", "1/0", "a/b", "1/65537", "1/3/4"})
    EXPECT_FALSE(parseShard(bad, "--shard").isOk()) << bad;
  EXPECT_EQ(shardSummaryName("summary.json", Shard{2, 4}), "summary.shard-2-of-4.json");
  EXPECT_EQ(shardSummaryName("summary", Shard{0, 1}), "summary.shard-0-of-1");
  // Every input in exactly one shard; loads within the largest input of each other.
  std::vector<JobInput> inputs;
  std::vector<uint64_t> sizes;
  for (int i = 0; i < 37; ++i) {
    inputs.push_back({std::to_string(100 + i), ""});
    sizes.push_back(uint64_t(1000 + (i * 7919) % 5000));
  }
  for (uint32_t n : {1u, 2u, 3u, 8u, 50u}) {
    std::map<std::string, int> seen;
    uint64_t lo = UINT64_MAX, hi = 0;
    for (uint32_t i = 0; i < n; ++i) {
      uint64_t load = 0;
      for (const auto& in : shardInputs(inputs, sizes, Shard{i, n})) {
        ++seen[in.path];
        load += sizes[std::stoi(in.path) - 100];
      }
      lo = std::min(lo, load), hi = std::max(hi, load);
    }
    EXPECT_EQ(seen.size(), inputs.size()) << n;
    for (const auto& [path, times] : seen) EXPECT_EQ(times, 1) << path;
    if (n <= inputs.size()) {
      EXPECT_LE(hi - lo, *std::max_element(sizes.begin(), sizes.end())) << n;
    }
  }
}

// A job split over three array tasks (by --shard and by Slurm's environment) writes the same containers as one
// process, and --merge gives the same summary entries; a missing shard or an input no shard covered is an error.
TEST(Shards, ArrayTasksAndMergeEqualOneProcess) {
  testing::TempDir dir;
  fs::create_directories(dir.file("scans"));
  fs::copy_file(std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst", dir.file("scans/bunny.ply.zst"));
  for (int i = 0; i < 5; ++i)
    ASSERT_TRUE(writeObj(dir.file("scans/octa" + std::to_string(i) + ".obj"), testing::octahedron()).isOk());
  auto writeJob = [&](const std::string& name, const std::string& out_dir) {
    testing::writeBytes(dir.file(name), "{\"inputs\": [\"scans\"], \"output\": {\"directory\": \"" + out_dir +
                                            "\"}, \"codec\": {\"name\": \"kdtree\", \"bits\": 12}}");
    return dir.file(name);
  };
  const std::string whole = writeJob("whole.json", "whole"), split = writeJob("split.json", "split");
  std::string out;
  ASSERT_EQ(run("run '" + whole + "' --quiet", &out), 0) << out;
  ASSERT_EQ(run("run '" + split + "' --quiet --shard 0/3", &out), 0) << out;
  ASSERT_EQ(testing::runScanpress("run '" + split + "' --quiet", &out,
                                  "SLURM_ARRAY_TASK_ID=5 SLURM_ARRAY_TASK_MIN=4 SLURM_ARRAY_TASK_COUNT=3"),
            0)
      << out;
  EXPECT_TRUE(fs::exists(dir.file("split/summary.shard-1-of-3.json")));
  // Before the last shard ran, merging names it.
  EXPECT_EQ(run("run '" + split + "' --merge", &out), 3);
  EXPECT_NE(out.find("no summary of shard 2 of 3"), std::string::npos) << out;
  ASSERT_EQ(run("run '" + split + "' --quiet --shard 2/3", &out), 0) << out;
  ASSERT_EQ(run("run '" + split + "' --merge", &out), 0) << out;
  EXPECT_NE(out.find("merged 6 files"), std::string::npos) << out;
  const auto a = nlohmann::json::parse(testing::readText(dir.file("whole/summary.json")));
  const auto b = nlohmann::json::parse(testing::readText(dir.file("split/summary.json")));
  ASSERT_EQ(a["files"].size(), 6u);
  ASSERT_EQ(b["files"].size(), 6u);
  for (size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(a["files"][i]["input"], b["files"][i]["input"]);
    EXPECT_EQ(a["files"][i]["bytes"], b["files"][i]["bytes"]);
    const std::string name = fs::path(a["files"][i]["output"].get<std::string>()).filename();
    EXPECT_EQ(testing::readText(dir.file("whole/" + name)), testing::readText(dir.file("split/" + name))) << name;
  }
  EXPECT_EQ(a["totals"]["bytes"], b["totals"]["bytes"]);
  EXPECT_EQ(b["shards"], 3);
  // An input added after the shards ran is in no shard's summary.
  ASSERT_TRUE(writeObj(dir.file("scans/late.obj"), testing::octahedron()).isOk());
  EXPECT_EQ(run("run '" + split + "' --merge", &out), 3);
  EXPECT_NE(out.find("late.obj: in no shard's summary"), std::string::npos) << out;
  // Wrong uses.
  EXPECT_EQ(run("run '" + split + "' --shard 3/3", &out), 1);
  EXPECT_EQ(testing::runScanpress("run '" + split + "'", &out, "JOB_COMPLETION_INDEX=1"), 1);
  EXPECT_NE(out.find("--shard-count"), std::string::npos) << out;
  EXPECT_EQ(testing::runScanpress("run '" + split + "' --quiet --shard-count 3", &out, "JOB_COMPLETION_INDEX=1"), 0)
      << out;
  EXPECT_EQ(testing::runScanpress("run '" + split + "'", &out, "SLURM_ARRAY_TASK_ID=7 SLURM_ARRAY_TASK_COUNT=3"), 1);
  EXPECT_NE(out.find("not in [SLURM_ARRAY_TASK_MIN"), std::string::npos) << out;
}

// /strict: an input holding what the container would not keep fails (exit 2, naming it); the others run; the
// setting is part of the resume fingerprint (a complete output made without it is redone, and fails).
// An exception while one input is encoded (here thrown before its survey; in the field, out of memory or a bug)
// fails that input as a summary entry: the other inputs still run and the summary is written (it used to leave
// runJob and end the whole batch without a summary).
TEST(Batch, ExceptionInOneInputFailsOnlyThatInput) {
  testing::TempDir dir;
  fs::create_directories(dir.file("scans"));
  for (const char* name : {"a", "b", "c"})
    ASSERT_TRUE(writeObj(dir.file(std::string("scans/") + name + ".obj"), testing::octahedron()).isOk());
  testing::writeBytes(dir.file("job.json"), R"({"inputs": ["scans"], "output": {"directory": "out"}})");
  auto job = loadJobConfig(dir.file("job.json"));
  ASSERT_TRUE(job.isOk()) << job.status().toString();
  PipelineHooks hooks;
  hooks.before_survey = [](const std::string& input) {
    if (fs::path(input).filename() == "b.obj") throw std::runtime_error("injected exception (test)");
  };
  RunOptions options;
  options.quiet = true;
  auto batch = runJob(*job, options, &hooks);
  ASSERT_TRUE(batch.isOk()) << batch.status().toString();
  ASSERT_EQ(batch->files.size(), 3u);
  for (const auto& f : batch->files) {
    const std::string name = fs::path(f.input).filename();
    if (name == "b.obj") {
      EXPECT_EQ(f.state, FileOutcome::State::kFailed);
      EXPECT_EQ(f.error.code(), ErrorCode::kInternal);
      EXPECT_NE(f.error.toString().find("injected exception (test)"), std::string::npos) << f.error.toString();
      EXPECT_NE(f.error.toString().find("b.obj"), std::string::npos) << f.error.toString();
    } else {
      EXPECT_EQ(f.state, FileOutcome::State::kOk) << name;
      EXPECT_TRUE(fs::exists(f.output)) << name;
    }
  }
  EXPECT_EQ(batch->exitCode(), 4);
  const auto summary = nlohmann::json::parse(testing::readText(dir.file("out/summary.json")));
  EXPECT_EQ(summary["files"].size(), 3u);
}

// Two jobs writing into one directory: the second replaces the first's summary, and says so.
TEST(Batch, ReplacingAnotherJobsSummaryIsWarned) {
  testing::TempDir dir;
  fs::create_directories(dir.file("scans"));
  ASSERT_TRUE(writeObj(dir.file("scans/octa.obj"), testing::octahedron()).isOk());
  const std::string first = dir.file("first.json"), second = dir.file("second.json");
  testing::writeBytes(first, R"({"inputs": ["scans"], "output": {"directory": "out"}})");
  testing::writeBytes(second, R"({"inputs": ["scans"], "output": {"directory": "out", "name": "{stem}.2.spz",
                                  "report": "{stem}.2.report.json"}})");
  std::string out;
  ASSERT_EQ(run("run '" + first + "' --quiet", &out), 0) << out;
  ASSERT_EQ(run("run '" + first + "' --quiet", &out), 0) << out;  // its own summary: no word
  EXPECT_EQ(out.find("replacing the summary"), std::string::npos) << out;
  ASSERT_EQ(run("run '" + second + "' --quiet", &out), 0) << out;
  EXPECT_NE(out.find("replacing the summary of another job (" + first + ")"), std::string::npos) << out;
  EXPECT_EQ(nlohmann::json::parse(testing::readText(dir.file("out/summary.json")))["job"], second);
}

TEST(Batch, StrictFailsInputsThatWouldDropData) {
  testing::TempDir dir;
  fs::create_directories(dir.file("scans"));
  testing::writeBytes(dir.file("scans/tex.obj"), "g part\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1\n");
  ASSERT_TRUE(writeObj(dir.file("scans/octa.obj"), testing::octahedron()).isOk());
  const std::string job = dir.file("job.json");
  auto writeJob = [&](bool strict) {
    testing::writeBytes(job, std::string("{\"inputs\": [\"scans\"], \"output\": {\"directory\": \"out\"}, ") +
                                 "\"strict\": " + (strict ? "true" : "false") + "}");
  };
  writeJob(false);
  std::string out;
  EXPECT_EQ(run("run '" + job + "'", &out), 0) << out;
  EXPECT_NE(out.find("scanpress: warning: " + dir.file("scans/tex.obj") + ": dropped obj g x 1"), std::string::npos)
      << out;
  auto report = nlohmann::json::parse(testing::readText(dir.file("out/tex.report.json")));
  ASSERT_EQ(report["dropped"].size(), 1u);

  writeJob(true);
  EXPECT_EQ(run("run '" + job + "' --quiet", &out), 2) << out;
  const auto summary = nlohmann::json::parse(testing::readText(dir.file("out/summary.json")));
  for (const auto& f : summary["files"]) {
    const std::string name = fs::path(f["input"].get<std::string>()).filename();
    if (name == "tex.obj") {
      EXPECT_EQ(f["status"], "failed");
      EXPECT_EQ(f["exit_code"], 2);
      EXPECT_NE(f["error"].get<std::string>().find("strict: the container would not keep obj g x 1"), std::string::npos)
          << f["error"];
    } else {
      EXPECT_EQ(f["status"], "ok") << name;  // redone: strict is in the fingerprint
    }
  }
  auto settings = loadJobConfig(job);
  ASSERT_TRUE(settings.isOk());
  EXPECT_TRUE(settings->encode.strict);
  EncodeSettings lax = settings->encode;
  lax.input = dir.file("scans/octa.obj");
  EncodeSettings strict = lax;
  lax.strict = false;
  EXPECT_NE(settingsFingerprint(lax), settingsFingerprint(strict));
}

// A job path that is a directory says so (it read as "invalid JSON: byte 1").
TEST(JobConfig, ADirectoryIsNotAJobFile) {
  testing::TempDir dir;
  std::string out;
  EXPECT_EQ(run("run '" + dir.path() + "'", &out), 1);
  EXPECT_NE(out.find(dir.path() + ": is a directory, not a job file"), std::string::npos) << out;
  EXPECT_EQ(out.find("invalid JSON"), std::string::npos) << out;
}

}  // namespace
}  // namespace scanpress
