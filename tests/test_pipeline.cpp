// The tiled pipeline: crack-free many-tile round trips, determinism across threads and memory modes, bounded
// memory on scans larger than the budget, and synthetic scans (the tiler's invariants: test_tiling.cpp).
#include <gtest/gtest.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>

#include <filesystem>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <tuple>

#include <nlohmann/json.hpp>

#include "jobs/commands.h"
#include "jobs/container_file.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "engine/shapes.h"
#include "jobs/synth.h"
#include "spatial/tiling.h"
#include "jobs_util.h"

extern char** environ;

namespace scanpress {
namespace {

namespace fs = std::filesystem;

// Directed edges used by exactly one triangle and not by a triangle in the opposite direction (the boundary),
// over positions, as a sorted multiset.
std::vector<std::pair<Vec3u, Vec3u>> boundaryEdges(const QuantizedMesh& m) {
  std::map<std::pair<Vec3u, Vec3u>, int> count;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) ++count[{m.positions[t[k]], m.positions[t[(k + 1) % 3]]}];
  std::vector<std::pair<Vec3u, Vec3u>> out;
  for (const auto& [e, n] : count)
    if (!count.count({e.second, e.first}))
      for (int i = 0; i < n; ++i) out.push_back(e);
  return out;
}

struct Decoded {
  EncodeResult enc;
  QuantizedMesh mesh;
  QuantizedMesh expected;
  ContainerHeader header;
};

Decoded roundTrip(const std::string& input, const std::string& out, uint64_t tile_triangles, int threads,
                  uint64_t budget = 0) {
  Decoded d;
  EncodeSettings s;
  s.input = input;
  s.output = out;
  s.tile_triangles = tile_triangles;
  s.threads = threads;
  s.memory_budget = budget;
  auto enc = encodeFile(s);
  EXPECT_TRUE(enc.isOk()) << enc.status().toString();
  if (!enc.isOk()) return d;
  d.enc = *enc;
  auto dec = decodeContainer(out, std::nullopt, &d.header);
  EXPECT_TRUE(dec.isOk()) << dec.status().toString();
  if (dec.isOk()) d.mesh = *dec;
  auto original = readMeshFile(input);
  d.expected = *quantizeMesh(*original, d.header.grid, d.header.layout, nullptr);
  return d;
}

std::string dataFile(const char* name) { return testing::sharedDataDir() + "/" + name; }

// A tiled scan with normals decoded at a coarse level: each tile derives its normals from its own triangles, so
// along a seam the two tiles disagree; welding by position (then deriving normals from the welded mesh) leaves
// one vertex per position, as without normals. For every progressive codec, at several coarse levels.
TEST(Pipeline, CoarseLevelsWeldByPosition) {
  testing::TempDir dir;
  Mesh sphere = icosphere(5);
  for (const auto& p : sphere.positions) sphere.normals.push_back({float(p[0]), float(p[1]), float(p[2])});
  const std::string input = dir.file("sphere.ply");
  ASSERT_TRUE(writeMeshFile(input, sphere, WriteOptions{}).isOk());
  for (const auto& codec : allCodecs()) {
    if (!codec.progressive()) continue;
    SCOPED_TRACE(codec.name);
    EncodeSettings s;
    s.input = input;
    s.output = dir.file(std::string(codec.name) + ".spz");
    s.codec = std::string(codec.name);
    s.bits = 12;
    s.tile_triangles = 1024;
    auto enc = encodeFile(s);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    EXPECT_GE(enc->tiles.size(), 16u);
    for (uint32_t level : {5u, 7u, 9u}) {
      SCOPED_TRACE(level);
      ContainerHeader header;
      auto m = decodeContainer(s.output, std::nullopt, &header, level);
      ASSERT_TRUE(m.isOk()) << m.status().toString();
      std::set<Vec3u> positions(m->positions.begin(), m->positions.end());
      EXPECT_EQ(m->positions.size(), positions.size()) << "duplicate vertices on seams";
      ASSERT_EQ(m->normals.size(), m->positions.size());
      // (kdtree and octree cells of a coarse level merge seam vertices with interior ones of each tile on its own,
      // so their coarse levels are not crack-free across tiles; only their complete level is.)
    }
    // The complete level still welds by position and attributes, and has the scan's own normals.
    auto full = decodeContainer(s.output, std::nullopt, nullptr, 12);
    ASSERT_TRUE(full.isOk());
    EXPECT_EQ(full->positions.size(), sphere.positions.size());
  }
}

// Coarse levels of many kdtree or octree tiles (version 3) show the scan's own normals and colors: each welded vertex
// has those of an input vertex nearby (a point of its cell, or of its ancestor's cell at the last level whose
// attributes the tile codes: Codecs/AttributeRoundTrip.CoarseLevelsShowTheTilesOwnAttributes checks that rule). The
// sphere's colors differ from vertex to vertex: derived ones (grey) or another vertex's fail. At the coarsest levels
// some tiles are at (or above) their root cube, whose one vertex derives its attributes: only that vertex does, the
// other tiles' keep their own.
// A sphere whose normals are its directions and whose colors vary from vertex to vertex.
Mesh attributedSphereMesh(int subdivisions) {
  Mesh sphere = icosphere(subdivisions);
  for (size_t i = 0; i < sphere.positions.size(); ++i) {
    const Vec3d& p = sphere.positions[i];
    sphere.normals.push_back({float(p[0]), float(p[1]), float(p[2])});
    sphere.colors.push_back({uint8_t(i * 37), uint8_t(i * 11), uint8_t(128 + 100 * p[2]), 255});
  }
  sphere.color_channels = 3;
  return sphere;
}

// Where each (normal, color) of a mesh is.
using AttributePlaces = std::map<std::pair<OctNormal, Rgba8>, std::vector<Vec3u>>;
AttributePlaces placesOf(const QuantizedMesh& q) {
  AttributePlaces where;
  for (size_t v = 0; v < q.positions.size(); ++v) where[{q.normals[v], q.colors[v]}].push_back(q.positions[v]);
  return where;
}

// Of m's vertices, those whose (normal, color) the scan has nowhere (foreign), and those that have it only farther
// than `reach` grid cells on some axis (far).
std::pair<size_t, size_t> foreignAndFar(const QuantizedMesh& m, const AttributePlaces& where, int64_t reach) {
  size_t foreign = 0, far = 0;
  for (size_t v = 0; v < m.positions.size(); ++v) {
    const auto it = where.find({m.normals[v], m.colors[v]});
    if (it == where.end()) {
      ++foreign;
      continue;
    }
    bool near = false;
    for (const Vec3u& p : it->second) {
      bool inside = true;
      for (int a = 0; a < 3; ++a) inside &= std::llabs(int64_t(p[a]) - int64_t(m.positions[v][a])) <= reach;
      near |= inside;
    }
    far += !near;
  }
  return {foreign, far};
}

TEST(Pipeline, CoarseLevelsOfManyTilesShowTheScansOwnAttributes) {
  testing::TempDir dir;
  const Mesh sphere = attributedSphereMesh(5);
  const std::string input = dir.file("sphere.ply");
  ASSERT_TRUE(writeMeshFile(input, sphere, WriteOptions{}).isOk());
  for (const char* codec : {"kdtree", "octree"}) {
    SCOPED_TRACE(codec);
    EncodeSettings s;
    s.input = input;
    s.output = dir.file(std::string(codec) + ".spz");
    s.codec = codec;
    s.bits = 12;
    s.tile_triangles = 1024;
    auto enc = encodeFile(s);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    EXPECT_GE(enc->tiles.size(), 16u);
    ContainerHeader header;
    ASSERT_TRUE(decodeContainer(s.output, std::nullopt, &header).isOk());
    auto q = quantizeMesh(sphere, header.grid, header.layout, nullptr);
    ASSERT_TRUE(q.isOk());
    auto file = ContainerFile::open(s.output);
    ASSERT_TRUE(file.isOk());
    std::vector<uint32_t> roots;  // each tile's root level (its first)
    for (const TileEntry& e : file->tiles()) {
      auto levels = file->tileLevels(e);
      ASSERT_TRUE(levels.isOk() && !levels->empty());
      roots.push_back(levels->front().level);
    }
    EXPECT_GT(std::set<uint32_t>(roots.begin(), roots.end()).size(), 1u) << "tiles with different root levels";
    for (uint32_t level : {1u, 2u, 3u, 5u, 7u, 9u}) {
      SCOPED_TRACE(level);
      const size_t at_root = size_t(std::count_if(roots.begin(), roots.end(), [&](uint32_t r) { return r >= level; }));
      auto m = decodeContainer(s.output, std::nullopt, nullptr, level);
      ASSERT_TRUE(m.isOk()) << m.status().toString();
      const AttributePlaces where = placesOf(*q);
      ASSERT_EQ(m->normals.size(), m->positions.size());
      ASSERT_EQ(m->colors.size(), m->positions.size());
      // A tile of 1024 triangles (about 500 vertices) codes the attributes of its levels with at most 64 vertices,
      // level 3 or finer on this sphere: the point shown lies in the level-3 cell of the vertex's ancestor, within
      // 2^9 grid cells on each axis (measured: at most 508). Another vertex's attributes would be up to 4096 away.
      const int64_t reach = int64_t(1) << std::max(9, 12 - int(level));
      const auto [foreign, far] = foreignAndFar(*m, where, reach);
      EXPECT_LE(foreign, at_root) << "of " << m->positions.size()
                                  << " vertices show attributes the scan does not have; tiles at their root level: "
                                  << at_root;
      if (level >= 3) {
        EXPECT_LT(at_root, roots.size() / 2);
      }
      EXPECT_EQ(far, 0u) << "of " << m->positions.size() << " vertices show a far point's attributes";
    }
  }
}

// pm v3 through the pipeline: every level of a tiled encode shows the scan's own normals and colors (each vertex
// those of a scan vertex near it: its own, or before the last level its base ancestor's), and the whole decode shows
// at each position exactly the scan's there.
TEST(Pipeline, PmLevelsOfManyTilesShowTheScansOwnAttributes) {
  testing::TempDir dir;
  const Mesh sphere = attributedSphereMesh(5);
  const std::string input = dir.file("sphere.ply");
  ASSERT_TRUE(writeMeshFile(input, sphere, WriteOptions{}).isOk());
  EncodeSettings s;
  s.input = input;
  s.output = dir.file("pm.spz");
  s.codec = "pm";
  s.bits = 12;
  s.tile_triangles = 2048;
  auto enc = encodeFile(s);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  EXPECT_GE(enc->tiles.size(), 8u);
  ContainerHeader header;
  auto whole = decodeContainer(s.output, std::nullopt, &header);
  ASSERT_TRUE(whole.isOk()) << whole.status().toString();
  auto read = readMeshFile(input);  // the positions as the file holds them
  ASSERT_TRUE(read.isOk());
  auto q = quantizeMesh(*read, header.grid, header.layout, nullptr);
  ASSERT_TRUE(q.isOk());
  std::map<Vec3u, std::pair<OctNormal, Rgba8>> at;
  for (size_t v = 0; v < q->positions.size(); ++v) at.emplace(q->positions[v], std::pair{q->normals[v], q->colors[v]});
  ASSERT_EQ(whole->normals.size(), whole->positions.size());
  ASSERT_EQ(whole->colors.size(), whole->positions.size());
  for (size_t v = 0; v < whole->positions.size(); ++v) {
    const auto& [normal, color] = at.at(whole->positions[v]);
    ASSERT_EQ(whole->normals[v], normal) << v;
    ASSERT_EQ(whole->colors[v], color) << v;
  }
  const AttributePlaces where = placesOf(*q);
  for (uint32_t level : {0u, 1u, 2u, 4u}) {
    SCOPED_TRACE(level);
    auto m = decodeContainer(s.output, std::nullopt, nullptr, level);
    ASSERT_TRUE(m.isOk()) << m.status().toString();
    ASSERT_EQ(m->normals.size(), m->positions.size());
    ASSERT_EQ(m->colors.size(), m->positions.size());
    EXPECT_LT(m->positions.size(), whole->positions.size());
    // A coarse vertex stands for the scan vertices collapsed into it, its base ancestor among them: a base vertex
    // stands for the region that collapsed into it, about 8 vertices (measured: at most 980 grid cells away, some 12
    // of this sphere's edges; a tile spans about 1500).
    const int64_t reach = 1024;
    const auto [foreign, far] = foreignAndFar(*m, where, reach);
    EXPECT_EQ(foreign, 0u) << "of " << m->positions.size() << " vertices show attributes the scan does not have";
    EXPECT_EQ(far, 0u) << "of " << m->positions.size() << " vertices show a far point's attributes";
  }
}

TEST(Pipeline, IgeaInSixteenTilesIsCrackFree) {
  const std::string path = dataFile("igea.ply.zst");
  if (!fs::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
  testing::TempDir dir;
  const Decoded d = roundTrip(path, dir.file("igea.spz"), 16384, 2);
  EXPECT_GE(d.enc.tiles.size(), 16u);
  EXPECT_EQ(d.enc.failed_tiles, 0u);
  EXPECT_GT(d.enc.tile_vertices, d.enc.vertices) << "border vertices are stored once per tile";
  EXPECT_TRUE(testing::triangleMultiset(d.mesh) == testing::triangleMultiset(d.expected));
  std::set<Vec3u> distinct(d.mesh.positions.begin(), d.mesh.positions.end());
  EXPECT_EQ(distinct.size(), d.mesh.positions.size()) << "duplicated vertex positions after welding";
  EXPECT_EQ(d.mesh.positions.size(), 134345u);
  EXPECT_TRUE(boundaryEdges(d.mesh).empty()) << "igea is closed: tiling opened seams";
  // Every tile respects the target unless one fine cell alone exceeds it.
  for (const auto& t : d.enc.tiles) EXPECT_LE(t.faces, 2 * 16384u);
}

// Open, non-manifold and soup scans keep exactly their boundaries through tiling.
TEST(Pipeline, TiledScansKeepTheirBoundaries) {
  testing::TempDir dir;
  for (const char* name : {"rs1_normals.ply.zst", "lato000.ply.zst", "parasaurolophus_low_normals2.ply.zst",
                           "bunny.stl.zst", "gargo.ply.zst"}) {
    SCOPED_TRACE(name);
    const std::string path = dataFile(name);
    if (!fs::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
    const Decoded d = roundTrip(path, dir.file("x.spz"), 4096, 2);
    EXPECT_GE(d.enc.tiles.size(), 8u);
    const int nb = d.header.layout.normal_bits;
    EXPECT_TRUE(testing::cornerMultiset(d.mesh, nb) == testing::cornerMultiset(d.expected, nb));
    EXPECT_EQ(boundaryEdges(d.mesh), boundaryEdges(d.expected));
  }
}

TEST(Pipeline, SameBytesAtAnyThreadCountAndMemoryMode) {
  const std::string path = dataFile("igea.ply.zst");
  if (!fs::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
  testing::TempDir dir;
  auto encode = [&](const std::string& out, int threads, uint64_t budget) {
    EncodeSettings s;
    s.input = path;
    s.output = dir.file(out);
    s.tile_triangles = 4096;
    s.threads = threads;
    s.memory_budget = budget;
    auto r = encodeFile(s);
    EXPECT_TRUE(r.isOk()) << r.status().toString();
    return r.isOk() ? r->out_of_core : false;
  };
  encode("t1.spz", 1, 0);
  encode("t2.spz", 2, 0);
  encode("t8.spz", 8, 0);
  // A 16 MiB budget sends igea through scratch files with the same tile target (4096): same bytes.
  EXPECT_TRUE(encode("disk.spz", 2, 16u << 20));
  const auto reference = testing::readBytes(dir.file("t1.spz"));
  EXPECT_GT(reference.size(), 0u);
  for (const char* other : {"t2.spz", "t8.spz", "disk.spz"})
    EXPECT_TRUE(testing::readBytes(dir.file(other)) == reference) << other;
}

TEST(Pipeline, FailedTileIsReportedAndTheOthersAreKept) {
  const std::string path = dataFile("igea.ply.zst");
  if (!fs::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
  testing::TempDir dir;
  EncodeSettings s;
  s.input = path;
  s.output = dir.file("f.spz");
  s.tile_triangles = 16384;
  PipelineHooks hooks;
  hooks.fail_tile = [](uint32_t tile) {
    return tile == 3 ? makeError(ErrorCode::kInternal, "injected failure (test)") : Status::ok();
  };
  auto r = encodeFile(s, nullptr, nullptr, &hooks);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_EQ(r->failed_tiles, 1u);
  EXPECT_EQ(r->tiles[3].status.code(), ErrorCode::kInternal);
  auto file = ContainerFile::open(s.output);
  ASSERT_TRUE(file.isOk());
  EXPECT_EQ(file->tiles().size(), r->tiles.size() - 1);
  EXPECT_EQ(file->findTile(3), nullptr);
  EXPECT_NE(file->findTile(4), nullptr);
  auto decoded = decodeContainer(s.output, std::nullopt);
  ASSERT_TRUE(decoded.isOk());
  EXPECT_EQ(decoded->triangles.size(), 268686u - r->tiles[3].faces);
}

// The tile stages: lock flags reach a stage and are the border flags (a vertex used by triangles of two tiles);
// a stage that moves every unlocked vertex still decodes crack-free; a stage that moves a locked vertex, or drops a
// border edge, is a tile error, never a cracked mesh.
// A scan for many tiles: igea when the shared data is there, else a synth scan.
std::string stageInput(testing::TempDir& dir) {
  const std::string igea = dataFile("igea.ply.zst");
  if (fs::exists(igea)) return igea;
  SynthSettings synth;
  synth.output = dir.file("s.ply");
  synth.triangles = 200000;
  EXPECT_TRUE(synthesize(synth).isOk());
  return synth.output;
}

EncodeSettings stageSettings(const std::string& input, const std::string& output, const char* codec) {
  EncodeSettings s;
  s.input = input;
  s.output = output;
  s.codec = codec;
  s.bits = 14;
  s.tile_triangles = 8192;
  s.threads = 2;
  return s;
}

TEST(Pipeline, LockFlagsReachStagesAndAreTheBorder) {
  testing::TempDir dir;
  const std::string input = stageInput(dir);
  std::mutex mu;
  std::map<uint32_t, std::vector<std::pair<Vec3u, uint8_t>>> seen;  // tile -> (position, locked)
  PipelineHooks hooks;
  hooks.extra_stage = [&](const TileContext&, const TileView& t, uint32_t tile) -> Result<StagedTile> {
    std::vector<std::pair<Vec3u, uint8_t>> v;
    EXPECT_EQ(t.locked.size(), t.mesh.positions.size());
    for (size_t i = 0; i < t.mesh.positions.size(); ++i) v.push_back({t.mesh.positions[i], t.locked[i]});
    std::lock_guard lock(mu);
    seen[tile] = std::move(v);
    return StagedTile{t.mesh, std::vector<uint8_t>(t.locked.begin(), t.locked.end())};
  };
  auto r = encodeFile(stageSettings(input, dir.file("l.spz"), "kdtree"), nullptr, nullptr, &hooks);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  ASSERT_GE(seen.size(), 20u);
  // Brute force: a position is on the border when two tiles hold it.
  std::map<Vec3u, int> tiles_at;
  for (const auto& [tile, v] : seen) {
    std::set<Vec3u> mine;
    for (const auto& [p, locked] : v) mine.insert(p);
    for (const Vec3u& p : mine) ++tiles_at[p];
  }
  size_t locked_count = 0;
  for (const auto& [tile, v] : seen)
    for (const auto& [p, locked] : v) {
      EXPECT_EQ(locked != 0, tiles_at[p] > 1) << "tile " << tile;
      locked_count += locked;
    }
  EXPECT_GT(locked_count, 1000u);
}

// Moves every unlocked vertex by one grid cell along x where that keeps its triangles valid; locked ones stay.
Result<StagedTile> moveUnlocked(const TileContext& ctx, const TileView& t, uint32_t) {
  StagedTile out{t.mesh, std::vector<uint8_t>(t.locked.begin(), t.locked.end())};
  const uint32_t max = (1u << ctx.bits) - 1;
  for (size_t v = 0; v < out.mesh.positions.size(); ++v)
    if (!out.locked[v]) {
      auto& p = out.mesh.positions[v];
      p[0] = p[0] < max ? p[0] + 1 : p[0] - 1;
    }
  undoDegenerateMoves(t.mesh, out.mesh);
  return out;
}

TEST(Pipeline, StageMovingEveryUnlockedVertexDecodesCrackFree) {
  testing::TempDir dir;
  const std::string input = stageInput(dir);
  for (const char* codec : {"kdtree", "octree", "store"}) {
    SCOPED_TRACE(codec);
    PipelineHooks hooks;
    hooks.extra_stage = moveUnlocked;
    const EncodeSettings s = stageSettings(input, dir.file(std::string(codec) + ".spz"), codec);
    auto r = encodeFile(s, nullptr, nullptr, &hooks);
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    EXPECT_GE(r->tiles.size(), 20u);
    EXPECT_EQ(r->failed_tiles, 0u);
    ContainerHeader header;
    auto m = decodeContainer(s.output, std::nullopt, &header);
    ASSERT_TRUE(m.isOk()) << m.status().toString();
    // Crack-free: the input is closed (or its boundary is the input's), and every seam welded: no position twice,
    // and the boundary edges are exactly the input's (none for igea).
    auto original = readMeshFile(input);
    ASSERT_TRUE(original.isOk());
    const QuantizedMesh expected = *quantizeMesh(*original, header.grid, header.layout, nullptr);
    std::set<Vec3u> positions(m->positions.begin(), m->positions.end());
    EXPECT_EQ(positions.size(), m->positions.size()) << "duplicate positions on seams";
    EXPECT_EQ(boundaryEdges(*m).size(), boundaryEdges(expected).size());
    EXPECT_EQ(m->triangles.size(), expected.triangles.size());
    // And the vertices did move: the stage ran.
    EXPECT_FALSE(testing::triangleMultiset(*m) == testing::triangleMultiset(expected));
  }
}

TEST(Pipeline, StageBreakingTheBorderContractIsATileError) {
  testing::TempDir dir;
  const std::string input = stageInput(dir);
  // Moves the first locked vertex of tile 2.
  PipelineHooks moves_locked;
  moves_locked.extra_stage = [](const TileContext&, const TileView& t, uint32_t tile) -> Result<StagedTile> {
    StagedTile out{t.mesh, std::vector<uint8_t>(t.locked.begin(), t.locked.end())};
    for (size_t v = 0; tile == 2 && v < out.locked.size(); ++v)
      if (out.locked[v]) {
        out.mesh.positions[v][2] ^= 1;
        break;
      }
    return out;
  };
  // Drops the triangles of tile 5 that hold a border edge.
  PipelineHooks drops_border = moves_locked;
  drops_border.extra_stage = [](const TileContext&, const TileView& t, uint32_t tile) -> Result<StagedTile> {
    StagedTile out{t.mesh, std::vector<uint8_t>(t.locked.begin(), t.locked.end())};
    if (tile != 5) return out;
    std::erase_if(out.mesh.triangles, [&](const Triangle& tri) {
      int locked = 0;
      for (uint32_t v : tri) locked += t.locked[v];
      return locked >= 2;
    });
    return out;
  };
  for (auto [hooks, bad_tile, what] :
       {std::tuple{&moves_locked, 2u, "locked vertex"}, std::tuple{&drops_border, 5u, "border edge"}}) {
    SCOPED_TRACE(what);
    auto r = encodeFile(stageSettings(input, dir.file("bad.spz"), "kdtree"), nullptr, nullptr, hooks);
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    EXPECT_EQ(r->failed_tiles, 1u);
    const Status& st = r->tiles[bad_tile].status;
    EXPECT_EQ(st.code(), ErrorCode::kInternal);
    EXPECT_NE(st.toString().find("border contract"), std::string::npos) << st.toString();
    EXPECT_NE(st.toString().find(what), std::string::npos) << st.toString();
  }
}

TEST(Pipeline, ScratchFilesAreRemovedWhenAnEncodeFails) {
  testing::TempDir dir;
  SynthSettings synth;
  synth.output = dir.file("s.ply");
  synth.triangles = 400000;  // ~14 MB of tile data: out of core under a 16 MiB budget
  ASSERT_TRUE(synthesize(synth).isOk());
  fs::create_directories(dir.file("scratch"));
  EncodeSettings s;
  s.input = synth.output;
  testing::writeBytes(dir.file("file"), "x");
  s.output = dir.file("file/dir/s.spz");  // fails after the bins are written (no folder can be made under a file)
  s.memory_budget = 16u << 20;
  s.scratch_dir = dir.file("scratch");
  auto r = encodeFile(s);
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(exitCodeFor(r.status().code()), 3) << r.status().toString();
  EXPECT_TRUE(fs::is_empty(dir.file("scratch"))) << "scratch files left behind";
  // The same scan with a writable output goes through scratch files.
  s.output = dir.file("s.spz");
  auto ok = encodeFile(s);
  ASSERT_TRUE(ok.isOk()) << ok.status().toString();
  EXPECT_TRUE(ok->out_of_core);
  EXPECT_TRUE(fs::is_empty(dir.file("scratch")));
}

// Runs the scanpress binary and returns its exit status and peak RSS in bytes.
std::pair<int, uint64_t> runMeasured(const std::vector<std::string>& args) {
  std::vector<char*> argv;
  std::string bin = SCANPRESS_BIN;
  argv.push_back(bin.data());
  std::vector<std::string> copy = args;
  for (auto& a : copy) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  if (::posix_spawn(&pid, bin.c_str(), nullptr, nullptr, argv.data(), environ) != 0) return {-1, 0};
  int status = 0;
  struct rusage ru {};
  ::wait4(pid, &status, 0, &ru);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, static_cast<uint64_t>(ru.ru_maxrss) * 1024};
}

// The documented margin over the budget: the process itself (binary, OpenVDB, TBB, ~33 MiB) and reader buffers.
constexpr uint64_t kRssMargin = 48ull << 20;

TEST(Pipeline, ScanLargerThanTheBudgetStaysWithinIt) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "peak RSS means nothing under AddressSanitizer (shadow memory and quarantine); the Release "
                  "suite measures it";
#endif
  testing::TempDir dir;
  SynthSettings synth;
  synth.output = dir.file("s5m.ply");
  synth.triangles = 5000000;
  auto made = synthesize(synth);
  ASSERT_TRUE(made.isOk()) << made.status().toString();
  // In memory this scan needs ~400 MB (measured: 406 MB peak RSS without a budget); give it 64 MiB.
  const uint64_t budget = 64ull << 20;
  fs::create_directories(dir.file("scratch"));
  auto [code, rss] = runMeasured({"encode", synth.output, dir.file("s5m.spz"), "--memory-budget", "64M",
                                  "--scratch-dir", dir.file("scratch"), "--report", dir.file("r.json"), "--quiet"});
  ASSERT_EQ(code, 0);
  // The report's figure is the child's own (VmHWM); wait4's ru_maxrss also counts this test process's resident
  // set at the spawn, which is large after the data tests when the whole binary runs in one process.
  const auto report = nlohmann::json::parse(testing::readBytes(dir.file("r.json")));
  const uint64_t peak = report.at("peak_rss").get<uint64_t>();
  std::printf("peak RSS %.1f MiB with a %.0f MiB budget (wait4: %.1f MiB)\n", peak / 1048576.0, budget / 1048576.0,
              rss / 1048576.0);
  EXPECT_GT(peak, 0u);
  EXPECT_LE(peak, budget + kRssMargin);
  EXPECT_TRUE(fs::is_empty(dir.file("scratch"))) << "scratch files left behind";
  auto file = ContainerFile::open(dir.file("s5m.spz"));
  ASSERT_TRUE(file.isOk());
  EXPECT_EQ(file->header().faces, 5000000u);
  EXPECT_GT(file->tiles().size(), 16u);
}

TEST(Synth, ExactCountsNoUnreferencedVerticesDeterministic) {
  testing::TempDir dir;
  for (uint64_t n : {1ull, 2ull, 1000ull, 123457ull}) {
    SCOPED_TRACE(n);
    SynthSettings s;
    s.output = dir.file("a.ply");
    s.triangles = n;
    s.seed = 3;
    auto r = synthesize(s);
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    ReadStats stats;
    auto mesh = readMeshFile(s.output, &stats);
    ASSERT_TRUE(mesh.isOk());
    EXPECT_EQ(mesh->triangles.size(), n);
    std::vector<uint8_t> used(mesh->positions.size(), 0);
    for (const auto& t : mesh->triangles)
      for (uint32_t v : t) used[v] = 1;
    EXPECT_EQ(std::count(used.begin(), used.end(), 0), 0);
    s.output = dir.file("b.ply");
    ASSERT_TRUE(synthesize(s).isOk());
    EXPECT_TRUE(testing::readBytes(dir.file("a.ply")) == testing::readBytes(dir.file("b.ply")));
  }
  // Built from a real scan.
  SynthSettings s;
  s.output = dir.file("c.ply");
  s.triangles = 300000;
  s.from = std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
  auto r = synthesize(s);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_EQ(r->triangles, 300000u);
}

}  // namespace
}  // namespace scanpress
