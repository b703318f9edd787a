// Codec `pm`: every level of a payload is the replay of the simplifier's collapses up to a pass boundary (checked
// against an independent forward replay of simplify()'s output, as triangles over positions), the last level is
// the tile when lossless, locked vertices survive at every level, ugly meshes (non-manifold, boundaries,
// duplicates, soups, degenerate triangles, isolated vertices) round-trip, every truncation and corruption fails
// cleanly or decodes a level, and hostile counts are refused before allocation.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <map>
#include <random>
#include <set>

#include "engine/codecs/attributes.h"
#include "engine/codecs/codec.h"
#include "engine/quantize.h"
#include "engine/shapes.h"
#include "engine/simplify/simplify.h"
#include "test_util.h"

namespace scanpress {
namespace {

using testing::quantized;
using testing::rawMesh;

using testing::PosTriangle;
using testing::triangleMultiset;

const CodecInfo& pm() { return *findCodec(CodecId::kPm); }

// The tile as pm's last level keeps it: triangles over positions, without those repeating a position.
std::vector<PosTriangle> weldedTriangles(const QuantizedMesh& m) {
  std::vector<PosTriangle> out;
  for (const auto& t : triangleMultiset(m))
    if (t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) out.push_back(t);
  return out;
}

// Welds by position (what the encoder simplifies), with lock flags OR-ed.
QuantizedMesh weld(const QuantizedMesh& m, std::span<const uint8_t> locked, std::vector<uint8_t>* welded_locked) {
  std::map<Vec3u, uint32_t> index;
  for (const auto& p : m.positions) index.emplace(p, 0);
  QuantizedMesh w;
  for (auto& [p, i] : index) i = uint32_t(w.positions.size()), w.positions.push_back(p);
  if (welded_locked) {
    welded_locked->assign(w.positions.size(), 0);
    for (size_t v = 0; v < locked.size(); ++v)
      if (locked[v]) (*welded_locked)[index[m.positions[v]]] = 1;
  }
  for (const auto& t : m.triangles) {
    const Triangle x{index[m.positions[t[0]]], index[m.positions[t[1]]], index[m.positions[t[2]]]};
    if (x[0] != x[1] && x[1] != x[2] && x[0] != x[2]) w.triangles.push_back(x);
  }
  return w;
}

// Replays collapses on a mesh (the header's definition), returning the triangles over positions after each pass.
std::vector<std::vector<PosTriangle>> replayPasses(const QuantizedMesh& mesh, const Simplification& s) {
  QuantizedMesh cur = mesh;
  std::vector<std::vector<PosTriangle>> out;
  size_t c = 0;
  for (uint32_t end : s.pass_ends) {
    for (; c < end; ++c) {
      const EdgeCollapse& e = s.collapses[c];
      std::vector<Triangle> next;
      for (Triangle t : cur.triangles) {
        const bool k = t[0] == e.kept || t[1] == e.kept || t[2] == e.kept;
        const bool r = t[0] == e.removed || t[1] == e.removed || t[2] == e.removed;
        if (k && r) continue;
        for (uint32_t& v : t)
          if (v == e.removed) v = e.kept;
        next.push_back(t);
      }
      cur.triangles = std::move(next);
      cur.positions[e.kept] = e.position;
    }
    out.push_back(triangleMultiset(cur));
  }
  return out;
}

struct Encoded {
  EncodedTile tile;
  std::vector<CodecLevel> levels;
  uint16_t version = 0;  // the payload's (pm writes v5 only for a tile with wedges)
};

Encoded encodeTile(const TileContext& ctx, const QuantizedMesh& m, std::span<const uint8_t> locked,
                   const PmOptions& opt = {}) {
  CodecOptions o;
  o.pm = opt;
  auto e = pm().encode(ctx, TileView{m, locked}, o);
  EXPECT_TRUE(e.isOk()) << e.status().toString();
  if (!e.isOk()) return {};
  const uint16_t version = payloadVersion(pm(), *e);
  auto levels = pm().levels(ctx, version, e->payload, limitsOf(e->decoded));
  EXPECT_TRUE(levels.isOk()) << levels.status().toString();
  EXPECT_EQ(levels->size(), e->levels.size());
  for (size_t i = 0; i < levels->size() && i < e->levels.size(); ++i) {
    EXPECT_EQ((*levels)[i].end_bytes, e->levels[i].end_bytes);
    EXPECT_EQ((*levels)[i].vertices, e->levels[i].vertices);
  }
  return Encoded{std::move(e).value(), levels.isOk() ? *levels : std::vector<CodecLevel>{}, version};
}

// Options that simplify to `ratio` of the tile's faces (1: lossless).
PmOptions ratioOptions(double ratio) {
  PmOptions opt;
  opt.ratio = ratio;
  return opt;
}

// Checks every level against the replay of the simplifications (lossless when opt.max_error < 0).
void expectLevelsReplay(const TileContext& ctx, const QuantizedMesh& tile, std::span<const uint8_t> locked,
                        const PmOptions& opt) {
  const Encoded enc = encodeTile(ctx, tile, locked, opt);
  ASSERT_FALSE(enc.levels.empty());
  // Independent truth: the welded tile, the last level and the base by replaying simplify()'s collapses.
  std::vector<uint8_t> wl;
  const QuantizedMesh welded = weld(tile, locked, &wl);
  QuantizedMesh last = welded;
  std::vector<uint8_t> last_locked = wl;
  if (opt.max_error >= 0 || opt.ratio < 1) {
    SimplifyOptions so;
    so.weights = opt.weights;
    so.max_error = opt.max_error < 0 ? std::numeric_limits<double>::infinity() : opt.max_error;
    so.target_faces = opt.ratio < 1 ? uint64_t(std::ceil(opt.ratio * double(welded.triangles.size()))) : 0;
    auto s1 = simplify(welded, wl, so);
    ASSERT_TRUE(s1.isOk());
    auto passes = replayPasses(welded, *s1);
    const std::vector<PosTriangle> expect_last = passes.empty() ? triangleMultiset(welded) : passes.back();
    auto d = pm().decode(ctx, enc.version, enc.tile.payload, limitsOf(enc.tile.decoded));
    ASSERT_TRUE(d.isOk()) << d.status().toString();
    EXPECT_TRUE(triangleMultiset(*d) == expect_last) << "the last level is not the simplified tile";
    return;  // the coarser levels are checked on lossless encodes (the same code path from the last level on)
  }
  // Pass boundaries of the simplification towards the base, as the encoder does it (pm.cpp: 1/8 of the faces).
  SimplifyOptions so2;
  so2.endpoints_only = true;  // as pm codes its splits
  so2.weights = opt.weights;
  so2.target_faces = std::max<uint64_t>(16, uint64_t(double(last.triangles.size()) / 8));
  std::set<std::vector<PosTriangle>> states;
  states.insert(triangleMultiset(last));
  if (last.triangles.size() > so2.target_faces) {
    auto s2 = simplify(last, last_locked, so2);
    ASSERT_TRUE(s2.isOk());
    for (auto& p : replayPasses(last, *s2)) states.insert(std::move(p));
  }
  std::set<Vec3u> locked_positions;
  for (size_t v = 0; v < locked.size(); ++v)
    if (locked[v]) locked_positions.insert(tile.positions[v]);
  uint64_t prev_vertices = 0;
  for (const CodecLevel& l : enc.levels) {
    SCOPED_TRACE(l.level);
    auto d = pm().decode_level(ctx, enc.version, std::span(enc.tile.payload).first(l.end_bytes), l.level,
                               limitsOf(enc.tile.decoded));
    ASSERT_TRUE(d.isOk()) << d.status().toString();
    EXPECT_TRUE(validateTile(ctx, *d).isOk());
    EXPECT_EQ(d->positions.size(), l.vertices);
    EXPECT_GE(l.vertices, prev_vertices);
    prev_vertices = l.vertices;
    EXPECT_EQ(l.kind, LevelKind::kSimplified);
    EXPECT_TRUE(states.count(triangleMultiset(*d))) << "level " << l.level << " is no pass boundary of the replay";
    std::set<Vec3u> have(d->positions.begin(), d->positions.end());
    for (const auto& p : locked_positions) EXPECT_TRUE(have.count(p)) << "a locked vertex is missing";
  }
  EXPECT_TRUE(enc.levels.back().complete);
  auto full = pm().decode(ctx, enc.version, enc.tile.payload, limitsOf(enc.tile.decoded));
  ASSERT_TRUE(full.isOk()) << full.status().toString();
  EXPECT_TRUE(weldedTriangles(*full) == weldedTriangles(tile)) << "the last level is not the tile";
  const TileSummary got = summarize(*full);
  EXPECT_EQ(got.vertices, enc.tile.decoded.vertices);
  EXPECT_EQ(got.faces, enc.tile.decoded.faces);
  EXPECT_EQ(got.lo, enc.tile.decoded.lo);
  EXPECT_EQ(got.hi, enc.tile.decoded.hi);
}

TEST(Pm, SphereEveryLevelReplaysTheCollapses) {
  const TileContext ctx{14, {}};
  const QuantizedMesh sphere = quantized(icosphere(5), 14);
  expectLevelsReplay(ctx, sphere, {}, PmOptions{});
  const Encoded enc = encodeTile(ctx, sphere, {});
  EXPECT_GE(enc.levels.size(), 4u);
  EXPECT_LT(enc.levels.front().vertices, sphere.positions.size() / 4);
}

TEST(Pm, LossyLastLevelIsTheSimplifiedTile) {
  const TileContext ctx{14, {}};
  const QuantizedMesh sphere = quantized(icosphere(5), 14);
  PmOptions opt;
  opt.max_error = 1e9;  // the face ratio decides
  opt.ratio = 0.3;
  expectLevelsReplay(ctx, sphere, {}, opt);
  const Encoded lossy = encodeTile(ctx, sphere, {}, opt);
  EXPECT_LE(lossy.tile.decoded.faces, uint64_t(0.3 * double(sphere.triangles.size())) + 2);
  EXPECT_LT(lossy.tile.payload.size(), encodeTile(ctx, sphere, {}).tile.payload.size());
}

TEST(Pm, LockedVerticesSurviveEveryLevel) {
  const TileContext ctx{12, {}};
  const QuantizedMesh sphere = quantized(icosphere(4), 12);
  std::vector<uint8_t> locked(sphere.positions.size(), 0);
  for (size_t v = 0; v < locked.size(); ++v) locked[v] = sphere.positions[v][0] < 1200;  // a cap of the sphere
  expectLevelsReplay(ctx, sphere, locked, PmOptions{});
  // Lossy, locked positions kept at the last level too.
  PmOptions opt;
  opt.max_error = 100;
  opt.ratio = 0.1;
  const Encoded enc = encodeTile(ctx, sphere, locked, opt);
  for (const CodecLevel& l : enc.levels) {
    auto d = pm().decode_level(ctx, enc.version, enc.tile.payload, l.level, limitsOf(enc.tile.decoded));
    ASSERT_TRUE(d.isOk());
    std::set<Vec3u> have(d->positions.begin(), d->positions.end());
    for (size_t v = 0; v < locked.size(); ++v)
      if (locked[v]) {
        EXPECT_TRUE(have.count(sphere.positions[v]));
      }
  }
}

TEST(Pm, UglyMeshesRoundTrip) {
  const TileContext ctx{10, {}};
  // Empty, points only, one triangle.
  expectLevelsReplay(ctx, QuantizedMesh{}, {}, PmOptions{});
  expectLevelsReplay(ctx, rawMesh({{1, 2, 3}, {4, 5, 6}, {1, 2, 3}}, {}), {}, PmOptions{});
  expectLevelsReplay(ctx, rawMesh({{0, 0, 0}, {9, 0, 0}, {0, 9, 0}}, {{0, 1, 2}}), {}, PmOptions{});
  // A grid patch with an open boundary, plus non-manifold fins, duplicates, a reversed copy, a degenerate triangle,
  // coincident vertices (a soup corner) and an isolated vertex.
  QuantizedMesh m;
  const int n = 24;
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x)
      m.positions.push_back({uint32_t(10 + 20 * x), uint32_t(10 + 20 * y), uint32_t(500 + (x * y) % 7)});
  for (int y = 0; y + 1 < n; ++y)
    for (int x = 0; x + 1 < n; ++x) {
      const uint32_t a = y * n + x, b = a + 1, c = a + n, d = c + 1;
      m.triangles.push_back({a, b, d});
      m.triangles.push_back({a, d, c});
    }
  const uint32_t fin = uint32_t(m.positions.size());
  m.positions.push_back({200, 200, 900});
  m.positions.push_back({220, 220, 100});
  m.triangles.push_back({5 * n + 5, 5 * n + 6, fin});  // three faces on one edge
  m.triangles.push_back({5 * n + 6, 5 * n + 5, fin + 1});
  m.triangles.push_back(m.triangles[40]);
  m.triangles.push_back({m.triangles[60][0], m.triangles[60][2], m.triangles[60][1]});
  m.triangles.push_back({3, 3, 4});
  const uint32_t twin = uint32_t(m.positions.size());
  m.positions.push_back(m.positions[10 * n + 10]);
  m.triangles.push_back({twin, 10 * n + 11, 11 * n + 11});
  m.positions.push_back({1000, 1000, 1000});
  expectLevelsReplay(ctx, m, {}, PmOptions{});
  // A soup: every triangle with its own corners.
  QuantizedMesh soup;
  for (const auto& t : quantized(icosphere(3), 10).triangles) {
    const QuantizedMesh s = quantized(icosphere(3), 10);
    const uint32_t base = uint32_t(soup.positions.size());
    for (uint32_t v : t) soup.positions.push_back(s.positions[v]);
    soup.triangles.push_back({base, base + 1, base + 2});
  }
  expectLevelsReplay(ctx, soup, {}, PmOptions{});
}

// A sphere with normals (its own directions, jittered) and 8-bit RGBA colors that name their vertex (so a decoded
// color says which input vertex it came from), plus a twin of every 7th vertex at its position with other
// attributes, its color naming it too, used by every other triangle around the vertex (pm keeps both: wedges, v5).
QuantizedMesh attributedPmSphere(const AttributeLayout& layout, int subdivisions) {
  Mesh s = icosphere(subdivisions);
  std::mt19937 rng(5);
  std::normal_distribution<float> jitter(0.f, 0.05f);
  const size_t n = s.positions.size();
  for (size_t v = 0; v < n; ++v) {
    const auto& p = s.positions[v];
    s.normals.push_back({float(p[0]) + jitter(rng), float(p[1]) + jitter(rng), float(p[2]) + jitter(rng)});
    s.colors.push_back({uint8_t(v & 0xFF), uint8_t((v >> 8) & 0xFF), uint8_t(v >> 16), 200});
  }
  for (size_t v = 0; v < n; v += 7) {
    const uint32_t twin = uint32_t(s.positions.size());
    s.positions.push_back(s.positions[v]);
    s.normals.push_back({-s.normals[v][0], -s.normals[v][1], -s.normals[v][2]});
    s.colors.push_back({uint8_t(v & 0xFF), uint8_t((v >> 8) & 0xFF), 1, 100});
    for (auto& t : s.triangles)
      if (t[0] == v && (&t - s.triangles.data()) % 2 == 0) t[0] = twin;
  }
  s.color_channels = 4;
  auto grid = makeGrid(boundingBox(s), 12);
  EXPECT_TRUE(grid.isOk());
  auto q = quantizeMesh(s, *grid, layout, nullptr);
  EXPECT_TRUE(q.isOk());
  return *q;
}

// Per triangle its corners' positions and attributes (normal, the layout's color channels, scalar row), rotated to
// start at its least corner, sorted: what a lossless decode gives back corner for corner.
std::vector<std::array<std::vector<uint32_t>, 3>> cornerRows(const QuantizedMesh& m, const AttributeLayout& layout) {
  const size_t stride = size_t(layout.scalarStride());
  auto corner = [&](uint32_t v) {
    std::vector<uint32_t> c(m.positions[v].begin(), m.positions[v].end());
    if (layout.hasNormals()) c.insert(c.end(), {m.normals[v][0], m.normals[v][1]});
    for (int k = 0; k < layout.color_channels; ++k) c.push_back(m.colors[v][k]);
    c.insert(c.end(), m.scalars.begin() + ptrdiff_t(v * stride), m.scalars.begin() + ptrdiff_t((v + 1) * stride));
    return c;
  };
  std::vector<std::array<std::vector<uint32_t>, 3>> out;
  for (const Triangle& t : m.triangles) {
    std::array<std::vector<uint32_t>, 3> c{corner(t[0]), corner(t[1]), corner(t[2])};
    std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
    out.push_back(std::move(c));
  }
  std::sort(out.begin(), out.end());
  return out;
}

// The points that share a position with an earlier point but not its attributes (what pm reports merged).
uint64_t differingTwins(const QuantizedMesh& m, const AttributeLayout& layout) {
  const size_t stride = size_t(layout.scalarStride());
  std::map<Vec3u, size_t> first;
  uint64_t n = 0;
  for (size_t v = 0; v < m.positions.size(); ++v) {
    const auto [it, fresh] = first.emplace(m.positions[v], v);
    const size_t f = it->second;
    n += !fresh &&
         ((layout.hasNormals() && m.normals[v] != m.normals[f]) || (layout.hasColors() && m.colors[v] != m.colors[f]) ||
          !std::equal(m.scalars.begin() + ptrdiff_t(v * stride), m.scalars.begin() + ptrdiff_t((v + 1) * stride),
                      m.scalars.begin() + ptrdiff_t(f * stride)));
  }
  return n;
}

// v3: every level shows the tile's own normals and colors. pm's vertex order is fixed by the payload (each split
// appends its wedges), so vertex i of a level is vertex i of the last level; the last level gives every corner its
// input vertex's attributes (lossless: the twins are wedges, v5), or a kept input vertex's (lossy: no two vertices
// show the same one).
TEST(Pm, EveryLevelShowsTheTilesOwnAttributes) {
  for (const AttributeLayout& layout :
       {AttributeLayout{10, 4}, AttributeLayout{12, 0}, AttributeLayout{0, 4}, AttributeLayout{6, 3, 5}}) {
    SCOPED_TRACE(::testing::Message() << int(layout.normal_bits) << " " << int(layout.color_channels) << " "
                                      << int(layout.color_bits));
    const TileContext ctx{12, layout};
    const QuantizedMesh tile = attributedPmSphere(layout, 4);
    std::set<Rgba8> input_colors(tile.colors.begin(), tile.colors.end());
    for (const double ratio : {1.0, 0.2}) {
      SCOPED_TRACE(ratio);
      const Encoded enc = encodeTile(ctx, tile, {}, ratioOptions(ratio));
      ASSERT_GE(enc.levels.size(), 3u);
      // The twins' other attributes are kept as wedges, nothing merged.
      EXPECT_EQ(enc.version, 5);
      EXPECT_EQ(enc.tile.merged_points, 0u);
      EXPECT_GT(differingTwins(tile, layout), 0u);
      auto full = pm().decode(ctx, enc.version, enc.tile.payload, limitsOf(enc.tile.decoded));
      ASSERT_TRUE(full.isOk()) << full.status().toString();
      ASSERT_TRUE(validateTile(ctx, *full).isOk());
      ASSERT_EQ(full->normals.size(), layout.hasNormals() ? full->positions.size() : 0u);
      ASSERT_EQ(full->colors.size(), layout.hasColors() ? full->positions.size() : 0u);
      if (ratio == 1.0) {
        EXPECT_TRUE(weldedTriangles(*full) == weldedTriangles(tile));
        EXPECT_TRUE(cornerRows(*full, layout) == cornerRows(tile, layout));
      } else if (layout.hasColors() && layout.color_bits == 8 && layout.color_channels == 4) {
        // The colors name input vertices: each shown once.
        std::set<Rgba8> seen;
        for (const Rgba8& c : full->colors) {
          EXPECT_TRUE(seen.insert(c).second) << "two vertices show one input vertex's color";
          EXPECT_TRUE(input_colors.count(c)) << "a color that no input vertex has";
        }
      }
      // The base's vertices show their own at every level; a vertex a later level adds shows, until the last
      // level, what its parent shows, so one of the base's.
      const size_t base = enc.levels.front().vertices;
      std::set<std::pair<OctNormal, Rgba8>> base_shows;
      for (size_t v = 0; v < base; ++v)
        base_shows.insert({layout.hasNormals() ? full->normals[v] : OctNormal{},
                           layout.hasColors() ? full->colors[v] : Rgba8{}});
      std::map<size_t, std::pair<OctNormal, Rgba8>> deferred;  // what a vertex past the base shows before the last
      for (const CodecLevel& l : enc.levels) {
        auto d = pm().decode_level(ctx, enc.version, std::span(enc.tile.payload).first(l.end_bytes), l.level,
                                   limitsOf(enc.tile.decoded));
        ASSERT_TRUE(d.isOk()) << d.status().toString();
        ASSERT_TRUE(validateTile(ctx, *d).isOk());
        ASSERT_EQ(d->positions.size(), l.vertices);
        for (size_t v = 0; v < d->positions.size(); ++v) {
          const std::pair<OctNormal, Rgba8> shown{layout.hasNormals() ? d->normals[v] : OctNormal{},
                                                  layout.hasColors() ? d->colors[v] : Rgba8{}};
          if (v < base || l.complete) {
            if (layout.hasNormals()) {
              ASSERT_EQ(d->normals[v], full->normals[v]) << "level " << l.level << " vertex " << v;
            }
            if (layout.hasColors()) {
              ASSERT_EQ(d->colors[v], full->colors[v]) << "level " << l.level << " vertex " << v;
            }
          } else {
            ASSERT_TRUE(base_shows.count(shown)) << "level " << l.level << " vertex " << v << " shows no base vertex's";
            // Its base ancestor does not change from level to level.
            const auto [it, fresh] = deferred.emplace(v, shown);
            ASSERT_TRUE(fresh || it->second == shown) << "level " << l.level << " vertex " << v << " changed";
          }
        }
      }
    }
  }
}

// A layout with scalar channels of every kind beside normals and colors: integers of each width and sign, float32,
// float64, and texture coordinates snapped to 2^-12 (`uv`: with them).
AttributeLayout scalarLayout(bool uv) {
  AttributeLayout layout{10, 3};
  layout.scalars = {{"confidence", ScalarType::kUint8},
                    {"flags", ScalarType::kInt16},
                    {"count", ScalarType::kUint32},
                    {"intensity", ScalarType::kFloat32},
                    {"time", ScalarType::kFloat64}};
  if (uv)
    layout.scalars.insert(layout.scalars.end(), {{"u", ScalarType::kFloat32, 12}, {"v", ScalarType::kFloat32, 12}});
  return layout;
}

// attributedPmSphere with the scalar channels of `layout`: a distinct row per input vertex (twins at a position
// differ from the first vertex there), texture coordinates a smooth function of the position, the same for twins
// unless `seams` (then every other twin gets other ones).
QuantizedMesh scalarPmSphere(const AttributeLayout& layout, int subdivisions, bool seams) {
  QuantizedMesh q = attributedPmSphere(AttributeLayout{layout.normal_bits, layout.color_channels}, subdivisions);
  std::map<Vec3u, uint32_t> first;
  uint32_t twins = 0;
  const size_t stride = size_t(layout.scalarStride());
  q.scalars.assign(q.positions.size() * stride, 0);
  for (uint32_t v = 0; v < q.positions.size(); ++v) {
    const auto [it, fresh] = first.emplace(q.positions[v], v);
    const bool other_uv = !fresh && seams && twins++ % 2 == 0;
    uint32_t* row = q.scalars.data() + size_t(v) * stride;
    size_t w = 0;
    for (const ScalarChannel& c : layout.scalars) {
      const Vec3u& p = q.positions[it->second];
      if (c.name == "u" || c.name == "v") {
        double t = (c.name == "u" ? p[0] : p[1]) / 4096.0;
        if (other_uv) t = 1 - t;
        const float level = float(std::round(t * 4096) / 4096);
        std::memcpy(&row[w], &level, 4);
      } else if (c.type == ScalarType::kFloat32) {
        const float f = float(v) * 0.37f - 100.f;
        std::memcpy(&row[w], &f, 4);
      } else if (c.type == ScalarType::kFloat64) {
        const double d = double(v) * 1e-7 + 1.6e9;
        std::memcpy(&row[w], &d, 8);
      } else {
        const int64_t x = c.type == ScalarType::kInt16 ? int64_t(v % 1000) - 500 : int64_t(v * 2654435761u % 200);
        hierarchy::scalarFromOrdered(c.type, x, &row[w]);
      }
      w += size_t(scalarTypeWords(c.type));
    }
  }
  return q;
}

std::span<const uint32_t> rowOf(const QuantizedMesh& m, size_t v, size_t stride) {
  return std::span<const uint32_t>(m.scalars.data() + v * stride, stride);
}

// v4: scalar channels through every level as normals and colors go (bit for bit: lossless at their type, texture
// coordinates at their levels). The last level gives every corner its input vertex's row (lossless; the twins,
// whose rows differ, are wedges: v5) or a kept input vertex's, each once (lossy); every level shows the base's own
// rows at base vertices and, elsewhere, until the last level, a base vertex's row that does not change from level
// to level.
TEST(Pm, ScalarChannelsThroughEveryLevel) {
  for (const bool uv : {false, true}) {
    SCOPED_TRACE(uv);
    const AttributeLayout layout = scalarLayout(uv);
    const size_t stride = size_t(layout.scalarStride());
    const TileContext ctx{12, layout};
    const QuantizedMesh tile = scalarPmSphere(layout, 4, false);
    ASSERT_TRUE(validateTile(ctx, tile).isOk());
    std::set<std::vector<uint32_t>> rows;
    for (size_t v = 0; v < tile.positions.size(); ++v) {
      const auto r = rowOf(tile, v, stride);
      rows.insert(std::vector<uint32_t>(r.begin(), r.end()));
    }
    for (const double ratio : {1.0, 0.2}) {
      SCOPED_TRACE(ratio);
      const Encoded enc = encodeTile(ctx, tile, {}, ratioOptions(ratio));
      ASSERT_GE(enc.levels.size(), 3u);
      EXPECT_EQ(payloadVersion(pm(), enc.tile), 5);
      EXPECT_EQ(enc.tile.merged_points, 0u);
      auto full = pm().decode(ctx, 5, enc.tile.payload, limitsOf(enc.tile.decoded));
      ASSERT_TRUE(full.isOk()) << full.status().toString();
      ASSERT_TRUE(validateTile(ctx, *full).isOk());
      ASSERT_EQ(full->scalars.size(), full->positions.size() * stride);
      std::set<std::vector<uint32_t>> shown;
      if (ratio == 1.0) EXPECT_TRUE(cornerRows(*full, layout) == cornerRows(tile, layout));
      for (size_t v = 0; v < full->positions.size(); ++v) {
        const auto r = rowOf(*full, v, stride);
        const std::vector<uint32_t> row(r.begin(), r.end());
        if (ratio != 1.0) {
          EXPECT_TRUE(rows.count(row)) << "vertex " << v << " shows a row no input vertex has";
          EXPECT_TRUE(shown.insert(row).second) << "two vertices show one input vertex's row";
        }
      }
      const size_t base = enc.levels.front().vertices;
      std::set<std::vector<uint32_t>> base_rows;
      for (size_t v = 0; v < base; ++v) {
        const auto r = rowOf(*full, v, stride);
        base_rows.insert(std::vector<uint32_t>(r.begin(), r.end()));
      }
      std::map<size_t, std::vector<uint32_t>> deferred;
      for (const CodecLevel& l : enc.levels) {
        auto d = pm().decode_level(ctx, 5, std::span(enc.tile.payload).first(l.end_bytes), l.level,
                                   limitsOf(enc.tile.decoded));
        ASSERT_TRUE(d.isOk()) << d.status().toString();
        ASSERT_TRUE(validateTile(ctx, *d).isOk());
        ASSERT_EQ(d->scalars.size(), l.vertices * stride);
        for (size_t v = 0; v < d->positions.size(); ++v) {
          const auto r = rowOf(*d, v, stride);
          const std::vector<uint32_t> row(r.begin(), r.end());
          if (v < base || l.complete) {
            const auto f = rowOf(*full, v, stride);
            ASSERT_TRUE(std::ranges::equal(r, f)) << "level " << l.level << " vertex " << v;
          } else {
            ASSERT_TRUE(base_rows.count(row)) << "level " << l.level << " vertex " << v << " shows no base row";
            const auto [it, fresh] = deferred.emplace(v, row);
            ASSERT_TRUE(fresh || it->second == row) << "level " << l.level << " vertex " << v << " changed";
          }
        }
      }
      // A payload of version 3 (which codes no scalars) in this layout is refused.
      auto v3 = pm().decode(ctx, 3, enc.tile.payload, limitsOf(enc.tile.decoded));
      ASSERT_FALSE(v3.isOk());
      EXPECT_EQ(v3.status().code(), ErrorCode::kMalformed);
    }
  }
}

// Texture coordinates that differ at one position (a seam carried as duplicated vertices) are wedges (v5): every
// corner gets its own back, lossless, and a simplified last level shows a kept input vertex's row at each corner.
TEST(Pm, TextureSeamsAreKeptAsWedges) {
  const AttributeLayout layout = scalarLayout(true);
  const TileContext ctx{12, layout};
  const QuantizedMesh tile = scalarPmSphere(layout, 3, true);
  ASSERT_TRUE(validateTile(ctx, tile).isOk());
  for (const double ratio : {1.0, 0.3}) {
    SCOPED_TRACE(ratio);
    const Encoded enc = encodeTile(ctx, tile, {}, ratioOptions(ratio));
    ASSERT_GE(enc.levels.size(), 2u);
    EXPECT_EQ(enc.version, 5);
    auto full = pm().decode(ctx, enc.version, enc.tile.payload, limitsOf(enc.tile.decoded));
    ASSERT_TRUE(full.isOk()) << full.status().toString();
    if (ratio == 1.0) {
      EXPECT_TRUE(cornerRows(*full, layout) == cornerRows(tile, layout));
    } else {
      // Each vertex shows an input vertex's row, each once (kept vertices may move: QEM placements).
      std::set<std::vector<uint32_t>> input, shown;
      const size_t stride = size_t(layout.scalarStride());
      for (size_t v = 0; v < tile.positions.size(); ++v) {
        const auto r = rowOf(tile, v, stride);
        input.insert(std::vector<uint32_t>(r.begin(), r.end()));
      }
      for (size_t v = 0; v < full->positions.size(); ++v) {
        const auto r = rowOf(*full, v, stride);
        const std::vector<uint32_t> row(r.begin(), r.end());
        EXPECT_TRUE(input.count(row)) << v;
        EXPECT_TRUE(shown.insert(row).second) << v;
      }
    }
  }
}

// A lossy last level can move a point into the cell of one it shares no triangle with (here: stray points placed
// where the simplifier puts collapsed vertices). Such points stay apart at every level, with attributes (v5: the
// base's wedge groups name which vertex a wedge at a shared position belongs to) and without (v3).
TEST(Pm, PointsMovedIntoOneCellStayApart) {
  const QuantizedMesh sphere = quantized(icosphere(4), 12);
  SimplifyOptions so;
  so.target_faces = uint64_t(std::ceil(0.2 * double(sphere.triangles.size())));
  auto s = simplify(sphere, {}, so);
  ASSERT_TRUE(s.isOk());
  const std::set<Vec3u> taken(sphere.positions.begin(), sphere.positions.end());
  QuantizedMesh tile = sphere;
  for (const EdgeCollapse& c : s->collapses)
    if (c.placement == 2 && !taken.count(c.position)) tile.positions.push_back(c.position);
  ASSERT_GT(tile.positions.size(), sphere.positions.size() + 100);
  for (const AttributeLayout& layout : {AttributeLayout{}, AttributeLayout{0, 3}}) {
    SCOPED_TRACE(int(layout.color_channels));
    size_t shared = 0;
    QuantizedMesh t = tile;
    if (layout.hasColors()) t.colors.assign(t.positions.size(), Rgba8{10, 20, 30, 255});  // no wedges
    const TileContext ctx{12, layout};
    const Encoded enc = encodeTile(ctx, t, {}, ratioOptions(0.2));
    ASSERT_GE(enc.levels.size(), 2u);
    EXPECT_EQ(enc.version, layout.hasColors() ? 5 : 3);
    for (const CodecLevel& l : enc.levels) {
      auto d = pm().decode_level(ctx, enc.version, std::span(enc.tile.payload).first(l.end_bytes), l.level,
                                 limitsOf(enc.tile.decoded));
      ASSERT_TRUE(d.isOk()) << d.status().toString();
      ASSERT_EQ(d->positions.size(), l.vertices);
      if (l.level == 0) {
        std::set<Vec3u> seen;
        for (const Vec3u& p : d->positions) shared += !seen.insert(p).second;
      }
    }
    auto full = pm().decode(ctx, enc.version, enc.tile.payload, limitsOf(enc.tile.decoded));
    ASSERT_TRUE(full.isOk()) << full.status().toString();
    EXPECT_EQ(full->triangles.size(), enc.tile.decoded.faces);
    EXPECT_GT(shared, 0u) << "no base point shares its cell: the test would not see the case";
  }
}

// Version 2 payloads (no attributes coded) still decode, with attributes derived from the triangles.
TEST(Pm, Version2DerivesAttributes) {
  const AttributeLayout layout{10, 3};
  const TileContext ctx{12, layout};
  const QuantizedMesh tile = attributedPmSphere(AttributeLayout{}, 3);
  const Encoded enc = encodeTile(TileContext{12, {}}, tile, {});  // without attributes: v3's bytes are v2's
  EXPECT_EQ(enc.tile.merged_points, 0u);                          // twins differ in nothing coded
  auto d = pm().decode(ctx, 2, enc.tile.payload, limitsOf(enc.tile.decoded));
  ASSERT_TRUE(d.isOk()) << d.status().toString();
  EXPECT_EQ(d->normals.size(), d->positions.size());
  EXPECT_EQ(d->colors.size(), d->positions.size());
  for (const Rgba8& c : d->colors) EXPECT_EQ(c, (Rgba8{128, 128, 128, 255}));
  EXPECT_TRUE(weldedTriangles(*d) == weldedTriangles(tile));
}

TEST(Pm, EveryTruncationFailsCleanlyOrDecodesALevel) {
  for (const AttributeLayout& layout : {AttributeLayout{}, AttributeLayout{10, 4}, scalarLayout(true)}) {
    const TileContext ctx{12, layout};
    const QuantizedMesh sphere = layout.hasScalars() ? scalarPmSphere(layout, 2, false) : attributedPmSphere(layout, 2);
    const Encoded enc = encodeTile(ctx, sphere, {});
    ASSERT_GE(enc.levels.size(), 3u);
    const auto& bytes = enc.tile.payload;
    const uint16_t version = payloadVersion(pm(), enc.tile);  // the version the container records
    const DecodeLimits limits = limitsOf(enc.tile.decoded);
    // Every cut (every fourth under the sanitizers).
    for (size_t cut = 0; cut < bytes.size(); cut += testing::sampleStride()) {
      const auto part = std::span(bytes).first(cut);
      EXPECT_FALSE(pm().decode(ctx, version, part, limits).isOk()) << cut;
      EXPECT_FALSE(pm().levels(ctx, version, part, limits).isOk()) << cut;
      for (const CodecLevel& l : enc.levels) {
        auto d = pm().decode_level(ctx, version, part, l.level, limits);
        EXPECT_EQ(d.isOk(), cut >= l.end_bytes) << "cut " << cut << " level " << l.level;
        if (d.isOk()) {
          EXPECT_EQ(d->positions.size(), l.vertices);
        }
      }
    }
  }
}

TEST(Pm, CorruptPayloadsFailCleanlyOrStayWithinLimits) {
  for (const AttributeLayout& layout : {AttributeLayout{}, AttributeLayout{10, 4}, scalarLayout(true)}) {
    const TileContext ctx{12, layout};
    const QuantizedMesh sphere = layout.hasScalars() ? scalarPmSphere(layout, 3, false) : attributedPmSphere(layout, 3);
    const Encoded enc = encodeTile(ctx, sphere, {});
    const DecodeLimits limits = limitsOf(enc.tile.decoded);
    const uint16_t version = payloadVersion(pm(), enc.tile);
    std::mt19937 rng(7);
    for (int trial = 0; trial < testing::sampled(1500); ++trial) {
      std::vector<uint8_t> bad = enc.tile.payload;
      const int flips = 1 + int(rng() % 3);
      for (int f = 0; f < flips; ++f) bad[rng() % bad.size()] ^= uint8_t(1u << (rng() % 8));
      auto d = pm().decode(ctx, version, bad, limits);
      if (d.isOk()) {
        EXPECT_LE(d->positions.size(), limits.vertices);
        EXPECT_LE(d->triangles.size(), limits.faces);
        EXPECT_TRUE(validateTile(ctx, *d).isOk());
      }
    }
  }
}

TEST(Pm, HostileCountsAreRefusedBeforeAllocating) {
  const TileContext ctx{12, {}};
  const QuantizedMesh sphere = quantized(icosphere(3), 12);
  const Encoded enc = encodeTile(ctx, sphere, {});
  const TileSummary s = enc.tile.decoded;
  EXPECT_EQ(pm().decode(ctx, enc.version, enc.tile.payload, DecodeLimits{s.vertices - 1, s.faces}).status().code(),
            ErrorCode::kMalformed);
  EXPECT_EQ(pm().decode(ctx, enc.version, enc.tile.payload, DecodeLimits{s.vertices, s.faces - 1}).status().code(),
            ErrorCode::kMalformed);
  // A header claiming 2^40 base vertices, and one claiming a level of 2^33 faces, within a few bytes.
  auto varint = [](std::vector<uint8_t>& out, uint64_t v) {
    while (v >= 0x80) out.push_back(uint8_t(v | 0x80)), v >>= 7;
    out.push_back(uint8_t(v));
  };
  std::vector<uint8_t> h1 = {2};
  varint(h1, 1), varint(h1, 0), varint(h1, uint64_t(1) << 40), varint(h1, 10);
  auto r1 = pm().decode(ctx, pm().version, h1, DecodeLimits{1000, 2000});
  EXPECT_EQ(r1.status().code(), ErrorCode::kMalformed) << r1.status().toString();
  // v5 level entries carry a wedge count after the vertex count: one claiming 2^33 wedges too.
  for (const uint16_t version : {uint16_t(4), uint16_t(5)})
    for (const bool huge_wedges : {false, true}) {
      if (version < 5 && huge_wedges) continue;
      SCOPED_TRACE(::testing::Message() << version << " " << huge_wedges);
      std::vector<uint8_t> h2 = {2};
      varint(h2, 1), varint(h2, 0), varint(h2, 4), varint(h2, 4);
      for (int i = 0; i < 4; ++i) h2.push_back(0);
      varint(h2, 1), varint(h2, 1), varint(h2, 5);
      if (version >= 5) varint(h2, huge_wedges ? uint64_t(1) << 33 : 6);
      varint(h2, huge_wedges ? 6 : uint64_t(1) << 33);
      for (int i = 0; i < 4; ++i) h2.push_back(0);
      varint(h2, 3);
      auto r2 = pm().decode(ctx, version, h2, DecodeLimits{1000, 2000});
      EXPECT_EQ(r2.status().code(), ErrorCode::kMalformed) << r2.status().toString();
    }
  // A version 5 payload (wedges) in a container without attributes: refused (no encoder writes one).
  {
    const AttributeLayout colors{0, 3};
    const QuantizedMesh colored = quantized(testing::coloredIcosphere(2), 12, colors);
    const Encoded v5 = encodeTile(TileContext{12, colors}, colored, {});
    ASSERT_EQ(v5.version, 5);
    EXPECT_EQ(pm().decode(ctx, 5, v5.tile.payload, limitsOf(v5.tile.decoded)).status().code(), ErrorCode::kMalformed);
  }
  // An unknown version.
  EXPECT_EQ(pm().decode(ctx, pm().version + 1, enc.tile.payload, limitsOf(s)).status().code(),
            ErrorCode::kUnknownVersion);
  // The payload admits the registry's floor.
  EXPECT_TRUE(pm().floor.admits(ctx.layout, s.vertices, s.faces, enc.tile.payload.size()));
}

}  // namespace
}  // namespace scanpress
