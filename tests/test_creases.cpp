// Creases and seams through the coarse levels of kdtree (v5) and octree (v4; engine/codecs/creases.h): a cube
// with a normal per face (every edge a crease, every corner three wedges), fandisk split at its sharp edges (whole,
// and with holes cutting its fans into pieces) and a UV-mapped sphere (a seam), against what the scan says at each
// level; the cut edges against a brute force; version 3 for tiles without creases; hostile payloads.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <filesystem>
#include <functional>
#include <map>
#include <random>
#include <set>
#include <tuple>

#include "engine/codecs/codec.h"
#include "engine/codecs/creases.h"
#include "engine/octahedral.h"
#include "engine/quantize.h"
#include "engine/shapes.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs_util.h"
#include "test_util.h"

namespace scanpress {
namespace {

// The codecs that code creases through their coarse levels.
class Creases : public ::testing::TestWithParam<CodecId> {
 protected:
  const CodecInfo& codec() const { return *findCodec(GetParam()); }
};

// A cube of side 0.8 at (0.1, 0.1, 0.1), each face an n x n grid of squares with its own vertices and the face's
// outward normal: its twelve edges are creases.
Mesh creasedCube(int n) {
  Mesh m;
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      const uint32_t base = uint32_t(m.positions.size());
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      for (int i = 0; i <= n; ++i)
        for (int j = 0; j <= n; ++j) {
          Vec3d p;
          p[size_t(axis)] = 0.1 + 0.8 * side;
          p[size_t(u)] = 0.1 + 0.8 * i / n;
          p[size_t(v)] = 0.1 + 0.8 * j / n;
          m.positions.push_back(p);
          Vec3f nrm{0, 0, 0};
          nrm[size_t(axis)] = side ? 1.f : -1.f;
          m.normals.push_back(nrm);
        }
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          const uint32_t a = base + uint32_t(i * (n + 1) + j), b = a + uint32_t(n + 1), c = b + 1, d = a + 1;
          if (side) m.triangles.push_back({a, b, c}), m.triangles.push_back({a, c, d});
          else m.triangles.push_back({a, c, b}), m.triangles.push_back({a, d, c});
        }
    }
  return m;
}

