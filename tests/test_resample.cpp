// Relief resampling (engine/remesh/resample.h), PRM section 2.2, against analytic height fields: the resampled
// relief covers exactly the input's projection (no flip, no gap, no overlap added), keeps its boundary and the
// caller's fixed vertices, leaves no removable vertex inside, every triangle off the boundary projects onto a grid
// triangle, and every grid vertex lies on the input surface. Also a spiral ramp whose projection overlaps itself,
// vertices exactly on grid lines and grid points, zero-area triangles, and bad arguments.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <map>
#include <random>
#include <set>

#include "engine/geometry.h"
#include "engine/remesh/relief.h"
#include "engine/remesh/resample.h"

namespace scanpress {
namespace {

struct Patch {
  std::vector<Vec3d> positions;
  std::vector<Triangle> triangles;
};

// A (cells x cells) grid over [x0, x0 + size]^2 in relief r's base plane with height h(x, y), cells split along
// alternating diagonals, counterclockwise in the base plane; `jitter` moves interior points by up to that share of
// a cell (then heights are taken at the moved points).
template <typename Height>
Patch heightField(int relief, int cells, double x0, double size, Height h, double jitter = 0, uint32_t seed = 1) {
  Patch p;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-jitter, jitter);
  const double step = size / cells;
  for (int j = 0; j <= cells; ++j)
    for (int i = 0; i <= cells; ++i) {
      double x = x0 + i * step, y = x0 + j * step;
      if (i > 0 && j > 0 && i < cells && j < cells) {
        x += u(rng) * step;
        y += u(rng) * step;
      }
      // Base (x, y) and height back to 3D: the inverse of reliefBase / reliefHeight.
      const int a = relief / 2;
      Vec3d q{};
      const double b0 = relief % 2 == 0 ? x : y, b1 = relief % 2 == 0 ? y : x;
      q[size_t((a + 1) % 3)] = b0;
      q[size_t((a + 2) % 3)] = b1;
      q[size_t(a)] = (relief % 2 == 0 ? 1 : -1) * h(x, y);
      p.positions.push_back(q);
    }
  const auto at = [&](int i, int j) { return uint32_t(j * (cells + 1) + i); };
  for (int j = 0; j < cells; ++j)
    for (int i = 0; i < cells; ++i) {
      if ((i + j) % 2 == 0) {
        p.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
        p.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
      } else {
        p.triangles.push_back({at(i, j), at(i + 1, j), at(i, j + 1)});
        p.triangles.push_back({at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)});
      }
    }
  return p;
}

double projectedArea(const std::vector<Vec3d>& p, const std::vector<Triangle>& triangles, int relief) {
  double sum = 0;
  for (const Triangle& t : triangles) {
    const auto a = reliefBase(p[t[0]], relief), b = reliefBase(p[t[1]], relief), c = reliefBase(p[t[2]], relief);
    sum += 0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]));
  }
  return sum;
}

