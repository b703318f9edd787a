// The scanpress binary: exit codes, help, JSON outputs, all-or-nothing outputs.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "engine/quantize.h"
#include "engine/shapes.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs_util.h"

namespace scanpress {
namespace {

using testing::kBunny;
using testing::run;

namespace fs = std::filesystem;

// Files in `dir` whose names contain ".tmp-" (left-over temporaries).
int temporaries(const std::string& dir) {
  int n = 0;
  for (const auto& e : fs::directory_iterator(dir))
    n += e.path().filename().string().find(".tmp-") != std::string::npos;
  return n;
}

TEST(Cli, UsageErrorsExitOne) {
  std::string out;
  EXPECT_EQ(run("", &out), 1);
  EXPECT_EQ(run("frobnicate", &out), 1);
  EXPECT_NE(out.find("unknown command"), std::string::npos);
  EXPECT_EQ(run("encode onlyone", &out), 1);
  EXPECT_EQ(run("encode a b --bits 99", &out), 1);
  EXPECT_NE(out.find("--bits"), std::string::npos);
  EXPECT_EQ(run("encode a b --codec nope", &out), 1);
  EXPECT_EQ(run("encode a b --what", &out), 1);
  EXPECT_EQ(run("decode a.spz b.ply --tiles 1,x", &out), 1);
  EXPECT_NE(out.find("--tiles: must be an integer"), std::string::npos) << out;
  EXPECT_EQ(run("encode a b --tile-triangles 2147483649", &out), 1);
  EXPECT_NE(out.find("--tile-triangles: must be an integer in [1024, 2147483648]"), std::string::npos) << out;
  EXPECT_EQ(run("encode a b --memory-budget 8M", &out), 1);
  EXPECT_NE(out.find("--memory-budget: must be 0 or at least 16M"), std::string::npos) << out;
  EXPECT_EQ(run("encode a b --memory-budget 2X", &out), 1);
  EXPECT_NE(out.find("--memory-budget: must be a size"), std::string::npos) << out;
  for (const char* seed : {"-1", "1.5", "18446744073709551616", "x"}) {
    EXPECT_EQ(run(std::string("measure a b --seed ") + seed, &out), 1) << seed;
    EXPECT_NE(out.find("--seed: must be a non-negative integer"), std::string::npos) << out;
    EXPECT_EQ(run(std::string("synth a.ply --triangles 10 --seed ") + seed, &out), 1) << seed;
    EXPECT_NE(out.find("--seed: must be a non-negative integer"), std::string::npos) << out;
  }
}

// --seed is an unsigned 64-bit integer in measure and in synth alike (measure read a double: 2^64-1
// overflowed).
TEST(Cli, SeedsAreUnsigned64BitIntegersEverywhere) {
  testing::TempDir dir;
  std::string out;
  const std::string a = dir.file("a.ply"), b = dir.file("b.ply");
  ASSERT_EQ(run("synth '" + a + "' --triangles 2e3 --seed 18446744073709551615 --quiet", &out), 0) << out;
  ASSERT_EQ(run("synth '" + b + "' --triangles 2000 --seed 1e19 --quiet", &out), 0) << out;
  ASSERT_EQ(run("measure '" + a + "' '" + b + "' --seed 18446744073709551615 --samples 1e4 --json", &out), 0) << out;
  const auto high = nlohmann::json::parse(out);
  ASSERT_EQ(run("measure '" + a + "' '" + b + "' --seed 7 --samples 10000 --json", &out), 0) << out;
  EXPECT_NE(nlohmann::json::parse(out), high);  // the seed reaches the sampler whole
}

TEST(Cli, HelpOnEveryCommand) {
  std::string out;
  for (const char* c : {"--help", "encode --help", "decode --help", "info --help", "help encode"}) {
    EXPECT_EQ(run(c, &out), 0) << c;
    EXPECT_NE(out.find("usage"), std::string::npos) << c;
  }
}

TEST(Cli, EncodeInfoDecodeWithReport) {
  testing::TempDir dir;
  std::string out;
  ASSERT_EQ(run("encode '" + kBunny + "' '" + dir.file("b.spz") + "' --report '" + dir.file("r.json") + "'", &out), 0)
      << out;
  const auto report = nlohmann::json::parse(std::ifstream(dir.file("r.json")));
  for (const char* key : {"input", "vertices", "faces", "bytes", "bpv", "seconds", "degenerate_triangles_dropped",
                          "unreferenced_vertices_dropped"})
    EXPECT_TRUE(report.contains(key)) << key;
  EXPECT_EQ(report["unreferenced_vertices_dropped"], 1113);
  EXPECT_EQ(report["bytes"], fs::file_size(dir.file("b.spz")));
  EXPECT_NEAR(report["bpv"].get<double>(), 8.0 * report["bytes"].get<double>() / report["vertices"].get<double>(),
              1e-9);
  for (const char* stage : {"read", "quantize", "encode", "write"}) EXPECT_TRUE(report["seconds"].contains(stage));

  ASSERT_EQ(run("info '" + dir.file("b.spz") + "' --json --verify", &out), 0) << out;
  const auto info = nlohmann::json::parse(out);
  EXPECT_EQ(info["grid"]["bits"], 16);
  EXPECT_EQ(info["grid"]["origin"].size(), 3u);
  EXPECT_GT(info["grid"]["cell"].get<double>(), 0);
  EXPECT_EQ(info["vertices"], 34834);
  EXPECT_EQ(info["faces"], 69451);
  EXPECT_EQ(info["bytes"], fs::file_size(dir.file("b.spz")));
  ASSERT_EQ(info["tiles"].size(), 1u);
  for (const char* key : {"id", "codec", "bytes", "vertices", "faces"}) EXPECT_TRUE(info["tiles"][0].contains(key));
  EXPECT_EQ(info["tiles"][0]["codec"], "edgebreaker");  // the default

  ASSERT_EQ(run("decode '" + dir.file("b.spz") + "' '" + dir.file("b.obj") + "' --tiles 0", &out), 0) << out;
  EXPECT_TRUE(fs::exists(dir.file("b.obj")));
  EXPECT_EQ(run("decode '" + dir.file("b.spz") + "' '" + dir.file("c.ply") + "' --tiles 5", &out), 1);
  EXPECT_FALSE(fs::exists(dir.file("c.ply")));
  EXPECT_EQ(temporaries(dir.path()), 0);
}

// --color-bits N keeps 2^N levels per channel: the report and info name them, every decoded color is the level
// nearest the input's; out-of-range values are usage errors.
TEST(Cli, ColorBitsKeepTheNearestLevel) {
  testing::TempDir dir;
  Mesh sphere = icosphere(3);
  for (const auto& p : sphere.positions)
    sphere.colors.push_back({uint8_t(128 + 127 * p[0]), uint8_t(128 + 90 * p[1]), uint8_t(128 + 60 * p[2]), 255});
  sphere.color_channels = 3;
  ASSERT_TRUE(writePly(dir.file("s.ply"), sphere).isOk());
  std::string out;
  for (const char* codec : {"kdtree", "edgebreaker", "store"}) {
    SCOPED_TRACE(codec);
    ASSERT_EQ(run("encode '" + dir.file("s.ply") + "' '" + dir.file("s.spz") + "' --color-bits 5 --codec " + codec +
                      " --report '" + dir.file("r.json") + "'",
                  &out),
              0)
        << out;
    const auto report = nlohmann::json::parse(std::ifstream(dir.file("r.json")));
    EXPECT_EQ(report["attributes"]["color_bits"], 5);
    ASSERT_EQ(run("info '" + dir.file("s.spz") + "' --json", &out), 0) << out;
    EXPECT_EQ(nlohmann::json::parse(out)["attributes"]["color_bits"], 5);
    ASSERT_EQ(run("decode '" + dir.file("s.spz") + "' '" + dir.file("d.ply") + "'", &out), 0) << out;
    auto decoded = readMeshFile(dir.file("d.ply"));
    ASSERT_TRUE(decoded.isOk());
    ASSERT_EQ(decoded->colors.size(), sphere.colors.size());
    // Match vertices by position (the grid keeps the sphere's vertices apart).
    for (size_t i = 0; i < decoded->positions.size(); ++i) {
      size_t best = 0;
      double best_d = 1e300;
      for (size_t j = 0; j < sphere.positions.size(); ++j) {
        double d = 0;
        for (int a = 0; a < 3; ++a) d += std::pow(decoded->positions[i][a] - sphere.positions[j][a], 2);
        if (d < best_d) best_d = d, best = j;
      }
      for (int c = 0; c < 3; ++c) {
        const int level = colorLevel(sphere.colors[best][c], 5);
        EXPECT_EQ(decoded->colors[i][c], colorOfLevel(level, 5)) << i << " channel " << c;
        EXPECT_LE(std::abs(int(decoded->colors[i][c]) - int(sphere.colors[best][c])), 5);  // half of 255/31
      }
    }
  }
  EXPECT_EQ(run("encode '" + dir.file("s.ply") + "' '" + dir.file("t.spz") + "' --color-bits 0", &out), 1);
  EXPECT_EQ(run("encode '" + dir.file("s.ply") + "' '" + dir.file("t.spz") + "' --color-bits 9", &out), 1);
  EXPECT_FALSE(fs::exists(dir.file("t.spz")));
}

// kdtree containers list their levels; decode --level and --bytes give coarser meshes; single-rate codecs and
// impossible budgets are usage errors that write nothing.
TEST(Cli, ProgressiveDecodeByLevelAndBytes) {
  testing::TempDir dir;
  const std::string in = std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
  std::string out;
  for (const char* codec : {"kdtree", "octree"}) {
    SCOPED_TRACE(codec);
    const std::string spz = dir.file(std::string(codec) + ".spz");
    ASSERT_EQ(run("encode '" + in + "' '" + spz + "' --codec " + codec + " --bits 12 --tile-triangles 20000 --quiet",
                  &out),
              0)
        << out;
    ASSERT_EQ(run("info '" + spz + "' --json --verify", &out), 0) << out;
    const auto info = nlohmann::json::parse(out);
    ASSERT_TRUE(info.contains("levels"));
    const auto& levels = info["levels"];
    ASSERT_EQ(levels.size(), 13u);
    for (size_t l = 1; l < levels.size(); ++l) EXPECT_GE(levels[l]["bytes"], levels[l - 1]["bytes"]);
    EXPECT_GT(info["tiles"].size(), 1u);
    EXPECT_TRUE(info["tiles"][0].contains("levels"));

    ASSERT_EQ(run("decode '" + spz + "' '" + dir.file("full.ply") + "'", &out), 0) << out;
    ASSERT_EQ(run("decode '" + spz + "' '" + dir.file("l6.ply") + "' --level 6", &out), 0) << out;
    EXPECT_NE(out.find("level 6: " + std::to_string(levels[6]["bytes"].get<uint64_t>()) + " payload bytes"),
              std::string::npos)
        << out;
    EXPECT_LT(fs::file_size(dir.file("l6.ply")), fs::file_size(dir.file("full.ply")));
    // The finest level within a budget: exactly level 8's bytes gives level 8.
    const uint64_t b8 = levels[8]["bytes"].get<uint64_t>();
    ASSERT_EQ(run("decode '" + spz + "' '" + dir.file("b.ply") + "' --bytes " + std::to_string(b8), &out), 0) << out;
    EXPECT_NE(out.find("level 8:"), std::string::npos) << out;
    ASSERT_EQ(run("decode '" + spz + "' '" + dir.file("b.ply") + "' --bytes " + std::to_string(b8 - 1), &out), 0);
    EXPECT_NE(out.find("level 7:"), std::string::npos) << out;

    EXPECT_EQ(run("decode '" + spz + "' '" + dir.file("x.ply") + "' --level 13", &out), 1);
    EXPECT_NE(out.find("level 13 is past the last (12)"), std::string::npos) << out;
    EXPECT_EQ(run("decode '" + spz + "' '" + dir.file("x.ply") + "' --bytes 3", &out), 1);
    EXPECT_NE(out.find("below the coarsest level"), std::string::npos) << out;
    EXPECT_EQ(run("decode '" + spz + "' '" + dir.file("x.ply") + "' --level -1", &out), 1);
  }
  ASSERT_EQ(run("encode '" + in + "' '" + dir.file("s.spz") + "' --codec store --quiet", &out), 0);
  EXPECT_EQ(run("decode '" + dir.file("s.spz") + "' '" + dir.file("x.ply") + "' --level 3", &out), 1);
  EXPECT_NE(out.find("single-rate"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir.file("x.ply")));
}

TEST(Cli, BadDataExitsTwoAndLeavesNoOutput) {
  testing::TempDir dir;
  testing::writeBytes(dir.file("bad.ply"),
                      "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n"
                      "property float y\nproperty float z\nend_header\n0 0 0\n1 nan 0\n");
  std::string out;
  EXPECT_EQ(run("encode '" + dir.file("bad.ply") + "' '" + dir.file("o.spz") + "'", &out), 2);
  EXPECT_NE(out.find("bad.ply:9"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir.file("o.spz")));

  ASSERT_EQ(run("encode '" + kBunny + "' '" + dir.file("b.spz") + "' --quiet", &out), 0);
  auto bytes = testing::readBytes(dir.file("b.spz"));
  bytes.resize(bytes.size() - 10);
  testing::writeBytes(dir.file("t.spz"), std::string(bytes.begin(), bytes.end()));
  EXPECT_EQ(run("decode '" + dir.file("t.spz") + "' '" + dir.file("t.ply") + "'", &out), 2);
  EXPECT_NE(out.find("t.spz"), std::string::npos);
  EXPECT_FALSE(fs::exists(dir.file("t.ply")));
  EXPECT_EQ(run("info '" + dir.file("t.spz") + "'", &out), 2);
  EXPECT_EQ(temporaries(dir.path()), 0);
}

TEST(Cli, EnvironmentErrorsExitThree) {
  testing::TempDir dir;
  std::string out;
  EXPECT_EQ(run("encode '" + dir.file("missing.ply") + "' '" + dir.file("o.spz") + "'", &out), 3);
  EXPECT_NE(out.find("missing.ply"), std::string::npos);
  // A missing output folder is created (issue 24); one that cannot be (a file in the way) is an environment error.
  EXPECT_EQ(run("encode '" + kBunny + "' '" + dir.file("new/dir/o.spz") + "' --quiet", &out), 0) << out;
  EXPECT_TRUE(fs::is_regular_file(dir.file("new/dir/o.spz")));
  EXPECT_EQ(run("decode '" + dir.file("new/dir/o.spz") + "' '" + dir.file("other/b.ply") + "' --quiet", &out), 0);
  EXPECT_TRUE(fs::is_regular_file(dir.file("other/b.ply")));
  testing::writeBytes(dir.file("file"), "x");
  EXPECT_EQ(run("encode '" + kBunny + "' '" + dir.file("file/dir/o.spz") + "'", &out), 3);
  EXPECT_NE(out.find("cannot create the output's folder"), std::string::npos) << out;
}

// A full disk, simulated with a file-size limit: the write fails, the exit code says environment, and neither
// the output nor a temporary is left behind.
TEST(Cli, FullDiskLeavesNothingBehind) {
  testing::TempDir dir;
  const std::string cmd = "sh -c \"ulimit -f 64; trap '' XFSZ; exec '" + std::string(SCANPRESS_BIN) + "' encode '" +
                          kBunny + "' '" + dir.file("o.spz") + "'\" 2>&1";
  FILE* p = ::popen(cmd.c_str(), "r");
  std::string text;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) text.append(buf, n);
  const int status = ::pclose(p);
  ASSERT_TRUE(WIFEXITED(status)) << text;
  EXPECT_EQ(WEXITSTATUS(status), 3) << text;
  EXPECT_NE(text.find("o.spz"), std::string::npos) << text;
  EXPECT_FALSE(fs::exists(dir.file("o.spz")));
  EXPECT_EQ(temporaries(dir.path()), 0);
}

// An OBJ with texture coordinates, materials and normals (a small quad).
const char* kTexturedObj =
    "mtllib quad.mtl\ng quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n"
    "usemtl paint\nf 1/1/1 2/2/1 3/3/1 4/4/1\n";

// Lines of `out` that contain `what`.
int linesWith(const std::string& out, const std::string& what) {
  int n = 0;
  for (size_t at = 0; (at = out.find(what, at)) != std::string::npos; at += what.size()) ++n;
  return n;
}

// What the reader skips is named: one warning line, the report's `dropped` array, and with --strict a failure
// (exit 2, nothing written). Normals dropped on request are listed in the report, not warned about.
TEST(Cli, DroppedDataIsWarnedReportedAndFailsUnderStrict) {
  testing::TempDir dir;
  const std::string in = dir.file("quad.obj");
  testing::writeBytes(in, kTexturedObj);
  std::string out;
  ASSERT_EQ(run("encode '" + in + "' '" + dir.file("q.spz") + "' --report '" + dir.file("r.json") + "'", &out), 0)
      << out;
  EXPECT_EQ(linesWith(out, "warning"), 1) << out;
  // The texture coordinates are kept (scalar channels u and v), and the material lines; the group is not.
  EXPECT_NE(out.find("scanpress: warning: dropped obj g x 1 "), std::string::npos) << out;
  auto report = nlohmann::json::parse(std::ifstream(dir.file("r.json")));
  EXPECT_EQ(report["dropped"], nlohmann::json::parse(R"([{"name": "obj g", "count": 1, "reason": "unsupported"}])"));

  ASSERT_EQ(run("encode '" + in + "' '" + dir.file("q.spz") + "' --quiet", &out), 0) << out;
  EXPECT_EQ(out, "");  // --quiet: nothing, the warning included (the report still lists the drops)

  EXPECT_EQ(run("encode '" + in + "' '" + dir.file("s.spz") + "' --strict", &out), 2) << out;
  EXPECT_NE(out.find("quad.obj: strict: the container would not keep obj g x 1"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir.file("s.spz")));

  // Nothing unsupported: --strict encodes; --no-normals is listed as requested and warned about by nobody.
  testing::writeBytes(in, "v 0 0 0\nv 1 0 0\nv 1 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n");
  ASSERT_EQ(run("encode '" + in + "' '" + dir.file("s.spz") + "' --strict --no-normals --report '" +
                    dir.file("r.json") + "'",
                &out),
            0)
      << out;
  EXPECT_EQ(linesWith(out, "warning"), 0) << out;
  report = nlohmann::json::parse(std::ifstream(dir.file("r.json")));
  EXPECT_EQ(report["dropped"],
            nlohmann::json::parse(R"([{"name": "vertex normals", "count": 3, "reason": "requested"}])"));
}

// The bunny's confidence and intensity, through the CLI: kept by edgebreaker, pm and prm (prm resamples them), each
// listed in the report's layout, with no warning and nothing dropped, under --strict too.
TEST(Cli, BundledScanDropsAreNamed) {
  testing::TempDir dir;
  std::string out;
  ASSERT_EQ(run("encode '" + kBunny + "' '" + dir.file("a.spz") + "' --report '" + dir.file("a.json") + "'", &out), 0)
      << out;
  EXPECT_EQ(out.find("warning"), std::string::npos) << out;
  auto report = nlohmann::json::parse(std::ifstream(dir.file("a.json")));
  EXPECT_TRUE(report["dropped"].empty()) << report["dropped"];
  EXPECT_EQ(report["attributes"]["scalars"],
            nlohmann::json::parse(R"([{"name": "confidence", "type": "float", "bits": 0},
                                {"name": "intensity", "type": "float", "bits": 0}])"));
  for (const std::string codec : {"pm", "prm"}) {
    ASSERT_EQ(run("encode '" + kBunny + "' '" + dir.file(codec + ".spz") + "' --codec " + codec +
                      " --strict --report '" + dir.file(codec + ".json") + "'",
                  &out),
              0)
        << out;
    EXPECT_EQ(out.find("warning"), std::string::npos) << out;
    report = nlohmann::json::parse(std::ifstream(dir.file(codec + ".json")));
    EXPECT_TRUE(report["dropped"].empty()) << report["dropped"];
    EXPECT_EQ(report["attributes"]["scalars"].size(), 2u) << codec;
  }
  ASSERT_EQ(run("info '" + dir.file("a.spz") + "'", &out), 0) << out;
  EXPECT_NE(out.find("scalars:   confidence (float), intensity (float)"), std::string::npos) << out;
}

// decode: a tile named twice, and --level with --bytes, are usage errors (one of each silently won before).
TEST(Cli, DecodeRefusesDuplicateTilesAndTwoLevelChoices) {
  testing::TempDir dir;
  std::string out;
  const std::string spz = dir.file("b.spz");
  ASSERT_EQ(run("encode '" + kBunny + "' '" + spz + "' --codec kdtree --bits 12 --quiet", &out), 0) << out;
  EXPECT_EQ(run("decode '" + spz + "' '" + dir.file("x.ply") + "' --tiles 0,0", &out), 1);
  EXPECT_NE(out.find("tile 0 is named twice"), std::string::npos) << out;
  EXPECT_EQ(run("decode '" + spz + "' '" + dir.file("x.ply") + "' --level 6 --bytes 100000", &out), 1);
  EXPECT_NE(out.find("--level and --bytes"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir.file("x.ply")));
  ASSERT_EQ(run("decode '" + spz + "' '" + dir.file("x.ply") + "' --tiles 0 --level 6", &out), 0) << out;
}

// `info` counts vertices summed over tiles, the report distinct vertices: both say which is which, and the
// report's bpv_tile_vertices is info's bpv.
TEST(Cli, InfoAndReportSayWhichVertexCountTheyUse) {
  testing::TempDir dir;
  std::string out;
  const std::string spz = dir.file("b.spz");
  ASSERT_EQ(run("encode '" + kBunny + "' '" + spz + "' --tile-triangles 8000 --quiet --report '" + dir.file("r.json") +
                    "'",
                &out),
            0)
      << out;
  const auto report = nlohmann::json::parse(std::ifstream(dir.file("r.json")));
  ASSERT_EQ(run("info '" + spz + "' --json", &out), 0) << out;
  const auto info = nlohmann::json::parse(out);
  EXPECT_GT(report["tile_vertices"].get<uint64_t>(), report["vertices"].get<uint64_t>());  // several tiles
  EXPECT_EQ(info["vertices"], report["tile_vertices"]);
  EXPECT_DOUBLE_EQ(info["bpv"].get<double>(), report["bpv_tile_vertices"].get<double>());
  EXPECT_TRUE(report["counts"].contains("vertices"));
  EXPECT_TRUE(info["counts"].contains("vertices"));
  ASSERT_EQ(run("info '" + spz + "'", &out), 0) << out;
  EXPECT_NE(out.find(" (decoded, summed over tiles: a border vertex once per tile)"), std::string::npos) << out;
}

// decode --box: exactly the tiles whose world bounds (from `info --json`) meet the box; --crop: exactly the triangles
// of the full decode that lie wholly inside it (brute force over the full decode); tile bounds hold their vertices.
TEST(Cli, DecodeByBoxInWorldUnits) {
  testing::TempDir dir;
  std::string out;
  const std::string spz = dir.file("b.spz");
  ASSERT_EQ(run("encode '" + kBunny + "' '" + spz + "' --tile-triangles 8000 --quiet", &out), 0) << out;
  ASSERT_EQ(run("info '" + spz + "' --json", &out), 0) << out;
  const auto info = nlohmann::json::parse(out);
  ASSERT_GT(info["tiles"].size(), 3u);
  std::vector<std::array<double, 6>> bounds;
  for (const auto& t : info["tiles"]) {
    const auto& w = t["world_bounds"];
    bounds.push_back({w[0][0], w[0][1], w[0][2], w[1][0], w[1][1], w[1][2]});
  }
  // Every decoded vertex of tile 1 lies in its bounds.
  ASSERT_EQ(run("decode '" + spz + "' '" + dir.file("t1.ply") + "' --tiles 1 --quiet", &out), 0) << out;
  auto t1 = readMeshFile(dir.file("t1.ply"));
  ASSERT_TRUE(t1.isOk());
  for (const auto& p : t1->positions)
    for (int a = 0; a < 3; ++a) {
      EXPECT_GE(p[a], bounds[1][a]);
      EXPECT_LE(p[a], bounds[1][a + 3]);
    }
  // A box around the middle of tile 1's bounds.
  std::array<double, 6> box;
  for (int a = 0; a < 3; ++a) {
    const double c = (bounds[1][a] + bounds[1][a + 3]) / 2, h = (bounds[1][a + 3] - bounds[1][a]) / 3;
    box[a] = c - h;
    box[a + 3] = c + h;
  }
  size_t meeting = 0;
  for (const auto& b : bounds) {
    bool meets = true;
    for (int a = 0; a < 3; ++a) meets &= b[a] <= box[a + 3] && box[a] <= b[a + 3];
    meeting += meets;
  }
  ASSERT_LT(meeting, bounds.size());
  char arg[512];
  std::snprintf(arg, sizeof arg, "%.17g,%.17g,%.17g,%.17g,%.17g,%.17g", box[0], box[1], box[2], box[3], box[4], box[5]);
  ASSERT_EQ(run("decode '" + spz + "' '" + dir.file("box.ply") + "' --box " + arg, &out), 0) << out;
  EXPECT_NE(out.find("from " + std::to_string(meeting) + " tile(s)"), std::string::npos) << out;
  // --crop against brute force over the full decode.
  ASSERT_EQ(run("decode '" + spz + "' '" + dir.file("all.ply") + "' --quiet", &out), 0) << out;
  ASSERT_EQ(run("decode '" + spz + "' '" + dir.file("crop.ply") + "' --quiet --crop --box " + arg, &out), 0) << out;
  auto all = readMeshFile(dir.file("all.ply"));
  auto crop = readMeshFile(dir.file("crop.ply"));
  ASSERT_TRUE(all.isOk() && crop.isOk());
  auto inside = [&](const Vec3d& p) {
    for (int a = 0; a < 3; ++a)
      if (p[a] < box[a] || p[a] > box[a + 3]) return false;
    return true;
  };
  size_t expected = 0;
  for (const auto& t : all->triangles)
    expected += inside(all->positions[t[0]]) && inside(all->positions[t[1]]) && inside(all->positions[t[2]]);
  EXPECT_GT(expected, 0u);
  EXPECT_EQ(crop->triangles.size(), expected);
  for (const auto& p : crop->positions) EXPECT_TRUE(inside(p));
  // Wrong uses.
  EXPECT_EQ(run("decode '" + spz + "' '" + dir.file("x.ply") + "' --box " + arg + " --tiles 1", &out), 1);
  EXPECT_NE(out.find("--box and --tiles"), std::string::npos) << out;
  EXPECT_EQ(run("decode '" + spz + "' '" + dir.file("x.ply") + "' --crop", &out), 1);
  EXPECT_NE(out.find("--crop needs --box"), std::string::npos) << out;
  EXPECT_EQ(run("decode '" + spz + "' '" + dir.file("x.ply") + "' --box 1,1,1,0,0,0", &out), 1);
  EXPECT_NE(out.find("min must not exceed max"), std::string::npos) << out;
  EXPECT_EQ(run("decode '" + spz + "' '" + dir.file("x.ply") + "' --box 1e9,1e9,1e9,2e9,2e9,2e9", &out), 1);
  EXPECT_NE(out.find("no tile meets the box"), std::string::npos) << out;
  EXPECT_EQ(run("decode '" + spz + "' '" + dir.file("x.ply") + "' --box 1,2,3", &out), 1);
  EXPECT_FALSE(fs::exists(dir.file("x.ply")));
  ASSERT_EQ(run("info '" + spz + "'", &out), 0) << out;
  EXPECT_NE(out.find(", box "), std::string::npos) << out;
}

// `-` is stdin or stdout for encode and decode (and --report): through pipes, the bytes equal those of the same
// commands on files; messages go to stderr; failures leave nothing in the temporary directory and name <stdin>.
// Names that claim another format are refused.
TEST(Cli, StdinAndStdoutThroughPipes) {
  testing::TempDir dir;
  fs::create_directories(dir.file("tmp"));
  const std::string bin = std::string("TMPDIR='") + dir.file("tmp") + "' '" + SCANPRESS_BIN + "'";
  auto sh = [&](const std::string& cmd) {
    const int status = std::system(cmd.c_str());
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  };
  std::string out;
  ASSERT_EQ(run("encode '" + kBunny + "' '" + dir.file("file.spz") + "' --codec kdtree --quiet", &out), 0) << out;
  ASSERT_EQ(run("decode '" + dir.file("file.spz") + "' '" + dir.file("file.ply") + "' --quiet", &out), 0) << out;
  ASSERT_EQ(sh("cat '" + kBunny + "' | " + bin + " encode - - --format ply.zst --codec kdtree 2>'" +
               dir.file("err.txt") + "' > '" + dir.file("pipe.spz") + "'"),
            0);
  EXPECT_EQ(testing::readText(dir.file("pipe.spz")), testing::readText(dir.file("file.spz")));
  EXPECT_NE(testing::readText(dir.file("err.txt")).find("<stdin> -> <stdout>"), std::string::npos)
      << testing::readText(dir.file("err.txt"));
  ASSERT_EQ(sh(bin + " decode - - --format ply --quiet < '" + dir.file("pipe.spz") + "' > '" + dir.file("pipe.ply") +
               "'"),
            0);
  EXPECT_EQ(testing::readText(dir.file("pipe.ply")), testing::readText(dir.file("file.ply")));
  // The report on stdout, the container to a file.
  ASSERT_EQ(sh(bin + " encode '" + kBunny + "' '" + dir.file("r.spz") + "' --report - > '" + dir.file("r.json") +
               "' 2>/dev/null"),
            0);
  EXPECT_EQ(nlohmann::json::parse(testing::readText(dir.file("r.json")))["faces"], 69451);
  // Failures: a clear message naming <stdin>, exit 2, nothing on stdout, nothing left in the temporary directory.
  EXPECT_EQ(sh("printf garbage | " + bin + " encode - - --format ply > '" + dir.file("bad.spz") + "' 2>'" +
               dir.file("err.txt") + "'"),
            2);
  EXPECT_NE(testing::readText(dir.file("err.txt")).find("<stdin>:1: not a PLY file"), std::string::npos)
      << testing::readText(dir.file("err.txt"));
  EXPECT_EQ(fs::file_size(dir.file("bad.spz")), 0u);
  EXPECT_EQ(sh("printf garbage | " + bin + " decode - '" + dir.file("x.ply") + "' 2>/dev/null"), 2);
  EXPECT_TRUE(fs::is_empty(dir.file("tmp")));
  // Wrong uses.
  EXPECT_EQ(run("encode - o.spz", &out), 1);
  EXPECT_NE(out.find("needs --format"), std::string::npos) << out;
  EXPECT_EQ(run("encode '" + kBunny + "' o.spz --format ply", &out), 1);
  EXPECT_NE(out.find("--format is for a mesh on stdin"), std::string::npos) << out;
  EXPECT_EQ(run("encode - - --format ply --report -", &out), 1);
  EXPECT_NE(out.find("cannot both be -"), std::string::npos) << out;
  EXPECT_EQ(run("decode '" + dir.file("file.spz") + "' -", &out), 1);
  EXPECT_NE(out.find("needs --format ply|obj|stl|off|glb|gltf"), std::string::npos) << out;
  for (const char* name : {"x.glb", "x.ply", "X.OBJ", "x.ply.zst", "x.png"}) {
    EXPECT_EQ(run("encode '" + kBunny + "' '" + dir.file(name) + "'", &out), 1) << name;
    EXPECT_NE(out.find("name it .spz"), std::string::npos) << out;
    EXPECT_FALSE(fs::exists(dir.file(name)));
  }
  EXPECT_EQ(run("render '" + dir.file("file.ply") + "' '" + dir.file("x.jpg") + "'", &out), 1);
  EXPECT_NE(out.find("OUT must end in .png"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir.file("x.jpg")));
}

// decode writes every format it names: PLY, OBJ, STL, OFF (each also through zstd) read back to the same triangles
// over the same positions as the PLY; glTF (.glb and .gltf) passes the Khronos validator with no errors and no
// warnings, and its accessors hold the decoded counts and bounds.
TEST(Cli, DecodeToEveryFormat) {
  testing::TempDir dir;
  std::string out;
  const std::string spz = dir.file("b.spz");
  ASSERT_EQ(run("encode '" + kBunny + "' '" + spz + "' --bits 12 --quiet", &out), 0) << out;
  ASSERT_EQ(run("decode '" + spz + "' '" + dir.file("ref.ply") + "' --quiet", &out), 0) << out;
  auto ref = readMeshFile(dir.file("ref.ply"));
  ASSERT_TRUE(ref.isOk());
  const auto triangles = [](const Mesh& m) { return testing::positionTriangles(m); };
  const auto want = triangles(*ref);
  for (const char* name : {"b.obj", "b.stl", "b.off", "b.ply.zst", "b.obj.zst", "b.stl.zst", "b.off.zst"}) {
    SCOPED_TRACE(name);
    ASSERT_EQ(run("decode '" + spz + "' '" + dir.file(name) + "' --quiet", &out), 0) << out;
    auto back = readMeshFile(dir.file(name));
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_EQ(triangles(*back), want);
  }
  EXPECT_EQ(run("decode '" + spz + "' '" + dir.file("b.xyz") + "'", &out), 1);
  EXPECT_NE(out.find(".glb or .gltf"), std::string::npos) << out;
  for (const char* name : {"b.glb", "b.gltf"}) {
    SCOPED_TRACE(name);
    ASSERT_EQ(run("decode '" + spz + "' '" + dir.file(name) + "' --quiet", &out), 0) << out;
    // The document: from the JSON chunk of the .glb, or the .gltf itself.
    std::string text = testing::readText(dir.file(name));
    if (text.compare(0, 4, "glTF") == 0) {
      uint32_t len = 0;
      std::memcpy(&len, text.data() + 12, 4);
      text = text.substr(20, len);
    }
    const auto doc = nlohmann::json::parse(text);
    const auto& prim = doc["meshes"][0]["primitives"][0];
    const auto& pos = doc["accessors"][prim["attributes"]["POSITION"].get<int>()];
    EXPECT_EQ(pos["count"], ref->positions.size());
    EXPECT_EQ(doc["accessors"][prim["indices"].get<int>()]["count"], 3 * ref->triangles.size());
    for (int a = 0; a < 3; ++a) {
      double lo = 1e300, hi = -1e300;
      for (const auto& p : ref->positions) lo = std::min(lo, p[a]), hi = std::max(hi, p[a]);
      const double t = doc["nodes"][0]["translation"][a];
      EXPECT_NEAR(pos["min"][a].get<double>() + t, lo, 1e-6);
      EXPECT_NEAR(pos["max"][a].get<double>() + t, hi, 1e-6);
    }
    // The Khronos validator, when node has it (scripts/install-test-tools.sh).
    const std::string result = testing::validateGltf(dir.file(name), dir.path());
    if (result.rfind("SKIP", 0) == 0) {
      std::printf("[  SKIPPED ] %s: %s not validated\n", result.c_str(), name);
      continue;
    }
    EXPECT_NE(result.find("errors=0 warnings=0"), std::string::npos) << result;
  }
}

// --quiet prints nothing, whatever the thread count (oneTBB warned about more threads than cores).
TEST(Cli, QuietIsQuietWithMoreThreadsThanCores) {
  testing::TempDir dir;
  std::string out;
  ASSERT_EQ(run("encode '" + kBunny + "' '" + dir.file("b.spz") +
                    "' --codec kdtree --bits 12 --tile-triangles 4000 "
                    "--threads 64 --quiet",
                &out),
            0);
  EXPECT_EQ(out, "");
}

}  // namespace
}  // namespace scanpress