Vec3d unit(const Vec3d& v) {
  const double l = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  return l > 0 ? Vec3d{v[0] / l, v[1] / l, v[2] / l} : v;
}
Vec3d faceNormal(const QuantizedMesh& m, const Triangle& t) {
  const auto& a = m.positions[t[0]];
  const auto& b = m.positions[t[1]];
  const auto& c = m.positions[t[2]];
  const Vec3d u{double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
  const Vec3d w{double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
  return unit({u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]});
}

struct LevelCheck {
  size_t triangles = 0, flat = 0, wrong = 0, wedged = 0;
};

// At a decoded level: the triangles that lie flat on a face of the cube (their normal within 10 degrees of an
// axis, either orientation: coarse levels orient their triangles themselves) and, of those, the ones with a corner
// whose normal is not that face's; and the vertices that share their position with another (the wedges).
LevelCheck checkCube(const QuantizedMesh& m, int normal_bits) {
  LevelCheck r;
  r.triangles = m.triangles.size();
  for (const Triangle& t : m.triangles) {
    const Vec3d g = faceNormal(m, t);
    int axis = -1;
    for (int a = 0; a < 3; ++a)
      if (std::fabs(g[size_t(a)]) > std::cos(10 * M_PI / 180)) axis = a;
    if (axis < 0) continue;
    ++r.flat;
    // The face: the side of the cube the triangle lies on (its cells' centers are near that plane).
    const double mid = double(m.positions[t[0]][size_t(axis)]);
    const int side = mid > 2048 ? 1 : -1;
    bool ok = true;
    for (uint32_t v : t) {
      const Vec3f n = decodeOctahedral(m.normals[v], normal_bits);
      ok &= std::fabs(n[size_t(axis)] - float(side)) < 1e-3f;
    }
    r.wrong += !ok;
  }
  std::map<Vec3u, int> at;
  for (const Vec3u& p : m.positions) ++at[p];
  for (const auto& [p, k] : at)
    if (k > 1) r.wedged += size_t(k);
  return r;
}

// The level with one value per position (each position's first vertex's normal and scalars), as version 3 showed
// a cell.
QuantizedMesh onePerPosition(QuantizedMesh m) {
  const size_t stride = m.positions.empty() ? 0 : m.scalars.size() / m.positions.size();
  std::map<Vec3u, size_t> first;
  for (size_t v = 0; v < m.positions.size(); ++v) {
    const size_t f = first.try_emplace(m.positions[v], v).first->second;
    if (!m.normals.empty()) m.normals[v] = m.normals[f];
    std::copy_n(m.scalars.begin() + ptrdiff_t(f * stride), stride, m.scalars.begin() + ptrdiff_t(v * stride));
  }
  return m;
}

// The coarse levels of `q` coded by `codec` (its version with creases), each decoded from the payload cut at its end
// and valid; the root level (one cell) and the last level left out.
std::vector<std::pair<uint32_t, QuantizedMesh>> coarseLevels(const CodecInfo& codec, const TileContext& ctx,
                                                             const QuantizedMesh& q) {
  std::vector<std::pair<uint32_t, QuantizedMesh>> out;
  auto enc = encodeMesh(codec, ctx, q);
  EXPECT_TRUE(enc.isOk()) << enc.status().toString();
  if (!enc.isOk()) return out;
  EXPECT_EQ(enc->version, codec.version);
  std::printf("%s v%d payload: %zu bytes\n", std::string(codec.name).c_str(), int(enc->version), enc->payload.size());
  auto levels = codec.levels(ctx, enc->version, enc->payload, limitsOf(enc->decoded));
  EXPECT_TRUE(levels.isOk());
  if (!levels.isOk()) return out;
  for (const CodecLevel& l : *levels) {
    if (l.complete || l.level == levels->front().level) continue;
    auto m = codec.decode_level(ctx, enc->version, std::span(enc->payload).first(l.end_bytes), l.level,
                                limitsOf(enc->decoded));
    EXPECT_TRUE(m.isOk()) << "level " << l.level << ": " << m.status().toString();
    if (!m.isOk()) continue;
    EXPECT_TRUE(validateTile(ctx, *m).isOk()) << "level " << l.level;
    out.push_back({l.level, std::move(m).value()});
  }
  auto full = codec.decode(ctx, enc->version, enc->payload, limitsOf(enc->decoded));
  EXPECT_TRUE(full.isOk());
  if (full.isOk()) out.push_back({uint32_t(ctx.bits), std::move(full).value()});
  return out;
}

// Every level of the cube decodes with its creases: each triangle flat on a face shows that face's normal at all
// three corners, and the cells along the cube's edges are split into wedges. One value per cell (version 3) gets
// some of those corners wrong at every level; the test checks that its measure sees that.
TEST_P(Creases, CubeEdgesSurviveEveryLevel) {
  const AttributeLayout layout{12, 0};
  const QuantizedMesh q = testing::quantized(creasedCube(24), 12, layout);
  auto levels = coarseLevels(codec(), TileContext{12, layout}, q);
  ASSERT_GE(levels.size(), 2u);
  // The last level is the cube as it was.
  EXPECT_TRUE(testing::cornerMultiset(levels.back().second, 12) == testing::cornerMultiset(q, 12));
  levels.pop_back();
  size_t checked = 0;
  for (const auto& [level, m] : levels) {
    SCOPED_TRACE("level " + std::to_string(level));
    const LevelCheck c = checkCube(m, 12);
    std::printf("level %u: %zu triangles, %zu flat, %zu wrong, %zu wedge vertices\n", level, c.triangles, c.flat,
                c.wrong, c.wedged);
    if (c.flat == 0) continue;
    ++checked;
    EXPECT_EQ(c.wrong, 0u);
    EXPECT_GT(c.wedged, 0u);
    EXPECT_GT(checkCube(onePerPosition(m), 12).wrong, 0u) << "the check sees one normal per cell";
  }
  EXPECT_GE(checked, 3u);
}

// The corners of a level whose normal is more than 60 degrees from their triangle's plane normal (either side:
// coarse levels orient their triangles themselves): a normal from across a crease.
// Only the triangles `count` marks (all when empty).
size_t cornersAcrossACrease(const QuantizedMesh& m, int normal_bits, const std::vector<bool>& count = {}) {
  size_t across = 0;
  for (size_t i = 0; i < m.triangles.size(); ++i) {
    if (!count.empty() && !count[i]) continue;
    const Triangle& t = m.triangles[i];
    const Vec3d g = faceNormal(m, t);
    for (uint32_t v : t) {
      const Vec3f n = decodeOctahedral(m.normals[v], normal_bits);
      across += std::fabs(g[0] * n[0] + g[1] * n[1] + g[2] * n[2]) < 0.5;
    }
  }
  return across;
}

// Per triangle of level `level` of `q` (coded at `bits`), whether it is the projection of one of q's triangles onto
// the level's cells: octree shows every three-clique of a level's edges, and the others (ghosts) lie on no side of a
// crease.
std::vector<bool> projections(const QuantizedMesh& q, const QuantizedMesh& m, uint32_t level, int bits) {
  const auto cells = [&](const Vec3u& a, const Vec3u& b, const Vec3u& c) {
    std::array<Vec3u, 3> k{a, b, c};
    for (Vec3u& p : k)
      for (uint32_t& x : p) x >>= uint32_t(bits) - level;
    std::sort(k.begin(), k.end());
    return k;
  };
  std::set<std::array<Vec3u, 3>> fine;
  for (const Triangle& t : q.triangles) fine.insert(cells(q.positions[t[0]], q.positions[t[1]], q.positions[t[2]]));
  std::vector<bool> out;
  for (const Triangle& t : m.triangles)
    out.push_back(fine.count(cells(m.positions[t[0]], m.positions[t[1]], m.positions[t[2]])) > 0);
  return out;
}

// Fandisk with its normals per corner split at its sharp edges (30 degrees), a vertex per distinct normal of its
// corners (a wedge); every `leave_out`-th triangle left out (0: none).
Mesh fandiskWedged(const Mesh& base, size_t leave_out) {
  const auto split = testing::cornerNormalsSplitAt(base, 30);
  Mesh wedged;
  std::map<std::pair<uint32_t, Vec3f>, uint32_t> wedge;
  for (size_t f = 0; f < base.triangles.size(); ++f) {
    if (leave_out && f % leave_out == leave_out - 1) continue;
    Triangle t;
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = base.triangles[f][size_t(k)];
      const auto& c = split[3 * f + size_t(k)];
      const Vec3f n{float(c[0]), float(c[1]), float(c[2])};
      const auto [it, added] = wedge.try_emplace({v, n}, uint32_t(wedged.positions.size()));
      if (added) wedged.positions.push_back(base.positions[v]), wedged.normals.push_back(n);
      t[size_t(k)] = it->second;
    }
    wedged.triangles.push_back(t);
  }
  return wedged;
}