// The checks every resampled relief must pass.
void expectValid(const Patch& in, const ResampledRelief& r, int relief, const HexLattice& lattice,
                 const std::vector<uint8_t>& fixed = {}, size_t* irregular_inside = nullptr) {
  ASSERT_EQ(r.regular.size(), r.triangles.size());
  ASSERT_EQ(r.kind.size(), r.positions.size());
  ASSERT_EQ(r.input_vertex.size(), r.positions.size());
  // Input vertices keep their positions; `kept` says which are still there.
  std::vector<uint8_t> kept(in.positions.size(), 0);
  for (size_t v = 0; v < r.positions.size(); ++v)
    if (r.input_vertex[v] != UINT32_MAX) {
      ASSERT_LT(r.input_vertex[v], in.positions.size());
      EXPECT_EQ(r.positions[v], in.positions[r.input_vertex[v]]);
      EXPECT_FALSE(kept[r.input_vertex[v]]) << "input vertex " << r.input_vertex[v] << " twice";
      kept[r.input_vertex[v]] = 1;
    }
  const double in_area = projectedArea(in.positions, in.triangles, relief);
  EXPECT_NEAR(projectedArea(r.positions, r.triangles, relief), in_area, 1e-9 * in_area);
  std::vector<uint8_t> used(r.positions.size(), 0);
  for (size_t i = 0; i < r.triangles.size(); ++i) {
    const Triangle& t = r.triangles[i];
    const auto a = reliefBase(r.positions[t[0]], relief), b = reliefBase(r.positions[t[1]], relief),
               c = reliefBase(r.positions[t[2]], relief);
    EXPECT_GT((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]), 0) << "triangle " << i << " flipped";
    bool on_boundary = false;
    for (uint32_t v : t) {
      used[v] = 1;
      on_boundary = on_boundary || (r.kind[v] & kFixedVertex);
    }
    if (!on_boundary && irregular_inside) {
      *irregular_inside += !r.regular[i];
    } else if (!on_boundary) {
      EXPECT_TRUE(r.regular[i]) << "interior triangle " << i << " is not a grid triangle";
    }
    if (r.regular[i])  // its corners are grid points of one cell, at the integer base coordinates of the lattice
      for (uint32_t v : t) {
        const auto ij = r.lattice_ij[v];
        const auto base = reliefBase(r.positions[v], relief);
        EXPECT_NEAR(base[0], ij[0] * double(lattice.spacing) + ij[1] * double(lattice.spacing / 2), 1e-6);
        EXPECT_NEAR(base[1], ij[1] * double(lattice.row), 1e-6);
      }
  }
  for (size_t v = 0; v < r.positions.size(); ++v) {
    EXPECT_TRUE(used[v]) << "vertex " << v << " unused";
    EXPECT_TRUE((r.kind[v] & kFixedVertex) || (r.kind[v] & 3) == kLatticeVertex)
        << "removable vertex " << v << " left inside";
  }
  for (size_t v = 0; v < fixed.size(); ++v)
    if (fixed[v]) {
      EXPECT_TRUE(kept[v]) << "fixed vertex " << v << " removed";
    }
  // The input's boundary vertices are all still there.
  std::map<std::pair<uint32_t, uint32_t>, int> edges;
  for (const Triangle& t : in.triangles)
    for (int k = 0; k < 3; ++k) ++edges[std::minmax(t[size_t(k)], t[size_t((k + 1) % 3)])];
  for (const auto& [e, n] : edges)
    if (n == 1) {
      EXPECT_TRUE(kept[e.first]);
      EXPECT_TRUE(kept[e.second]);
    }
}

TEST(Resample, PlaneBecomesGridTrianglesInsideItsUnchangedBoundary) {
  for (int relief = 0; relief < kReliefCount; ++relief) {
    SCOPED_TRACE("relief " + std::to_string(relief));
    const Patch in = heightField(
        relief, 24, 100, 1000, [](double x, double y) { return 0.3 * x - 0.2 * y + 500; }, 0.3);
    const HexLattice lattice = HexLattice::withSpacing(40);
    auto r = resampleRelief(in.positions, in.triangles, relief, lattice, {});
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    expectValid(in, *r, relief, lattice);
    // Grid vertices lie on the plane.
    size_t regular = 0;
    for (size_t v = 0; v < r->positions.size(); ++v)
      if ((r->kind[v] & 3) == kLatticeVertex) {
        const auto b = reliefBase(r->positions[v], relief);
        EXPECT_NEAR(reliefHeight(r->positions[v], relief), 0.3 * b[0] - 0.2 * b[1] + 500, 1e-6);
      }
    for (uint8_t g : r->regular) regular += g;
    // Cells wholly inside the square: its area less a band of about two cells along the rim.
    const double cell = 0.5 * lattice.spacing * lattice.row;
    EXPECT_GT(double(regular), (1000.0 - 4 * lattice.spacing) * (1000.0 - 4 * lattice.spacing) / cell);
  }
}

