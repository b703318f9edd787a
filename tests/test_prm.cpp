// Codec `prm` (engine/codecs/prm.cpp): the lattice coder against independent truth (height fields built on a
// relief's lattice, where every face is regular by construction; plain edgebreaker on the same meshes, which must
// decode to the same triangles), the ugly meshes edgebreaker handles, remeshing and coding in one on analytic shapes
// (a sphere and a torus stay near their surfaces; the decoded mesh is the remesh stage's), locked tile borders,
// the error knob's floor, and hostile payloads.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <limits>
#include <functional>
#include <map>
#include <random>
#include <set>

#include "engine/codecs/codec.h"
#include "engine/geometry.h"
#include "engine/io/bytes.h"
#include "engine/quantize.h"
#include "engine/remesh/resample.h"
#include "engine/shapes.h"
#include "engine/stages/stage.h"
#include "test_util.h"

namespace scanpress {
namespace {

const CodecInfo& prm() { return *findCodec(CodecId::kPrm); }

// A height field on relief r's lattice of spacing G (the convention of engine/remesh/resample.h): lattice points
// (i, j), 0 <= i < n, 0 <= j < m, at base (i G + j G / 2, j H), height h(i, j); two triangles per lattice
// parallelogram, counterclockwise in the relief's base (reversed with `flip`).
QuantizedMesh latticeField(int relief, uint32_t G, int n, int m, const std::function<double(int, int)>& h,
                           bool flip = false) {
  const uint32_t H = HexLattice::withSpacing(G).row;
  const int a = relief / 2;
  const int axis0 = relief % 2 == 0 ? (a + 1) % 3 : (a + 2) % 3, axis1 = relief % 2 == 0 ? (a + 2) % 3 : (a + 1) % 3;
  QuantizedMesh q;
  for (int j = 0; j < m; ++j)
    for (int i = 0; i < n; ++i) {
      Vec3u p{};
      p[size_t(axis0)] = uint32_t(i) * G + uint32_t(j) * (G / 2);
      p[size_t(axis1)] = uint32_t(j) * H;
      p[size_t(a)] = uint32_t(std::lround(h(i, j)));
      // Independent of how the coder reads the base: resample.h's reliefBase gives the same two coordinates.
      const auto base = reliefBase({double(p[0]), double(p[1]), double(p[2])}, relief);
      EXPECT_EQ(base[0], double(uint32_t(i) * G + uint32_t(j) * (G / 2)));
      EXPECT_EQ(base[1], double(uint32_t(j) * H));
      q.positions.push_back(p);
    }
  const auto at = [&](int i, int j) { return uint32_t(j * n + i); };
  for (int j = 0; j + 1 < m; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      Triangle t1{at(i, j), at(i + 1, j), at(i, j + 1)}, t2{at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)};
      if (flip) std::swap(t1[1], t1[2]), std::swap(t2[1], t2[2]);
      q.triangles.push_back(t1);
      q.triangles.push_back(t2);
    }
  return q;
}

// Codes `q` on the lattice of spacing G and checks that it decodes to the same triangles (positions, orientation,
// multiplicity) as the input and as plain edgebreaker's decode.
CodecStats expectLatticeRoundTrip(const TileContext& ctx, const QuantizedMesh& q, uint32_t G) {
  std::vector<uint8_t> bytes;
  CodecStats stats;
  TileSummary summary;
  const Status st = edgebreakerEncodeOnLattice(ctx, q, G, bytes, &stats, &summary);
  EXPECT_TRUE(st.isOk()) << st.toString();
  if (!st.isOk()) return stats;
  auto d = edgebreakerDecodeOnLattice(ctx, bytes, limitsOf(summary), G);
  EXPECT_TRUE(d.isOk()) << d.status().toString();
  if (!d.isOk()) return stats;
  EXPECT_TRUE(testing::cornerMultiset(*d, ctx.layout.normal_bits) ==
              testing::cornerMultiset(q, ctx.layout.normal_bits));
  auto plain = encodeMesh(*findCodec(CodecId::kEdgebreaker), ctx, q);
  EXPECT_TRUE(plain.isOk());
  auto pd = findCodec(CodecId::kEdgebreaker)->decode(ctx, 2, plain->payload, limitsOf(plain->decoded));
  EXPECT_TRUE(pd.isOk());
  EXPECT_TRUE(d->positions == pd->positions && d->triangles == pd->triangles)
      << "prm's coder decodes the points in another order than edgebreaker's";
  return stats;
}

TEST(Prm, LatticeHeightFieldsAreRegularInEveryRelief) {
  const TileContext ctx{12, {}};
  for (int relief = 0; relief < 6; ++relief)
    for (uint32_t G : {8u, 20u})
      for (bool flip : {false, true}) {
        SCOPED_TRACE("relief " + std::to_string(relief) + " G " + std::to_string(G) + (flip ? " flipped" : ""));
        const QuantizedMesh q = latticeField(
            relief, G, 30, 24,
            [](int i, int j) {
          return 1500 + 0.9 * (i - 14) * (i - 14) - 0.5 * (j - 9) * (j - 11) + 40 * std::sin(0.3 * i);
            },
            flip);
        const CodecStats s = expectLatticeRoundTrip(ctx, q, G);
        EXPECT_EQ(s.regular_faces, q.triangles.size());
        // What the pictures show (render --color-by): every face regular, and in this relief where its normal is
        // nearer the relief's axis than the others (a steep face may be a unit triangle of another relief too, and is shown there).
        const auto pictured = latticeFaceReliefs(q, G);
        for (size_t f = 0; f < q.triangles.size(); ++f) {
          ASSERT_NE(pictured[f], -1);
          Vec3d p[3];
          for (int c = 0; c < 3; ++c)
            for (int k = 0; k < 3; ++k) p[c][size_t(k)] = q.positions[q.triangles[f][size_t(c)]][size_t(k)];
          const Vec3d n = vcross(vsub(p[1], p[0]), vsub(p[2], p[0]));
          const size_t axis = size_t(relief / 2);
          if (std::abs(n[axis]) > std::max(std::abs(n[(axis + 1) % 3]), std::abs(n[(axis + 2) % 3]))) {
            ASSERT_EQ(pictured[f], relief) << "face " << f;
          }
        }
        EXPECT_EQ(latticeFaceReliefs(q, G / 2), std::vector<int8_t>(q.triangles.size(), -1));
        EXPECT_EQ(s.patches, 1u);
        // The first point of the patch is coded in full and anchors it; every other point is a height only.
        EXPECT_EQ(s.lattice_points, q.positions.size() - 1);
        // On another lattice (half the spacing: the field's points are on it, its triangles are not unit ones)
        // no face is regular, and the mesh still round-trips.
        const CodecStats other = expectLatticeRoundTrip(ctx, q, G / 2);
        EXPECT_EQ(other.regular_faces, 0u);
      }
}

TEST(Prm, HeightsCostLessThanEdgebreakersThreeCoordinates) {
  // A smooth field with rounding noise: heights predicted from the lattice against edgebreaker's parallelograms.
  const TileContext ctx{12, {}};
  const QuantizedMesh q = latticeField(4, 24, 60, 60, [](int i, int j) {
    return 2000 + 600 * std::sin(0.07 * i) * std::cos(0.05 * j) + 0.004 * i * j * j;
  });
  std::vector<uint8_t> lattice, plain;
  CodecStats ls, ps;
  ASSERT_TRUE(edgebreakerEncodeOnLattice(ctx, q, 24, lattice, &ls, nullptr).isOk());
  ASSERT_TRUE(edgebreakerEncodeWithStats(ctx, q, plain, &ps).isOk());
  EXPECT_LT(ls.geometry_bits, 0.7 * ps.geometry_bits);
  EXPECT_LT(lattice.size(), plain.size());
}

TEST(Prm, PatchesThatShareAProjectionAndUglyMeshesRoundTrip) {
  const TileContext ctx{12, {}};
  const auto bump = [](int i, int j) { return 1000 + 3.0 * i + 2.0 * j + 0.2 * i * j; };
  // Two sheets of the same relief over the same base (one 900 cells above the other), one flipped, and a sheet
  // of another relief: three patches, keys of the same lattice coordinates in two of them.
  QuantizedMesh two = latticeField(4, 16, 12, 12, bump);
  const QuantizedMesh upper = latticeField(
      4, 16, 12, 12, [&](int i, int j) { return bump(i, j) + 900; }, true);
  const QuantizedMesh side = latticeField(1, 16, 10, 10, [](int i, int j) { return 3000 - i - j; });
  for (const QuantizedMesh* part : {&upper, &side}) {
    const uint32_t base = uint32_t(two.positions.size());
    two.positions.insert(two.positions.end(), part->positions.begin(), part->positions.end());
    for (Triangle t : part->triangles) two.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  }
  CodecStats s = expectLatticeRoundTrip(ctx, two, 16);
  EXPECT_EQ(s.patches, 3u);
  EXPECT_EQ(s.regular_faces, two.triangles.size());

  // What real data has, on top of a regular field: a fin (a third triangle on an edge), a duplicated and a
  // reversed face, a zero-area triangle, two corners at one position (a second vertex there), a stray vertex, and
  // a free-floating soup triangle.
  QuantizedMesh ugly = latticeField(0, 12, 14, 14, bump);
  const uint32_t n = uint32_t(ugly.positions.size());
  ugly.positions.push_back({4000, 4000, 4000});
  ugly.triangles.push_back({ugly.triangles[30][0], ugly.triangles[30][1], n});
  ugly.triangles.push_back(ugly.triangles[50]);
  ugly.triangles.push_back({ugly.triangles[60][0], ugly.triangles[60][2], ugly.triangles[60][1]});
  ugly.positions.push_back(ugly.positions[ugly.triangles[70][0]]);  // n + 1: coincident with a corner
  ugly.triangles.push_back({n + 1, ugly.triangles[70][1], ugly.triangles[71][2]});
  const Vec3u pa = ugly.positions[5], pb = ugly.positions[6];
  ugly.positions.push_back({(pa[0] + pb[0]) / 2, (pa[1] + pb[1]) / 2, (pa[2] + pb[2]) / 2});  // on edge 5-6
  ugly.triangles.push_back({5, 6, n + 2});                                                    // zero area (or nearly)
  ugly.positions.push_back({10, 20, 30});                                                     // stray
  ugly.positions.push_back({100, 4000, 50});
  ugly.positions.push_back({140, 4010, 60});
  ugly.positions.push_back({120, 3990, 90});
  ugly.triangles.push_back({n + 4, n + 5, n + 6});
  s = expectLatticeRoundTrip(ctx, ugly, 12);
  EXPECT_GT(s.regular_faces, 0u);

  // Attributes ride along as edgebreaker codes them.
  TileContext attr{12, {10, 4}};
  QuantizedMesh colored = latticeField(2, 20, 16, 16, bump);
  for (size_t v = 0; v < colored.positions.size(); ++v) {
    colored.normals.push_back({uint16_t(300 + v % 7), uint16_t(500 + v % 5)});
    colored.colors.push_back({uint8_t(v), uint8_t(2 * v), 200, 255});
  }
  expectLatticeRoundTrip(attr, colored, 20);
}

// `q` coded by prm with `options` and decoded (`decoded`), and the remesh stage's mesh of it at prm's spacing
// (`staged`, tau 0.2).
void prmAndRemeshStage(const TileContext& ctx, const QuantizedMesh& q, const CodecOptions& options,
                       QuantizedMesh& decoded, QuantizedMesh& staged) {
  auto enc = prm().encode(ctx, TileView{q, {}}, options);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  auto d = prm().decode(ctx, payloadVersion(prm(), *enc), enc->payload, limitsOf(enc->decoded));
  ASSERT_TRUE(d.isOk()) << d.status().toString();
  auto remeshed = remeshTile(ctx, TileView{q, {}}, 0.2, prmSpacing(options.prm, ctx.bits));
  ASSERT_TRUE(remeshed.isOk()) << remeshed.status().toString();
  decoded = *std::move(d);
  staged = std::move(remeshed->mesh);
}

// prmAndRemeshStage with a lattice of 0.03 of the grid (`options`), which remeshes `q` (asserted).
void prmAndRemeshStageAtFineLattice(const TileContext& ctx, const QuantizedMesh& q, CodecOptions& options,
                                    QuantizedMesh& decoded, QuantizedMesh& staged) {
  options.prm.grid = 0.03;
  ASSERT_NO_FATAL_FAILURE(prmAndRemeshStage(ctx, q, options, decoded, staged));
  ASSERT_FALSE(testing::triangleMultiset(staged) == testing::triangleMultiset(q)) << "not remeshed";
}

TEST(Prm, SphereAndTorusRemeshNearTheirSurfaces) {
  struct Shape {
    const char* name;
    Mesh mesh;
    // Distance of a point (in the mesh's own units) to the analytic surface.
    std::function<double(const Vec3d&)> distance;
  };
  const Shape shapes[] = {
      {"sphere", icosphere(5), [](const Vec3d& p) { return std::abs(vlen(p) - 1.0); }},
      {"torus", torus(160, 60, 1.0, 0.35),
       [](const Vec3d& p) { return std::abs(std::hypot(std::hypot(p[0], p[1]) - 1.0, p[2]) - 0.35); }},
  };
  for (const Shape& shape : shapes) {
    SCOPED_TRACE(shape.name);
    const Grid grid = *makeGrid(boundingBox(shape.mesh), 14);
    const QuantizedMesh q = *quantizeMesh(shape.mesh, grid, {}, nullptr);
    const TileContext ctx{14, {}};
    CodecOptions options;
    options.prm.grid = 0.025;  // 410 grid cells: about the size of the input's triangles
    QuantizedMesh d, staged;
    ASSERT_NO_FATAL_FAILURE(prmAndRemeshStage(ctx, q, options, d, staged));
    // The decoded mesh is the remesh stage's output at that spacing, exactly.
    EXPECT_TRUE(testing::triangleMultiset(d) == testing::triangleMultiset(staged));
    // Vertices on the surface within the lattice's sagitta plus rounding: a chord of length g (the lattice
    // spacing, slanted up to 1 / tau = 5 times longer in space) is within (5 g)^2 / (8 R) of a surface of
    // curvature radius R; the smallest here is the torus tube's 0.35.
    const double g = prmSpacing(options.prm, 14) * grid.cell, r_min = std::string(shape.name) == "torus" ? 0.35 : 1.0;
    const double bound = (5 * g) * (5 * g) / (8 * r_min) + 2 * grid.cell;
    double worst = 0;
    for (const Vec3u& p : d.positions) worst = std::max(worst, shape.distance(grid.dequantize(p)));
    EXPECT_LT(worst, bound);
    // Most of the remeshed faces are coded as regular.
    std::vector<uint8_t> bytes;
    CodecStats s;
    ASSERT_TRUE(prmEncodeWithStats(ctx, TileView{q, {}}, options, bytes, &s, nullptr).isOk());
    EXPECT_GT(double(s.regular_faces), 0.6 * double(s.triangles));
    // The pictures' classification of the decoded faces is the coder's.
    const auto relief = latticeFaceReliefs(d, prmSpacing(options.prm, 14));
    EXPECT_EQ(uint64_t(std::count_if(relief.begin(), relief.end(), [](int8_t r) { return r >= 0; })), s.regular_faces);
  }
}

// A remeshed sphere with the scan's normals and colors: prm decodes the remesh stage's mesh with its interpolated
// attributes, exactly.
TEST(Prm, RemeshedAttributesDecodeExactly) {
  const AttributeLayout layout{10, 3};
  const QuantizedMesh q = testing::quantized(testing::coloredIcosphere(4), 14, layout);
  const TileContext ctx{14, layout};
  CodecOptions options;
  QuantizedMesh d, staged;
  ASSERT_NO_FATAL_FAILURE(prmAndRemeshStageAtFineLattice(ctx, q, options, d, staged));
  ASSERT_EQ(staged.normals.size(), staged.positions.size());
  ASSERT_EQ(staged.colors.size(), staged.positions.size());
  EXPECT_TRUE(testing::cornerMultiset(d, layout.normal_bits) == testing::cornerMultiset(staged, layout.normal_bits));
}

// Scalar channels (v2, issue 22 part 4): the remesh stage resamples them and prm's coder codes the result exactly.
// A kept input vertex keeps its row; an added one, lying on an input triangle, takes float channels interpolated
// from its corners (a linear field stays near its value at the vertex; the float64 channel shows values no input
// vertex has) and integer and quantized channels (texture coordinates) from one corner (a value an input vertex
// has). A non-finite corner value is never mixed (no NaN). A version 1 payload in this layout is refused.
TEST(Prm, ScalarChannelsAreResampledAndDecodeExactly) {
  AttributeLayout layout{10, 3};
  layout.scalars = {{"field", ScalarType::kFloat32},
                    {"time", ScalarType::kFloat64},
                    {"label", ScalarType::kUint16},
                    {"u", ScalarType::kFloat32, 12},
                    {"v", ScalarType::kFloat32, 12}};
  const size_t stride = size_t(layout.scalarStride());
  QuantizedMesh q = testing::quantized(testing::coloredIcosphere(4), 14, AttributeLayout{10, 3});
  const auto field = [](const Vec3u& p) { return 1e-3 * (double(p[0]) + 2.0 * p[1] - 0.5 * p[2]); };
  std::map<uint32_t, std::set<std::vector<uint32_t>>> input_values;  // word -> the input's values there
  q.scalars.clear();
  for (size_t v = 0; v < q.positions.size(); ++v) {
    const Vec3u& p = q.positions[v];
    const float f = v == 7 ? std::numeric_limits<float>::infinity() : float(field(p));
    const double t = 1e9 + double(p[2]) * 0.25;
    const uint64_t tb = std::bit_cast<uint64_t>(t);
    const float u = float(std::round(double(p[0]) / 16384 * 4096) / 4096),
                w = float(std::round(double(p[1]) / 16384 * 4096) / 4096);
    q.scalars.insert(q.scalars.end(), {std::bit_cast<uint32_t>(f), uint32_t(tb), uint32_t(tb >> 32),
                                       uint32_t(v % 5000), std::bit_cast<uint32_t>(u), std::bit_cast<uint32_t>(w)});
  }
  const auto word = [&](const QuantizedMesh& m, size_t v, size_t w) { return m.scalars[v * stride + w]; };
  for (size_t v = 0; v < q.positions.size(); ++v)
    for (size_t w : {3, 4, 5}) input_values[uint32_t(w)].insert({word(q, v, w)});
  std::set<std::vector<uint32_t>> input_times;
  for (size_t v = 0; v < q.positions.size(); ++v) input_times.insert({word(q, v, 1), word(q, v, 2)});
  std::map<Vec3u, std::vector<uint32_t>> input_rows;
  for (size_t v = 0; v < q.positions.size(); ++v)
    input_rows.emplace(q.positions[v], std::vector<uint32_t>(q.scalars.begin() + ptrdiff_t(v * stride),
                                                             q.scalars.begin() + ptrdiff_t((v + 1) * stride)));
  const TileContext ctx{14, layout};
  CodecOptions options;
  QuantizedMesh d, staged;
  ASSERT_NO_FATAL_FAILURE(prmAndRemeshStageAtFineLattice(ctx, q, options, d, staged));
  ASSERT_EQ(staged.scalars.size(), staged.positions.size() * stride);
  // prm codes the stage's mesh exactly: the same (position, row) pairs.
  ASSERT_EQ(d.scalars.size(), d.positions.size() * stride);
  const auto pairs = [&](const QuantizedMesh& m) {
    std::vector<std::pair<Vec3u, std::vector<uint32_t>>> out;
    for (size_t v = 0; v < m.positions.size(); ++v)
      out.push_back({m.positions[v], std::vector<uint32_t>(m.scalars.begin() + ptrdiff_t(v * stride),
                                                           m.scalars.begin() + ptrdiff_t((v + 1) * stride))});
    std::sort(out.begin(), out.end());
    return out;
  };
  // prm keeps the smaller of the two codings (here the tile as it is: its 800 added vertices' interpolated values
  // cost more than remeshing saves); the remeshed one, coded on the lattice, decodes exactly too.
  EXPECT_TRUE(pairs(d) == pairs(staged) || pairs(d) == pairs(q));
  {
    const uint32_t spacing = prmSpacing(options.prm, 14);
    std::vector<uint8_t> payload;
    ByteWriter(payload).varint(spacing);
    TileSummary summary;
    ASSERT_TRUE(edgebreakerEncodeOnLattice(ctx, staged, spacing, payload, nullptr, &summary).isOk());
    auto back = prm().decode(ctx, 2, payload, limitsOf(summary));
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_TRUE(pairs(*back) == pairs(staged));
  }
  std::set<uint32_t> input_fields;
  for (size_t v = 0; v < q.positions.size(); ++v) input_fields.insert(word(q, v, 0));
  size_t added = 0, new_times = 0, new_fields = 0;
  for (size_t v = 0; v < staged.positions.size(); ++v) {
    const std::vector<uint32_t> row(staged.scalars.begin() + ptrdiff_t(v * stride),
                                    staged.scalars.begin() + ptrdiff_t((v + 1) * stride));
    const float f = std::bit_cast<float>(row[0]);
    EXPECT_FALSE(std::isnan(f)) << v;
    for (size_t w : {3, 4, 5})
      EXPECT_TRUE(input_values[uint32_t(w)].count({row[w]})) << "vertex " << v << " word " << w;
    const auto kept = input_rows.find(staged.positions[v]);
    if (kept != input_rows.end() && kept->second == row) continue;  // a kept input vertex (or one at its point)
    ++added;
    new_times += !input_times.count({row[1], row[2]});
    new_fields += !input_fields.count(row[0]);
    // Interpolated from the corners of the input triangle under it: within a few lattice steps' change of the field
    // (the vertex moved by rounding, and lies on the relief, not on the triangle), unless a corner was infinite.
    if (std::isfinite(f)) {
      EXPECT_NEAR(f, field(staged.positions[v]), 1e-3 * 3.5 * 4 * double(prmSpacing(options.prm, 14))) << v;
    }
  }
  EXPECT_GT(added, 100u);
  EXPECT_GT(new_times, added / 2) << "float64 values are interpolated, not copied";
  EXPECT_GT(new_fields, added / 2) << "float32 values are interpolated, not copied";
  // Version 1 payloads carry no scalar channels: refused in this layout.
  auto enc = prm().encode(ctx, TileView{q, {}}, options);
  ASSERT_TRUE(enc.isOk());
  EXPECT_EQ(payloadVersion(prm(), *enc), 2);
  EXPECT_EQ(prm().decode(ctx, 1, enc->payload, limitsOf(enc->decoded)).status().code(), ErrorCode::kMalformed);
  QuantizedMesh bare = q;
  bare.scalars.clear();
  auto without = prm().encode(TileContext{14, {10, 3}}, TileView{bare, {}}, options);
  ASSERT_TRUE(without.isOk()) << without.status().toString();
  EXPECT_EQ(payloadVersion(prm(), *without), 1);
}

TEST(Prm, LockedBorderIsKept) {
  const TileContext ctx{14, {}};
  const Mesh sphere = icosphere(4);
  const testing::LockedCap cap =
      testing::lockedCap(*quantizeMesh(sphere, *makeGrid(boundingBox(sphere), 14), {}, nullptr), 14, 100);
  CodecOptions options;
  options.prm.spacing = 300;
  auto enc = prm().encode(ctx, TileView{cap.mesh, cap.locked}, options);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  auto d = prm().decode(ctx, payloadVersion(prm(), *enc), enc->payload, limitsOf(enc->decoded));
  ASSERT_TRUE(d.isOk()) << d.status().toString();
  const std::set<Vec3u> decoded(d->positions.begin(), d->positions.end());
  std::map<std::pair<Vec3u, Vec3u>, int> edges;
  for (const Triangle& t : d->triangles)
    for (int k = 0; k < 3; ++k) ++edges[std::minmax(d->positions[t[size_t(k)]], d->positions[t[size_t((k + 1) % 3)]])];
  for (uint32_t v = 0; v < cap.locked.size(); ++v)
    if (cap.locked[v]) {
      EXPECT_TRUE(decoded.count(cap.mesh.positions[v]));
    }
  // Every rim edge is still a boundary edge (one triangle), and there is no other boundary.
  ASSERT_GT(cap.rim.size(), 10u);
  for (const auto& [a, b] : cap.rim) {
    const auto it = edges.find(std::minmax(cap.mesh.positions[a], cap.mesh.positions[b]));
    ASSERT_TRUE(it != edges.end());
    EXPECT_EQ(it->second, 1);
  }
  size_t boundary = 0;
  for (const auto& [e, n] : edges) boundary += n == 1;
  EXPECT_EQ(boundary, cap.rim.size());
}

// The knob's floor and lattices too fine for the remesher keep the tile as it is.
TEST(Prm, KnobFloorTooFineLatticesAndTheSmallerCodingKeepTheTile) {
  const TileContext ctx{12, {}};
  const QuantizedMesh q = *quantizeMesh(icosphere(2), *makeGrid(boundingBox(icosphere(2)), 12), {}, nullptr);
  for (double spacing : {0.0, 2.0}) {
    SCOPED_TRACE(spacing);
    CodecOptions options;
    options.prm.spacing = spacing;  // 0: the knob's floor; 2 cells: 64 and more pieces per triangle
    auto enc = prm().encode(ctx, TileView{q, {}}, options);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    auto d = prm().decode(ctx, payloadVersion(prm(), *enc), enc->payload, limitsOf(enc->decoded));
    ASSERT_TRUE(d.isOk());
    EXPECT_TRUE(testing::triangleMultiset(*d) == testing::triangleMultiset(q));
  }
  // Otherwise the smaller of the two codings, the tile as it is and the remesh stage's output, whichever that is:
  // a coarse icosphere on lattices from finer than its triangles (remeshing is larger) to coarser.
  const QuantizedMesh coarse = *quantizeMesh(icosphere(3), *makeGrid(boundingBox(icosphere(3)), 12), {}, nullptr);
  std::set<bool> chosen;
  bool more_than_doubled_and_kept = false;  // the case a rule on triangle counts would miss
  for (double spacing : {64.0, 160.0, 180.0, 400.0}) {
    SCOPED_TRACE(spacing);
    CodecOptions options;
    options.prm.spacing = spacing;
    auto enc = prm().encode(ctx, TileView{coarse, {}}, options);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    auto d = prm().decode(ctx, payloadVersion(prm(), *enc), enc->payload, limitsOf(enc->decoded));
    ASSERT_TRUE(d.isOk());
    auto staged = remeshTile(ctx, TileView{coarse, {}}, options.prm.tau, uint32_t(spacing));
    ASSERT_TRUE(staged.isOk());
    std::vector<uint8_t> as_is, remeshed;
    TileSummary unused;
    ASSERT_TRUE(edgebreakerEncodeOnLattice(ctx, coarse, uint32_t(spacing), as_is, nullptr, &unused).isOk());
    ASSERT_TRUE(edgebreakerEncodeOnLattice(ctx, staged->mesh, uint32_t(spacing), remeshed, nullptr, &unused).isOk());
    const bool remesh_smaller = remeshed.size() < as_is.size();
    chosen.insert(remesh_smaller);
    more_than_doubled_and_kept |= remesh_smaller && staged->mesh.triangles.size() > 2 * coarse.triangles.size();
    EXPECT_EQ(enc->payload.size(), std::min(as_is.size(), remeshed.size()) + (spacing < 128 ? 1 : 2));
    EXPECT_TRUE(testing::triangleMultiset(*d) == testing::triangleMultiset(remesh_smaller ? staged->mesh : coarse));
  }
  EXPECT_EQ(chosen.size(), 2u) << "the lattices should give both choices";
  EXPECT_TRUE(more_than_doubled_and_kept) << "spacing 180: more than twice the triangles, and fewer bytes";
  CodecOptions bad;
  bad.prm.tau = 0.9;
  EXPECT_EQ(prm().encode(ctx, TileView{q, {}}, bad).status().code(), ErrorCode::kInvalidArgument);
  bad = CodecOptions{};
  bad.prm.spacing = NAN;
  EXPECT_EQ(prm().encode(ctx, TileView{q, {}}, bad).status().code(), ErrorCode::kInvalidArgument);
}

TEST(Prm, HostilePayloadsFailCleanly) {
  const TileContext ctx{12, {10, 3}};
  // A payload with patches, irregular faces and a boundary, with normals and colors.
  QuantizedMesh q = latticeField(4, 12, 16, 16, [](int i, int j) { return 900 + 2.0 * i * j; });
  q.triangles.erase(q.triangles.begin() + 100, q.triangles.begin() + 110);
  q.positions.push_back({2000, 2000, 3000});
  q.triangles.push_back({0, 1, uint32_t(q.positions.size() - 1)});
  for (size_t v = 0; v < q.positions.size(); ++v) {
    q.normals.push_back({uint16_t(500 + v % 9), uint16_t(480 + v / 40)});
    q.colors.push_back({uint8_t(v), uint8_t(100 + v % 7), uint8_t(v / 3), 255});
  }
  CodecOptions options;
  options.prm.spacing = 0;  // as it is: a patch of the lattice of spacing 12, coded with it
  std::vector<uint8_t> payload;
  {
    ByteWriter w(payload);
    w.varint(12);
  }
  TileSummary summary;
  ASSERT_TRUE(edgebreakerEncodeOnLattice(ctx, q, 12, payload, nullptr, &summary).isOk());
  const DecodeLimits lim = limitsOf(summary);
  auto good = prm().decode(ctx, 1, payload, lim);
  ASSERT_TRUE(good.isOk()) << good.status().toString();
  EXPECT_TRUE(testing::cornerMultiset(*good, 10) == testing::cornerMultiset(q, 10));
  // Every truncation fails.
  for (size_t n = 0; n < payload.size(); n += testing::sampleStride())
    EXPECT_FALSE(prm().decode(ctx, 1, std::span(payload).first(n), lim).isOk()) << n;
  // Corruptions: an error or a valid mesh within the limits.
  std::mt19937 rng(21);
  for (int trial = 0; trial < testing::sampled(3000); ++trial) {
    auto bytes = payload;
    const int edits = 1 + int(rng() % 4);
    for (int e = 0; e < edits; ++e) bytes[1 + rng() % (bytes.size() - 1)] ^= uint8_t(1 + rng() % 255);
    auto d = prm().decode(ctx, 1, bytes, lim);
    if (d.isOk()) {
      EXPECT_TRUE(validateTile(ctx, *d).isOk());
      EXPECT_LE(d->positions.size(), lim.vertices);
      EXPECT_LE(d->triangles.size(), lim.faces);
    }
  }
  // The lattice spacing: odd, too small, too large; an unknown version.
  for (uint64_t bad :
       {uint64_t(0), uint64_t(1), uint64_t(3), uint64_t(13), uint64_t(kMaxLatticeSpacing) + 2, uint64_t(1) << 40}) {
    std::vector<uint8_t> bytes;
    ByteWriter w(bytes);
    w.varint(bad);
    bytes.insert(bytes.end(), payload.begin() + 1, payload.end());
    EXPECT_EQ(prm().decode(ctx, 1, bytes, lim).status().code(), ErrorCode::kMalformed) << bad;
  }
  EXPECT_EQ(prm().decode(ctx, 3, payload, lim).status().code(), ErrorCode::kUnknownVersion);
  // Another valid spacing decodes the same stream differently or fails, never past the limits.
  std::vector<uint8_t> other = payload;
  other[0] = 14;
  auto d = prm().decode(ctx, 1, other, lim);
  if (d.isOk()) {
    EXPECT_TRUE(validateTile(ctx, *d).isOk());
  }
}

}  // namespace
}  // namespace scanpress