// Per level of `levels`: the corners across a crease, and those one normal per position would show (printed); their
// totals.
std::pair<size_t, size_t> acrossPerLevel(const std::vector<std::pair<uint32_t, QuantizedMesh>>& levels,
                                         const std::function<void(uint32_t, size_t, size_t)>& check = {}) {
  size_t total = 0, total_merged = 0;
  for (const auto& [level, m] : levels) {
    const size_t across = cornersAcrossACrease(m, 12);
    const size_t merged = cornersAcrossACrease(onePerPosition(m), 12);
    std::printf("level %u: %zu corners, %zu across a crease (one normal per position: %zu)\n", level,
                3 * m.triangles.size(), across, merged);
    total += across, total_merged += merged;
    if (check) check(level, across, merged);
  }
  return {total, total_merged};
}

// Fandisk with a normal per corner split at its sharp edges (30 degrees), each vertex one wedge per distinct
// normal: at every coarse level the corners' normals come from their own side of the creases. Measured against the
// same levels with one normal per position, which is what version 3 showed.
TEST_P(Creases, FandiskCreasesSurviveEveryLevel) {
  const std::string path = testing::sharedDataDir() + "/fandisk.obj";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
  auto base = readMeshFile(path);
  ASSERT_TRUE(base.isOk());
  const Mesh wedged = fandiskWedged(*base, 0);
  ASSERT_GT(wedged.positions.size(), base->positions.size() + 500);
  const AttributeLayout layout{12, 0};
  const QuantizedMesh q = testing::quantized(wedged, 14, layout);
  auto levels = coarseLevels(codec(), TileContext{14, layout}, q);
  ASSERT_GE(levels.size(), 2u);
  levels.pop_back();
  // Each level at least halves them; once cells are at most 64 grid cells (of 2^14), none is left (at coarser
  // levels a coarse triangle bridging a crease has a normal between its sides) on the projections of the tile's
  // triangles (octree's ghosts, one on fandisk, lie on no side).
  size_t i = 0;
  const auto [total, total_merged] = acrossPerLevel(levels, [&](uint32_t level, size_t across, size_t merged) {
    EXPECT_LE(2 * across, merged) << "level " << level;
    const QuantizedMesh& m = levels[i++].second;
    if (level >= 8) {
      EXPECT_EQ(cornersAcrossACrease(m, 12, projections(q, m, level, 14)), 0u) << "level " << level;
    }
  });
  EXPECT_EQ(cornersAcrossACrease(q, 12), 0u) << "the measure itself";
  EXPECT_GT(total_merged, 1000u);
  EXPECT_LT(total * 5, total_merged);
}