TEST(Resample, CurvedCapKeepsItsGridVerticesOnTheInputSurface) {
  const double R = 2000;
  const auto cap = [&](double x, double y) {
    return std::sqrt(R * R - (x - 1000) * (x - 1000) - (y - 1000) * (y - 1000));
  };
  const int cells = 32;
  const Patch in = heightField(4, cells, 400, 1200, cap);  // no jitter: the input's height is found by its cell
  const HexLattice lattice = HexLattice::withSpacing(30);
  auto r = resampleRelief(in.positions, in.triangles, 4, lattice, {});
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  expectValid(in, *r, 4, lattice);
  const double step = 1200.0 / cells;
  size_t checked = 0;
  for (size_t v = 0; v < r->positions.size(); ++v) {
    if ((r->kind[v] & 3) != kLatticeVertex) continue;
    const Vec3d& p = r->positions[v];
    // The input's piecewise linear height at (x, y): the triangle of its cell that holds the point.
    const int i = std::min(cells - 1, int((p[0] - 400) / step)), j = std::min(cells - 1, int((p[1] - 400) / step));
    const double fx = (p[0] - 400) / step - i, fy = (p[1] - 400) / step - j;
    const auto h = [&](int a, int b) { return cap(400 + a * step, 400 + b * step); };
    double z;
    if ((i + j) % 2 == 0)
      z = fx >= fy ? h(i, j) + fx * (h(i + 1, j) - h(i, j)) + fy * (h(i + 1, j + 1) - h(i + 1, j))
                   : h(i, j) + fy * (h(i, j + 1) - h(i, j)) + fx * (h(i + 1, j + 1) - h(i, j + 1));
    else
      z = fx + fy <= 1 ? h(i, j) + fx * (h(i + 1, j) - h(i, j)) + fy * (h(i, j + 1) - h(i, j))
                       : h(i + 1, j + 1) + (1 - fx) * (h(i, j + 1) - h(i + 1, j + 1)) +
                             (1 - fy) * (h(i + 1, j) - h(i + 1, j + 1));
    EXPECT_NEAR(p[2], z, 1e-6) << "grid vertex " << v;
    ++checked;
  }
  EXPECT_GT(checked, 1000u);
}

// A spiral ramp z = c * theta over an annulus, one and a half turns: its projection covers half the annulus twice.
// Each layer gets its own grid vertices, on the ramp.
TEST(Resample, SelfOverlappingSpiralRampResamplesEachLayer) {
  const double c = 120, r0 = 300, r1 = 900;
  const int nr = 12, nt = 180;
  Patch in;
  for (int k = 0; k <= nt; ++k)
    for (int i = 0; i <= nr; ++i) {
      const double th = 3 * std::numbers::pi * k / nt, rad = r0 + (r1 - r0) * i / nr;
      in.positions.push_back({2000 + rad * std::cos(th), 2000 + rad * std::sin(th), 500 + c * th});
    }
  const auto at = [&](int k, int i) { return uint32_t(k * (nr + 1) + i); };
  for (int k = 0; k < nt; ++k)
    for (int i = 0; i < nr; ++i) {
      in.triangles.push_back({at(k, i), at(k, i + 1), at(k + 1, i + 1)});
      in.triangles.push_back({at(k, i), at(k + 1, i + 1), at(k + 1, i)});
    }
  const HexLattice lattice = HexLattice::withSpacing(24);
  auto r = resampleRelief(in.positions, in.triangles, 4, lattice, {});
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  expectValid(in, *r, 4, lattice);
  size_t lower = 0, upper = 0;
  for (size_t v = 0; v < r->positions.size(); ++v) {
    if ((r->kind[v] & 3) != kLatticeVertex) continue;
    const Vec3d& p = r->positions[v];
    double th = std::atan2(p[1] - 2000, p[0] - 2000);
    if (th < 0) th += 2 * std::numbers::pi;
    // On the ramp: its height is c times one of the angles of its direction (chords sag by under 1 unit).
    const double turns = (p[2] - 500) / c - th;
    const double k = std::round(turns / (2 * std::numbers::pi));
    EXPECT_NEAR(p[2], 500 + c * (th + 2 * std::numbers::pi * k), 2.0) << "grid vertex " << v;
    (k == 0 ? lower : upper) += 1;
  }
  EXPECT_GT(lower, 500u);
  EXPECT_GT(upper, 200u);
}

TEST(Resample, FixedVerticesStayAndVerticesOnGridLinesAndPointsAreHandled) {
  // Corners on the integer grid with the lattice's spacing: many input vertices lie exactly on grid lines or are
  // grid points. A few interior vertices are fixed by the caller.
  const HexLattice lattice = HexLattice::withSpacing(20);
  Patch in = heightField(4, 20, 0, 20.0 * 20, [](double x, double y) { return std::floor(0.1 * x + 0.05 * y); });
  std::vector<uint8_t> fixed(in.positions.size(), 0);
  fixed[5 * 21 + 5] = fixed[10 * 21 + 13] = fixed[15 * 21 + 7] = 1;
  auto r = resampleRelief(in.positions, in.triangles, 4, lattice, fixed);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  expectValid(in, *r, 4, lattice, fixed);
  // A zero-area triangle (a fin on three collinear points) does not stop the rest, and the projected area stays.
  Patch fin = heightField(
      4, 10, 0, 400, [](double x, double) { return 0.2 * x; }, 0.2, 5);
  const uint32_t a = fin.triangles[40][0], b = fin.triangles[40][1];
  fin.positions.push_back(vmul(vadd(fin.positions[a], fin.positions[b]), 0.5));
  fin.triangles.push_back({a, b, uint32_t(fin.positions.size() - 1)});
  r = resampleRelief(fin.positions, fin.triangles, 4, lattice, {});
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_NEAR(projectedArea(r->positions, r->triangles, 4), projectedArea(fin.positions, fin.triangles, 4), 1e-6);
}