// A tile whose crease vertices' fans are cut into pieces (every fifth triangle of fandisk left out, as a tile's
// border cuts them): a vertex's corners are then more groups than it has points, and a fine level would show more
// vertices than the tile has. The groups that are one point merge (creases.h, Rules::merges; a level that still
// shows too many shows fewer groups, Rules::fit): the creases are kept, every level within the tile's count (kdtree
// v4, without these rules, coded such a tile as version 3).
TEST_P(Creases, FansCutIntoPiecesFitTheTile) {
  const std::string path = testing::sharedDataDir() + "/fandisk.obj";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
  auto base = readMeshFile(path);
  ASSERT_TRUE(base.isOk());
  const Mesh cut = fandiskWedged(*base, 5);
  const AttributeLayout layout{12, 0};
  const TileContext ctx{14, layout};
  const QuantizedMesh q = testing::quantized(cut, 14, layout);
  auto enc = encodeMesh(codec(), ctx, q);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  EXPECT_EQ(enc->version, codec().version);
  const auto levels = coarseLevels(codec(), ctx, q);
  ASSERT_GE(levels.size(), 5u);
  EXPECT_TRUE(testing::cornerMultiset(levels.back().second, 12) == testing::cornerMultiset(q, 12));
  size_t across = 0, merged = 0;
  for (const auto& [level, m] : levels) {
    EXPECT_LE(m.positions.size(), q.positions.size()) << "level " << level;
    if (level + 1 >= uint32_t(ctx.bits)) continue;
    // Octree's ghosts here are the triangles left out (their edges are still the surface's), on no side.
    const auto count = projections(q, m, level, ctx.bits);
    const size_t a = cornersAcrossACrease(m, 12, count), b = cornersAcrossACrease(onePerPosition(m), 12, count);
    std::printf(
        "level %u: %zu vertices (the tile's %zu), %zu corners across a crease (one normal per position: "
        "%zu)\n",
        level, m.positions.size(), q.positions.size(), a, b);
    // Where both sides of a crease meet at an edge (a cut edge) the crease is kept. Where the triangles between
    // them are gone on both sides of a vertex (no cut edge left at it), the vertex is one group showing one point's
    // values, as without creases: a fraction of the corners at fine levels.
    if (level >= 8) {
      EXPECT_LE(10 * a, b) << "level " << level;
    }
    across += a, merged += b;
  }
  EXPECT_LT(across * 2, merged);
}

// A UV sphere of `lat` x `lon` squares whose texture coordinates (u = longitude, v = latitude, on the 2^-12 grid)
// meet at a seam: the first and last columns share positions, at u = 0 and u = 1. Triangles with two corners at a
// pole are left out.
QuantizedMesh seamedSphere(int lat, int lon, const AttributeLayout& layout) {
  Mesh m;
  m.scalar_channels = layout.scalars;
  for (int j = 0; j <= lat; ++j)
    for (int i = 0; i <= lon; ++i) {
      const double th = M_PI * j / lat, ph = 2 * M_PI * (i % lon) / lon;
      m.positions.push_back({std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th)});
      m.scalars.push_back(std::bit_cast<uint32_t>(float(i) / float(lon)));
      m.scalars.push_back(std::bit_cast<uint32_t>(float(j) / float(lat)));
    }
  const auto at = [&](int j, int i) { return uint32_t(j * (lon + 1) + i); };
  for (int j = 0; j < lat; ++j)
    for (int i = 0; i < lon; ++i) {
      if (j > 0) m.triangles.push_back({at(j, i), at(j + 1, i), at(j, i + 1)});
      if (j + 1 < lat) m.triangles.push_back({at(j, i + 1), at(j + 1, i), at(j + 1, i + 1)});
    }
  return testing::quantized(m, 12, layout);
}

// The triangles of a level whose corners' u spans more than half the texture: a triangle across the seam.
size_t trianglesAcrossTheSeam(const QuantizedMesh& m) {
  size_t across = 0;
  for (const Triangle& t : m.triangles) {
    float lo = 2, hi = -1;
    for (uint32_t v : t) {
      const float u = std::bit_cast<float>(m.scalars[2 * size_t(v)]);
      lo = std::min(lo, u), hi = std::max(hi, u);
    }
    across += hi - lo > 0.5f;
  }
  return across;
}

// The seam of a UV sphere survives every level: no triangle interpolates u across it (one value per position, as
// version 3 showed a cell, does).
TEST_P(Creases, TextureSeamSurvivesEveryLevel) {
  AttributeLayout layout;
  layout.scalars = {{"u", ScalarType::kFloat32, 12}, {"v", ScalarType::kFloat32, 12}};
  const QuantizedMesh q = seamedSphere(32, 64, layout);
  ASSERT_EQ(trianglesAcrossTheSeam(q), 0u);
  auto levels = coarseLevels(codec(), TileContext{12, layout}, q);
  ASSERT_GE(levels.size(), 5u);
  // The lossless level: every corner's position and texture coordinates as given.
  const auto corners = [](const QuantizedMesh& m) {
    std::multiset<std::tuple<Vec3u, uint32_t, uint32_t>> out;
    for (const Triangle& t : m.triangles)
      for (uint32_t v : t) out.insert({m.positions[v], m.scalars[2 * size_t(v)], m.scalars[2 * size_t(v) + 1]});
    return out;
  };
  EXPECT_TRUE(corners(levels.back().second) == corners(q));
  size_t merged_total = 0;
  for (const auto& [level, m] : levels) {
    EXPECT_EQ(trianglesAcrossTheSeam(m), 0u) << "level " << level;
    merged_total += trianglesAcrossTheSeam(onePerPosition(m));
  }
  EXPECT_GT(merged_total, 50u);
}

// Version 4 payloads cut anywhere or with flipped bytes decode to a valid mesh within the index's counts, or fail
// cleanly, at every level.
TEST_P(Creases, HostilePayloadsFailCleanly) {
  const AttributeLayout layout{10, 0};
  const QuantizedMesh q = testing::quantized(creasedCube(6), 12, layout);
  const TileContext ctx{12, layout};
  auto enc = encodeMesh(codec(), ctx, q);
  ASSERT_TRUE(enc.isOk());
  ASSERT_EQ(enc->version, codec().version);
  const DecodeLimits lim = limitsOf(enc->decoded);
  const std::vector<uint8_t>& bytes = enc->payload;
  for (size_t n = 0; n < bytes.size(); n += testing::sampleStride()) {
    for (uint32_t level : {3u, 6u, 12u}) {
      auto d = codec().decode_level(ctx, enc->version, std::span(bytes).first(n), level, lim);
      if (d.isOk()) {
        EXPECT_TRUE(validateTile(ctx, *d).isOk());
        EXPECT_LE(d->positions.size(), lim.vertices);
      }
    }
  }
  std::mt19937 rng(5);
  size_t decoded = 0;
  for (int trial = 0; trial < testing::sampled(3000); ++trial) {
    std::vector<uint8_t> b = bytes;
    for (int f = 0; f < 1 + trial % 3; ++f) b[rng() % b.size()] ^= uint8_t(1 + rng() % 255);
    const uint32_t level = 1 + uint32_t(rng() % 12);
    auto d = codec().decode_level(ctx, enc->version, b, level, lim);
    if (!d.isOk()) continue;
    ++decoded;
    ASSERT_TRUE(validateTile(ctx, *d).isOk()) << trial;
    EXPECT_LE(d->positions.size(), lim.vertices);
  }
  std::printf("%zu of %d corrupted payloads decoded (to valid meshes)\n", decoded, testing::sampled(3000));
}