// The direct fill of cells inside good triangles (ResampleMethod::kDirect, the default) against slicing and
// collapsing every triangle (kSliceAll, the paper's way), a second implementation: the same regular triangles by
// their lattice corners and the same triangle count on a wavy jittered plane, a cap, the self-overlapping spiral
// ramp and a patch with fixed vertices and vertices on grid lines; and the direct result passes expectValid.
std::vector<std::array<int32_t, 6>> regularCellsOf(const ResampledRelief& r) {
  std::vector<std::array<int32_t, 6>> cells;
  for (size_t t = 0; t < r.triangles.size(); ++t) {
    if (!r.regular[t]) continue;
    std::array<std::array<int32_t, 2>, 3> c{r.lattice_ij[r.triangles[t][0]], r.lattice_ij[r.triangles[t][1]],
                                            r.lattice_ij[r.triangles[t][2]]};
    std::sort(c.begin(), c.end());
    cells.push_back({c[0][0], c[0][1], c[1][0], c[1][1], c[2][0], c[2][1]});
  }
  std::sort(cells.begin(), cells.end());
  return cells;
}

TEST(Resample, DirectFillMatchesSlicingEveryTriangle) {
  struct Case {
    const char* name;
    int relief;
    Patch in;
    HexLattice lattice;
    std::vector<uint8_t> fixed;
    bool valid = true;  // expectValid applies (no triangle that repeats a vertex)
  };
  std::vector<Case> cases;
  cases.push_back({"wavy plane",
                   4,
                   heightField(
                       4, 24, 100, 1000,
                       [](double x, double y) { return 0.3 * x - 0.2 * y + 500 + 30 * std::sin(x / 90); }, 0.3),
                   HexLattice::withSpacing(40),
                   {}});
  cases.push_back(
      {"cap",
       1,
       heightField(1, 32, 400, 1200,
                   [](double x,
                      double y) { return std::sqrt(4e6 - (x - 1000) * (x - 1000) - (y - 1000) * (y - 1000)); }),
       HexLattice::withSpacing(30),
       {}});
  {
    Patch spiral;
    const int nr = 12, nt = 180;
    for (int k = 0; k <= nt; ++k)
      for (int i = 0; i <= nr; ++i) {
        const double th = 3 * std::numbers::pi * k / nt, rad = 300 + 600.0 * i / nr;
        spiral.positions.push_back({2000 + rad * std::cos(th), 2000 + rad * std::sin(th), 500 + 120 * th});
      }
    const auto at = [&](int k, int i) { return uint32_t(k * (nr + 1) + i); };
    for (int k = 0; k < nt; ++k)
      for (int i = 0; i < nr; ++i) {
        spiral.triangles.push_back({at(k, i), at(k, i + 1), at(k + 1, i + 1)});
        spiral.triangles.push_back({at(k, i), at(k + 1, i + 1), at(k + 1, i)});
      }
    cases.push_back({"spiral ramp", 4, spiral, HexLattice::withSpacing(24), {}});
  }
  {
    Patch steps = heightField(4, 20, 0, 20.0 * 20, [](double x, double y) { return std::floor(0.1 * x + 0.05 * y); });
    std::vector<uint8_t> fixed(steps.positions.size(), 0);
    fixed[5 * 21 + 5] = fixed[10 * 21 + 13] = fixed[15 * 21 + 7] = 1;
    cases.push_back({"grid-aligned steps, fixed vertices", 4, steps, HexLattice::withSpacing(20), fixed});
  }
  {
    // A second layer over a plane, its vertices fixed: its triangles are sliced, and its grid vertices at the corners
    // of cells of the plane below make the direct fill give up for the whole relief.
    Patch two = heightField(
        4, 24, 100, 1000, [](double x, double) { return 0.1 * x; }, 0.3);
    const Patch top = heightField(4, 4, 400, 200, [](double x, double) { return 0.1 * x + 300; });
    const uint32_t offset = uint32_t(two.positions.size());
    two.positions.insert(two.positions.end(), top.positions.begin(), top.positions.end());
    for (Triangle t : top.triangles) two.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
    std::vector<uint8_t> fixed(two.positions.size(), 0);
    std::fill(fixed.begin() + offset, fixed.end(), 1);
    cases.push_back({"a fixed layer over a plane", 4, two, HexLattice::withSpacing(40), fixed});
  }
  {
    // A plane plus a triangle that repeats a vertex, its corners on lattice points far above the plane: kept as it
    // is, and no grid triangle of the plane may take its corners (review of the direct fill).
    Patch spike;
    const int n = 10;
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) spike.positions.push_back({i * 20.0 + 0.37, j * 20.0 + 0.21, 0.1 * i * 20.0});
    const auto at = [&](int i, int j) { return uint32_t(j * (n + 1) + i); };
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        spike.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
        spike.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
      }
    const uint32_t v = uint32_t(spike.positions.size());
    spike.positions.push_back({130, 90, 999});  // lattice points (8, 10) and (9, 10) at spacing 10
    spike.positions.push_back({140, 90, 999});
    spike.triangles.push_back({v, v, v + 1});
    cases.push_back({"a triangle repeating a vertex over a plane", 4, spike, HexLattice::withSpacing(10), {}, false});
  }
  {
    // Input vertices on lattice points: a plane with a vertex every 3 units at spacing 6 (row 5). Grid vertices that
    // are input vertices stay input vertices (they keep their normals and colors in the remesh stage).
    Patch integer;
    const int n = 40;
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) integer.positions.push_back({3.0 * i, 5.0 * j, 0.5 * i + 0.25 * j});
    const auto at = [&](int i, int j) { return uint32_t(j * (n + 1) + i); };
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        integer.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
        integer.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
      }
    cases.push_back({"input vertices on lattice points", 4, integer, HexLattice::withSpacing(6), {}});
  }
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const int relief = c.relief;
    auto direct = resampleRelief(c.in.positions, c.in.triangles, relief, c.lattice, c.fixed, ResampleMethod::kDirect);
    auto sliced = resampleRelief(c.in.positions, c.in.triangles, relief, c.lattice, c.fixed, ResampleMethod::kSliceAll);
    ASSERT_TRUE(direct.isOk()) << direct.status().toString();
    ASSERT_TRUE(sliced.isOk()) << sliced.status().toString();
    if (c.valid) expectValid(c.in, *direct, relief, c.lattice, c.fixed);
    const auto a = regularCellsOf(*direct), b = regularCellsOf(*sliced);
    EXPECT_GT(a.size(), 100u);
    EXPECT_EQ(a, b);
    EXPECT_EQ(direct->triangles.size(), sliced->triangles.size());
    // The regular triangles' corners: positions to rounding, and input vertices where slicing keeps input vertices.
    const auto gridVertices = [](const ResampledRelief& r) {
      std::map<std::array<int32_t, 2>, std::pair<Vec3d, uint32_t>> out;
      for (size_t t = 0; t < r.triangles.size(); ++t)
        if (r.regular[t])
          for (uint32_t v : r.triangles[t]) out[r.lattice_ij[v]] = {r.positions[v], r.input_vertex[v]};
      return out;
    };
    const auto ga = gridVertices(*direct), gb = gridVertices(*sliced);
    EXPECT_EQ(ga.size(), gb.size());
    for (const auto& [ij, p] : gb) {
      const auto it = ga.find(ij);
      ASSERT_NE(it, ga.end()) << "grid vertex " << ij[0] << "," << ij[1];
      EXPECT_LT(vlen(vsub(it->second.first, p.first)), 1e-6) << "grid vertex " << ij[0] << "," << ij[1];
      EXPECT_EQ(it->second.second, p.second) << "grid vertex " << ij[0] << "," << ij[1];
    }
  }
}