// A tile without creases or seams (one normal per position, a wedge of equal values) is written as version 3: the
// same bytes as before version 4 existed.
TEST_P(Creases, TileWithoutCreasesIsVersion3) {
  const AttributeLayout layout{12, 0};
  Mesh smooth = creasedCube(4);
  for (Vec3f& n : smooth.normals) n = {0.f, 0.f, 1.f};  // equal at every position: no cut edge
  const QuantizedMesh q = testing::quantized(smooth, 12, layout);
  auto enc = encodeMesh(codec(), TileContext{12, layout}, q);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  EXPECT_EQ(enc->version, 3);
  auto creased = encodeMesh(codec(), TileContext{12, layout}, testing::quantized(creasedCube(4), 12, layout));
  ASSERT_TRUE(creased.isOk());
  EXPECT_EQ(creased->version, codec().version);
}

INSTANTIATE_TEST_SUITE_P(Codecs, Creases, ::testing::Values(CodecId::kKdtree, CodecId::kOctree),
                         [](const auto& info) { return std::string(findCodec(info.param)->name); });

// pm (v5) keeps a crease's or a seam's wedges through its simplified levels: a collapse moves a corner only to the
// wedge on its own side (simplify.h, corner_wedges), and a wedge a split adds shows its parent's values, which lie
// on the same side. Every level of `q` coded by pm (the last level simplified to `ratio` of the faces), each decoded
// from the payload cut at its end and valid.
std::vector<std::pair<uint32_t, QuantizedMesh>> pmLevels(const TileContext& ctx, const QuantizedMesh& q, double ratio) {
  std::vector<std::pair<uint32_t, QuantizedMesh>> out;
  const CodecInfo& pm = *findCodec(CodecId::kPm);
  CodecOptions o;
  o.pm.ratio = ratio;
  auto enc = encodeMesh(pm, ctx, q, o);
  EXPECT_TRUE(enc.isOk()) << enc.status().toString();
  if (!enc.isOk()) return out;
  EXPECT_EQ(enc->version, 5);
  std::printf("pm v%d payload (ratio %.2f): %zu bytes\n", int(enc->version), ratio, enc->payload.size());
  auto levels = pm.levels(ctx, enc->version, enc->payload, limitsOf(enc->decoded));
  EXPECT_TRUE(levels.isOk());
  if (!levels.isOk()) return out;
  for (const CodecLevel& l : *levels) {
    auto m = pm.decode_level(ctx, enc->version, std::span(enc->payload).first(l.end_bytes), l.level,
                             limitsOf(enc->decoded));
    EXPECT_TRUE(m.isOk()) << "level " << l.level << ": " << m.status().toString();
    if (!m.isOk()) continue;
    EXPECT_TRUE(validateTile(ctx, *m).isOk()) << "level " << l.level;
    EXPECT_EQ(m->positions.size(), l.vertices) << "level " << l.level;
    out.push_back({l.level, std::move(m).value()});
  }
  return out;
}

// The cube: every flat triangle shows its face's normal at every level of pm, lossless and simplified.
TEST(PmCreases, CubeEdgesSurviveEveryLevel) {
  const AttributeLayout layout{12, 0};
  const QuantizedMesh q = testing::quantized(creasedCube(24), 12, layout);
  for (const double ratio : {1.0, 0.1}) {
    SCOPED_TRACE(ratio);
    const auto levels = pmLevels(TileContext{12, layout}, q, ratio);
    ASSERT_GE(levels.size(), 3u);
    if (ratio == 1.0) EXPECT_TRUE(testing::cornerMultiset(levels.back().second, 12) == testing::cornerMultiset(q, 12));
    size_t seen = 0;
    for (const auto& [level, m] : levels) {
      SCOPED_TRACE("level " + std::to_string(level));
      const LevelCheck c = checkCube(m, 12);
      std::printf("level %u: %zu triangles, %zu flat, %zu wrong, %zu wedge vertices\n", level, c.triangles, c.flat,
                  c.wrong, c.wedged);
      EXPECT_EQ(c.wrong, 0u);
      EXPECT_GT(c.wedged, 0u);
      seen += checkCube(onePerPosition(m), 12).wrong;
    }
    EXPECT_GT(seen, 0u) << "the check sees one normal per position";
  }
}