// A tile's border: rough tiles whose boundary vertices are all fixed by the caller (a tile's locked border), at
// grids finer than the input. Every point a grid line adds on a border edge must leave it (the border edges come
// back whole) and no triangle may flip. Where no collapse along the edge can go, the point is removed by
// triangulating the hole it leaves; before that existed, collapses checking nothing but the topology flipped
// thousands of triangles on these tiles. The holes' triangles may be irregular without a fixed corner (at most a
// few per point removed so).
TEST(Resample, TileBorderPointsLeaveWithoutFlippingATriangle) {
  const int cells = 12;
  uint64_t retriangulated = 0;
  for (uint32_t seed = 1; seed <= 8; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const Patch in = heightField(
        4, cells, 100, 600,
        [&](double x, double y) { return 40 * std::sin(x / 37.0 + seed) * std::cos(y / 23.0) + 0.05 * x; }, 0.3, seed);
    std::vector<uint8_t> fixed(in.positions.size(), 0);
    for (int j = 0; j <= cells; ++j)
      for (int i = 0; i <= cells; ++i)
        if (i == 0 || j == 0 || i == cells || j == cells) fixed[size_t(j * (cells + 1) + i)] = kFixedByCaller;
    std::set<std::pair<uint32_t, uint32_t>> border;  // input boundary edges, as input vertex pairs
    {
      std::map<std::pair<uint32_t, uint32_t>, int> uses;
      for (const Triangle& t : in.triangles)
        for (int k = 0; k < 3; ++k) ++uses[std::minmax(t[size_t(k)], t[size_t((k + 1) % 3)])];
      for (const auto& [e, n] : uses)
        if (n == 1) border.insert(e);
    }
    for (uint32_t spacing : {6u, 10u, 16u}) {
      SCOPED_TRACE("spacing " + std::to_string(spacing));
      const HexLattice lattice = HexLattice::withSpacing(spacing);
      auto r = resampleRelief(in.positions, in.triangles, 4, lattice, fixed);
      ASSERT_TRUE(r.isOk()) << r.status().toString();
      size_t irregular_inside = 0;
      expectValid(in, *r, 4, lattice, fixed, &irregular_inside);
      EXPECT_LE(irregular_inside, 2 * r->retriangulated);
      retriangulated += r->retriangulated;
      std::set<std::pair<uint32_t, uint32_t>> edges;
      for (const Triangle& t : r->triangles)
        for (int k = 0; k < 3; ++k) {
          const uint32_t a = r->input_vertex[t[size_t(k)]], b = r->input_vertex[t[size_t((k + 1) % 3)]];
          if (a != UINT32_MAX && b != UINT32_MAX) edges.insert(std::minmax(a, b));
        }
      for (const auto& e : border) EXPECT_TRUE(edges.count(e)) << "border edge " << e.first << "-" << e.second;
    }
  }
  EXPECT_GT(retriangulated, 100u);
  // A review's case on quantized coordinates: link vertices exactly on a chord (rounded a hair outside it) once made
  // the triangulation give up, and the point stayed on the border edge (the remesh stage then kept the tile as it
  // was). Every point leaves, and nothing flips.
  const Patch one{{{1029, 769, 1506}, {1028, 794, 1520}, {1012, 791, 1507}}, {{0, 1, 2}}};
  const std::vector<uint8_t> all_fixed(3, kFixedByCaller);
  auto r = resampleRelief(one.positions, one.triangles, 4, HexLattice::withSpacing(8), all_fixed);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  for (size_t v = 0; v < r->positions.size(); ++v)
    EXPECT_FALSE(r->input_vertex[v] == UINT32_MAX && r->input_edge[v][0] != UINT32_MAX)
        << "point " << v << " left on an input edge";
  size_t irregular_inside = 0;
  expectValid(one, *r, 4, HexLattice::withSpacing(8), all_fixed, &irregular_inside);
}

TEST(Resample, RefusesBadArguments) {
  const Patch in = heightField(4, 4, 0, 100, [](double, double) { return 1.0; });
  EXPECT_FALSE(resampleRelief(in.positions, in.triangles, 4, HexLattice::withSpacing(3), {}).isOk());
  EXPECT_FALSE(resampleRelief(in.positions, in.triangles, 4, HexLattice::withSpacing(0), {}).isOk());
  EXPECT_FALSE(resampleRelief(in.positions, in.triangles, 6, HexLattice::withSpacing(10), {}).isOk());
  EXPECT_FALSE(resampleRelief(in.positions, in.triangles, 4, HexLattice::withSpacing(10), std::vector<uint8_t>(3))
                   .isOk());
  auto away = resampleRelief(in.positions, in.triangles, 5, HexLattice::withSpacing(10), {});  // faces +z, not -z
  ASSERT_FALSE(away.isOk());
  EXPECT_NE(away.status().message().find("faces away"), std::string::npos);
  Patch bad = in;
  bad.triangles[2][2] = 99;
  EXPECT_FALSE(resampleRelief(bad.positions, bad.triangles, 4, HexLattice::withSpacing(10), {}).isOk());
}

}  // namespace
}  // namespace scanpress