// Fandisk split at 30 degrees: no corner shows a normal from across a crease at any level of pm (a coarse triangle
// is a simplified one, not a cell's: it lies on one side), lossless and simplified to a fifth.
TEST(PmCreases, FandiskCreasesSurviveEveryLevel) {
  const std::string path = testing::sharedDataDir() + "/fandisk.obj";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
  auto base = readMeshFile(path);
  ASSERT_TRUE(base.isOk());
  const AttributeLayout layout{12, 0};
  const QuantizedMesh q = testing::quantized(fandiskWedged(*base, 0), 14, layout);
  for (const double ratio : {1.0, 0.2}) {
    SCOPED_TRACE(ratio);
    const auto levels = pmLevels(TileContext{14, layout}, q, ratio);
    ASSERT_GE(levels.size(), 3u);
    if (ratio == 1.0) EXPECT_TRUE(testing::cornerMultiset(levels.back().second, 12) == testing::cornerMultiset(q, 12));
    const auto [total, total_merged] = acrossPerLevel(levels);
    EXPECT_GT(total_merged, 300u);
    EXPECT_LE(total * 50, total_merged);
  }
}

// The UV sphere's seam: no triangle interpolates u across it at any level of pm.
TEST(PmCreases, TextureSeamSurvivesEveryLevel) {
  AttributeLayout layout;
  layout.scalars = {{"u", ScalarType::kFloat32, 12}, {"v", ScalarType::kFloat32, 12}};
  const QuantizedMesh q = seamedSphere(32, 64, layout);
  for (const double ratio : {1.0, 0.1}) {
    SCOPED_TRACE(ratio);
    const auto levels = pmLevels(TileContext{12, layout}, q, ratio);
    ASSERT_GE(levels.size(), 3u);
    size_t merged_total = 0;
    for (const auto& [level, m] : levels) {
      EXPECT_EQ(trianglesAcrossTheSeam(m), 0u) << "level " << level;
      merged_total += trianglesAcrossTheSeam(onePerPosition(m));
    }
    EXPECT_GT(merged_total, 10u);
  }
}

// The cut edges against a brute force over every pair of triangles on random meshes with wedges.
TEST(CutEdges, MatchABruteForce) {
  std::mt19937 rng(9);
  for (int trial = 0; trial < 200; ++trial) {
    hierarchy::Points pts;
    const uint32_t positions = 4 + rng() % 12;
    for (uint32_t p = 0; p < positions; ++p) {
      const uint32_t wedges = 1 + (rng() % 4 == 0 ? 1 + rng() % 2 : 0);
      for (uint32_t w = 0; w < wedges; ++w) pts.pos.push_back({p, 0, 0});
    }
    const uint32_t n = uint32_t(pts.pos.size());
    std::set<hierarchy::TriKey> keys;
    for (int t = 0; t < 30; ++t) {
      hierarchy::TriKey k{uint32_t(rng() % n), uint32_t(rng() % n), uint32_t(rng() % n)};
      std::sort(k.begin(), k.end());
      if (k[0] != k[1] && k[1] != k[2]) keys.insert(k);
    }
    pts.tri_keys.assign(keys.begin(), keys.end());
    std::set<uint64_t> want;
    for (const auto& a : pts.tri_keys)
      for (const auto& b : pts.tri_keys)
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) {
            const uint32_t a0 = a[i], a1 = a[(i + 1) % 3], b0 = b[j], b1 = b[(j + 1) % 3];
            const auto same = [&](uint32_t x, uint32_t y) { return pts.pos[x] == pts.pos[y]; };
            if (pts.pos[a0] == pts.pos[a1]) continue;
            const bool same_positions = (same(a0, b0) && same(a1, b1)) || (same(a0, b1) && same(a1, b0));
            if (same_positions && hierarchy::edgeKey(a0, a1) != hierarchy::edgeKey(b0, b1))
              want.insert(hierarchy::edgeKey(a0, a1));
          }
    const auto got = hierarchy::cutEdges(pts);
    EXPECT_EQ(std::set<uint64_t>(got.begin(), got.end()), want) << trial;
  }
}

}  // namespace
}  // namespace scanpress
