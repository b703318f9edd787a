// Relief resampling (see resample.h), after section 2.2 of Szymczak, Rossignac, King, "Piecewise Regular Meshes:
// Construction and Compression" (../shared/papers/prm-piecewise-regular-meshes.md).
//
// As in the paper: every triangle is sliced by the grid's three line families into convex polygons, each inside one
// grid triangle (a cell), and the polygons are cut into triangles by diagonals. Then vertices are removed by
// half-edge collapses, one endpoint moving onto the other, never moving a boundary vertex or a grid vertex, never
// making an edge that crosses a grid edge (unless it lies along one), never flipping a triangle (its projection
// stays counterclockwise, so its normal stays within 90 degrees of the defining vector).
//
// Departures and choices the paper leaves open:
// - The grid is on the integer grid (resample.h's HexLattice), so that the coder can rebuild every grid vertex's
//   base coordinates exactly from its lattice coordinates.
// - A vertex is classified against a grid line by its own lattice coordinates only (below, on, above), and a point
//   where a line crosses an edge depends only on that edge and line; a point made on a line has that coordinate
//   exactly (an integer), so the slicing is conforming across triangles and consistent at every level. Coordinates
//   within 1e-7 of an integer are snapped to it, so that a grid point on (or within rounding of) an edge is one
//   vertex, not one per line through it.
// - "Never crosses a grid edge" is kept as: every triangle lies in one closed cell. Each vertex knows the cells it
//   touches (from the pieces around it after slicing, which never change, since collapses keep positions), and a
//   collapse is allowed only when each triangle it makes has a cell common to its three corners.
// - Collapses keep the mesh a manifold: the link condition (the two endpoints share only the vertices opposite the
//   edge), and only vertices whose triangles form one closed fan move.
// - A vertex prefers to collapse onto a grid vertex, then onto a vertex on a grid line, then onto any other, nearest
//   first; passes repeat until none is possible.
// - Not in the paper, for speed (ResampleMethod::kDirect, the default): inside the relief, slicing and collapsing
//   leave each cell's grid triangle with its corners at the input's heights, so cells that only good triangles
//   cover (planInterior says which) are filled directly, and only the triangles over the other cells (the band along
//   boundaries, fixed vertices and zero-area triangles) are sliced. Each directly filled cell is first a polygon of
//   its corners and the points the band's pieces have on its sides, so the mesh stays conforming, and the usual
//   collapses then remove those points. kSliceAll does what the paper does; tests compare the two.
#include "engine/remesh/resample.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <unordered_map>

#include "engine/geometry.h"

namespace scanpress {
namespace {

using u32 = uint32_t;
using u64 = uint64_t;
// Lattice coordinates this close to an integer are on that line: far above the rounding noise of coordinates up
// to 2^25 grid units (resampleRelief refuses more; the tool's grids have at most 2^24), far below any spacing.
constexpr double kSnap = 1e-7;
constexpr u32 kNone = UINT32_MAX;
constexpr double kMaxCoordinate = double(1 << 25);
// Twice the smallest area, in lattice units (a cell has 1/2), of a triangle the slicing makes or a collapse leaves.
// Above the rounding noise of the pieces' orientation at the tool's grids (lattice coordinates up to 2^23 at
// spacing 2: one rounding step is 1.9e-9, so near that corner slivers of that size can pass; not flips of real
// area).
constexpr double kMinArea = 1e-9;

struct SliceVertex {
  double f[3];     // lattice coordinates s, t and u = s + t
  uint8_t on = 0;  // bit F: exactly on a line of family F (f[F] is an integer)
  // An added vertex on an input edge: that edge's two (local) input vertices, lower first; else none.
  uint32_t edge[2] = {UINT32_MAX, UINT32_MAX};
};

struct CrossingKey {
  u32 lo, hi;
  int64_t line;  // family * 2^40 + k (k fits in 32 bits for any 32-bit grid)
  bool operator==(const CrossingKey&) const = default;
};
struct CrossingHash {
  size_t operator()(const CrossingKey& k) const {
    u64 h = (u64(k.lo) << 32 | k.hi) * 0x9e3779b97f4a7c15ull;
    return size_t(h ^ (u64(k.line) * 0xc2b2ae3d27d4eb4full) ^ (h >> 29));
  }
};

// Cell ids: up cell (i, j) has lattice corners (i, j), (i+1, j), (i, j+1); down cell (i, j) has (i+1, j),
// (i, j+1), (i+1, j+1).
// |i|, |j| < 2^30 (coordinates below 2^25 grid units: resampleRelief checks).
u64 cellId(int64_t i, int64_t j, bool up) {
  return (u64(i + (int64_t(1) << 30)) << 33) | (u64(j + (int64_t(1) << 30)) << 1) | (up ? 1u : 0u);
}
constexpr u64 kNoCell = ~u64(0);  // a triangle that repeats a vertex (never sliced) or one of a triangulated hole

double cross2(const double* a, const double* b, const double* c) {
  return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}

// A lattice point's key.
u64 pointKey(int64_t i, int64_t j) { return (u64(i + (int64_t(1) << 30)) << 32) | u64(j + (int64_t(1) << 30)); }
// A grid edge's key: the edge of line `k` of family F between its lattice points m and m + 1 along the line (along
// t for family 0, along s for families 1 and 2).
u64 edgeKey(int family, int64_t k, int64_t m) {
  return (u64(family) << 62) | (u64(k + (int64_t(1) << 30)) << 31) | u64(m + (int64_t(1) << 30));
}

// An open-addressing map from 64-bit keys (never ~0) to 32-bit values: cells and lattice points of a relief.
class KeyMap {
 public:
  // The value of `key`, inserted as `fresh` if absent (`added` says which).
  u32& insert(u64 key, u32 fresh, bool& added) {
    if ((size_ + 1) * 2 > keys_.size()) grow();
    size_t s = hash(key) & (keys_.size() - 1);
    while (keys_[s] != kEmpty) {
      if (keys_[s] == key) {
        added = false;
        return values_[s];
      }
      s = (s + 1) & (keys_.size() - 1);
    }
    keys_[s] = key;
    values_[s] = fresh;
    ++size_;
    added = true;
    return values_[s];
  }
  const u32* find(u64 key) const {
    if (keys_.empty()) return nullptr;
    for (size_t s = hash(key) & (keys_.size() - 1); keys_[s] != kEmpty; s = (s + 1) & (keys_.size() - 1))
      if (keys_[s] == key) return &values_[s];
    return nullptr;
  }
  template <typename F>
  void forEach(F f) {
    for (size_t s = 0; s < keys_.size(); ++s)
      if (keys_[s] != kEmpty) f(keys_[s], values_[s]);
  }

 private:
  static constexpr u64 kEmpty = ~u64(0);
  static size_t hash(u64 k) {
    k ^= k >> 33;
    k *= 0xff51afd7ed558ccdull;
    return size_t(k ^ (k >> 33));
  }
  void grow() {
    std::vector<u64> keys = std::move(keys_);
    std::vector<u32> values = std::move(values_);
    keys_.assign(std::max<size_t>(64, keys.size() * 2), kEmpty);
    values_.assign(keys_.size(), 0);
    size_ = 0;
    bool added;
    for (size_t s = 0; s < keys.size(); ++s)
      if (keys[s] != kEmpty) insert(keys[s], values[s], added);
  }
  std::vector<u64> keys_;
  std::vector<u32> values_;
  size_t size_ = 0;
};

// A vertex's triangles (v, a, b), given as the pairs (a, b), link into one cycle through all its neighbours (sorts
// `ring`).
bool closedCycle(std::span<std::pair<u32, u32>> ring) {
  std::sort(ring.begin(), ring.end());
  for (size_t i = 1; i < ring.size(); ++i)
    if (ring[i].first == ring[i - 1].first) return false;
  if (ring.size() < 3) return false;
  u32 a = ring[0].first;
  for (size_t steps = 0; steps < ring.size(); ++steps) {
    const auto it = std::lower_bound(ring.begin(), ring.end(), std::pair<u32, u32>{a, 0});
    if (it == ring.end() || it->first != a) return false;
    a = it->second;
    if (a == ring[0].first) return steps + 1 == ring.size();
  }
  return false;
}

class Resampler {
 public:
  Resampler(std::span<const Vec3d> positions, std::span<const Triangle> triangles, int relief,
            const HexLattice& lattice, std::span<const uint8_t> fixed, bool direct)
      : relief_(relief), lattice_(lattice), direct_(direct) {
    // The used vertices, numbered in order of first use.
    std::unordered_map<u32, u32> local;
    local.reserve(triangles.size());
    triangles_in_.reserve(triangles.size());
    for (const Triangle& t : triangles) {
      Triangle l;
      for (size_t k = 0; k < 3; ++k) {
        const auto [it, added] = local.emplace(t[k], u32(positions_.size()));
        if (added) {
          positions_.push_back(positions[t[k]]);
          input_vertex_.push_back(t[k]);
          fixed_in_.push_back(fixed.empty() ? 0 : fixed[t[k]]);
        }
        l[k] = it->second;
      }
      triangles_in_.push_back(l);
    }
  }

  Result<ResampledRelief> run() {
    const size_t n = positions_.size();
    verts_.resize(n);
    for (size_t v = 0; v < n; ++v) {
      const auto base = reliefBase(positions_[v], relief_);
      const auto st = latticeCoordinates(lattice_, base);
      const double G = lattice_.spacing, H = lattice_.row;
      SliceVertex& s = verts_[v];
      s.f[0] = st[0];
      s.f[1] = st[1];
      s.f[2] = (2 * H * base[0] + G * base[1]) / (2 * G * H);
      completeLattice(s);
    }
    // Per input triangle: kRepeats, kZeroArea or 0.
    std::vector<uint8_t> degenerate(triangles_in_.size(), 0);
    for (size_t t = 0; t < triangles_in_.size(); ++t) {
      const Triangle& tri = triangles_in_[t];
      if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) {
        degenerate[t] = kRepeats;
        continue;
      }
      // Rounding noise of the orientation grows with the coordinates' size and the triangle's extent (lattice
      // coordinates are quotients): below it a triangle counts as zero-area, and only beyond it as facing away.
      double scale = 0, extent = 0;
      for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 2; ++c) {
          scale = std::max(scale, std::abs(verts_[tri[size_t(k)]].f[c]));
          extent = std::max(extent, std::abs(verts_[tri[size_t(k)]].f[c] - verts_[tri[size_t((k + 1) % 3)]].f[c]));
        }
      const double noise = kMinArea + 64 * std::numeric_limits<double>::epsilon() * (scale + 1) * (extent + 1);
      const double a = cross2(verts_[tri[0]].f, verts_[tri[1]].f, verts_[tri[2]].f);
      if (a < -noise)
        return makeError(ErrorCode::kInvalidArgument, "resampling relief " + std::to_string(relief_) + ": triangle " +
                                                          std::to_string(t) + " faces away from it");
      if (a <= noise) degenerate[t] = kZeroArea;
    }
    if (direct_) planInterior(degenerate);
    for (size_t t = 0; t < triangles_in_.size(); ++t) {
      if (degenerate[t] == kRepeats) {  // kept as it is
        addTriangle(triangles_in_[t], kNoCell);
        continue;
      }
      if (direct_ && !band_[t]) continue;  // only in cells filled directly
      current_triangle_ = u32(t);
      slice(triangles_in_[t], degenerate[t] == kZeroArea);  // (near) zero area: its pieces are fanned as they come
    }
    if (direct_ && !fillInterior()) {
      needs_full_ = true;
      return ResampledRelief{};
    }
    findFixed();
    collapseAll();
    collapseBoundaryChains();
    finish();
    return std::move(out_);
  }

  // The direct fill met two vertices at one of its cells' corners (overlapping layers the planning did not see):
  // run() gave up, and the relief must be resampled with every triangle sliced.
  bool needsFull() const { return needs_full_; }

 private:
  static constexpr uint8_t kRepeats = 1, kZeroArea = 2;
  // Cell states in cell_state_.
  static constexpr u32 kBadCell = 1, kInteriorCell = 2;
  struct Location {  // where a lattice point is on the input: a triangle and barycentric coordinates in it
    u32 triangle;
    double b[3];
    bool conflict;  // also in a triangle that shares no vertex with that one: another layer
  };

  static std::array<int64_t, 3> cellOf(u64 cell) {  // i, j, up
    return {int64_t(cell >> 33) - (int64_t(1) << 30), int64_t((cell >> 1) & 0xffffffffull) - (int64_t(1) << 30),
            int64_t(cell & 1)};
  }
  static std::array<std::array<int64_t, 2>, 3> cellCorners(u64 cell) {  // counterclockwise
    const auto [i, j, up] = cellOf(cell);
    if (up) return {{{i, j}, {i + 1, j}, {i, j + 1}}};
    return {{{i + 1, j}, {i + 1, j + 1}, {i, j + 1}}};
  }

  // Calls f with every cell the triangle may overlap (a superset: each row's part of the triangle by its extents
  // in s and u, padded by kSnap).
  template <typename F>
  void forCells(const Triangle& tri, F f) const {
    const double* p[3] = {verts_[tri[0]].f, verts_[tri[1]].f, verts_[tri[2]].f};
    const double tmin = std::min({p[0][1], p[1][1], p[2][1]}), tmax = std::max({p[0][1], p[1][1], p[2][1]});
    for (int64_t j = int64_t(std::floor(tmin - kSnap)); j <= int64_t(std::floor(tmax + kSnap)); ++j) {
      // The triangle's part in the row j <= t <= j + 1: its corners there and its sides' crossings of the row's
      // two lines.
      double smin = INFINITY, smax = -INFINITY, umin = INFINITY, umax = -INFINITY;
      const auto take = [&](double s, double u) {
        smin = std::min(smin, s);
        smax = std::max(smax, s);
        umin = std::min(umin, u);
        umax = std::max(umax, u);
      };
      for (int k = 0; k < 3; ++k) {
        const double *a = p[k], *b = p[(k + 1) % 3];
        if (a[1] >= double(j) - kSnap && a[1] <= double(j + 1) + kSnap) take(a[0], a[2]);
        for (const double line : {double(j), double(j + 1)})
          if ((a[1] - line) * (b[1] - line) < 0) {
            const double l = (line - a[1]) / (b[1] - a[1]);
            take(a[0] + l * (b[0] - a[0]), a[2] + l * (b[2] - a[2]));
          }
      }
      if (smin > smax) continue;
      smin -= kSnap;
      smax += kSnap;
      umin -= kSnap;
      umax += kSnap;
      for (int64_t i = int64_t(std::floor(smin)); i <= int64_t(std::floor(smax)); ++i) {
        const double lo = double(i + j);
        if (umax >= lo && umin <= lo + 1) f(cellId(i, j, true));
        if (umax >= lo + 1 && umin <= lo + 2) f(cellId(i, j, false));
      }
    }
  }

  // Finds the cells to fill directly and the triangles to slice (band_). A cell is filled directly when every
  // triangle that may overlap it is good (not zero-area, corners neither flagged by the caller nor on a boundary,
  // each corner's triangles one closed fan winding once around it in projection) and each of its corners lies in
  // one good triangle (or in several that share a vertex: on their common side or corner). Such a cell is covered
  // once by good triangles (a boundary crossing it would bring a bad triangle), so slicing and collapsing it would
  // leave exactly its grid triangle, with its corners' heights on the input.
  void planInterior(const std::vector<uint8_t>& degenerate) {
    const size_t n_in = input_vertex_.size(), m = triangles_in_.size();
    std::vector<u32> start(n_in + 1, 0);
    for (const Triangle& tri : triangles_in_)
      for (u32 v : tri) ++start[v + 1];
    for (size_t v = 0; v < n_in; ++v) start[v + 1] += start[v];
    std::vector<u32> fill(start.begin(), start.end() - 1);
    std::vector<std::pair<u32, u32>> ring(start[n_in]);
    std::vector<double> turn(n_in, 0);
    std::vector<uint8_t> good(n_in, 1);
    for (size_t t = 0; t < m; ++t) {
      const Triangle& tri = triangles_in_[t];
      for (size_t k = 0; k < 3; ++k) {
        const u32 v = tri[k], a = tri[(k + 1) % 3], b = tri[(k + 2) % 3];
        ring[fill[v]++] = {a, b};
        if (degenerate[t]) {
          good[v] = 0;
          continue;
        }
        const double *pv = verts_[v].f, *pa = verts_[a].f, *pb = verts_[b].f;
        const double ax = pa[0] - pv[0], ay = pa[1] - pv[1], bx = pb[0] - pv[0], by = pb[1] - pv[1];
        turn[v] += std::atan2(ax * by - ay * bx, ax * bx + ay * by);
      }
    }
    for (u32 v = 0; v < n_in; ++v)
      good[v] = good[v] && fixed_in_[v] == 0 && std::abs(turn[v] - 2 * std::numbers::pi) < 1 &&
                closedCycle(std::span(ring).subspan(start[v], start[v + 1] - start[v]));
    std::vector<uint8_t> good_triangle(m, 0);
    std::vector<u32> cell_start = {0};  // per triangle, into tri_cells: the cells it may overlap
    std::vector<u64> tri_cells;
    bool added;
    for (size_t t = 0; t < m; ++t) {
      const Triangle& tri = triangles_in_[t];
      if (degenerate[t] != kRepeats) {
        good_triangle[t] = !degenerate[t] && good[tri[0]] && good[tri[1]] && good[tri[2]];
        forCells(tri, [&](u64 cell) {
          tri_cells.push_back(cell);
          u32& state = cell_state_.insert(cell, 0, added);
          if (!good_triangle[t]) state |= kBadCell;
        });
      }
      cell_start.push_back(u32(tri_cells.size()));
    }
    // Lattice points in good triangles.
    for (size_t t = 0; t < m; ++t) {
      if (!good_triangle[t]) continue;
      const Triangle& tri = triangles_in_[t];
      const double* p[3] = {verts_[tri[0]].f, verts_[tri[1]].f, verts_[tri[2]].f};
      const double area = cross2(p[0], p[1], p[2]);
      const double tmin = std::min({p[0][1], p[1][1], p[2][1]}), tmax = std::max({p[0][1], p[1][1], p[2][1]});
      for (int64_t j = int64_t(std::ceil(tmin - kSnap)); j <= int64_t(std::floor(tmax + kSnap)); ++j) {
        double lo = INFINITY, hi = -INFINITY;  // the line t = j's part in the triangle
        for (int k = 0; k < 3; ++k) {
          const double *a = p[k], *b = p[(k + 1) % 3];
          if (a[1] == double(j)) {
            lo = std::min(lo, a[0]);
            hi = std::max(hi, a[0]);
          } else if ((a[1] - double(j)) * (b[1] - double(j)) < 0) {
            const double s = a[0] + (double(j) - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            lo = std::min(lo, s);
            hi = std::max(hi, s);
          }
        }
        if (lo > hi) continue;
        for (int64_t i = int64_t(std::ceil(lo - kSnap)); i <= int64_t(std::floor(hi + kSnap)); ++i) {
          const double x[2] = {double(i), double(j)};
          const double b0 = cross2(p[1], p[2], x) / area, b1 = cross2(p[2], p[0], x) / area, b2 = 1 - b0 - b1;
          if (b0 < -1e-9 || b1 < -1e-9 || b2 < -1e-9) continue;
          u32& at = located_.insert(pointKey(i, j), u32(locations_.size()), added);
          if (added) {
            locations_.push_back({u32(t), {b0, b1, b2}, false});
          } else {
            const Triangle& other = triangles_in_[locations_[at].triangle];
            bool shares = false;
            for (u32 v : tri) shares = shares || v == other[0] || v == other[1] || v == other[2];
            if (!shares) locations_[at].conflict = true;
          }
        }
      }
    }
    cell_state_.forEach([&](u64 cell, u32& state) {
      if (state & kBadCell) return;
      for (const auto& c : cellCorners(cell)) {
        const u32* at = located_.find(pointKey(c[0], c[1]));
        if (!at || locations_[*at].conflict) return;
      }
      state |= kInteriorCell;
    });
    band_.assign(m, 0);
    for (size_t t = 0; t < m; ++t)
      for (u32 k = cell_start[t]; k < cell_start[t + 1] && !band_[t]; ++k)
        band_[t] = !(*cell_state_.find(tri_cells[k]) & kInteriorCell);
  }

  bool interiorCell(u64 cell) const {
    if (!direct_) return false;
    const u32* state = cell_state_.find(cell);
    return state && (*state & kInteriorCell);
  }

  // The vertex at lattice point (i, j) of the kept pieces, or a new one at the input's height there.
  u32 latticeVertex(int64_t i, int64_t j) {
    bool added;
    u32& id = lattice_id_.insert(pointKey(i, j), u32(positions_.size()), added);
    if (!added) return id;
    const Location& l = locations_[*located_.find(pointKey(i, j))];
    const Triangle& tri = triangles_in_[l.triangle];
    for (u32 v : tri)  // an input vertex at the point is the grid vertex, as slicing keeps it
      if (verts_[v].on == 7 && verts_[v].f[0] == double(i) && verts_[v].f[1] == double(j)) return id = v;
    Vec3d p{0, 0, 0};
    for (int k = 0; k < 3; ++k) p = vadd(p, vmul(positions_[tri[size_t(k)]], l.b[k]));
    SliceVertex x;
    x.f[0] = double(i);
    x.f[1] = double(j);
    x.f[2] = double(i + j);
    x.on = 7;
    positions_.push_back(p);
    verts_.push_back(x);
    origin_.push_back(l.triangle);
    return id;
  }

  // Fills the cells planInterior chose: each cell's polygon (its corners and the points the kept pieces have on its
  // sides) is fanned as a piece. False when two of the kept pieces' vertices are at one of those corners.
  bool fillInterior() {
    constexpr u32 kTwice = kNone - 1;
    std::vector<uint8_t> seen(positions_.size(), 0);
    std::vector<std::pair<std::pair<u64, double>, u32>> on_side;  // (grid edge, position along it), vertex
    for (size_t t = 0; t < tris_.size(); ++t)
      for (u32 v : tris_[t]) {
        if (tri_cell_[t] == kNoCell || seen[v]) continue;  // not a triangle that repeats a vertex (kept as it is)
        seen[v] = 1;
        const SliceVertex& s = verts_[v];
        if (s.on == 7) {
          bool added;
          u32& id = lattice_id_.insert(pointKey(int64_t(s.f[0]), int64_t(s.f[1])), v, added);
          if (!added && id != v) id = kTwice;
        } else if (s.on) {
          const int family = s.on == 1 ? 0 : s.on == 2 ? 1 : 2;
          const double along = family == 0 ? s.f[1] : s.f[0];
          on_side.push_back({{edgeKey(family, int64_t(s.f[family]), int64_t(std::floor(along))), along}, v});
        }
      }
    std::sort(on_side.begin(), on_side.end());
    std::vector<u64> cells;
    cell_state_.forEach([&](u64 cell, u32 state) {
      if (state & kInteriorCell) cells.push_back(cell);
    });
    std::sort(cells.begin(), cells.end());
    std::vector<u32> poly;
    for (const u64 cell : cells) {
      const auto [i, j, up] = cellOf(cell);
      const auto corners = cellCorners(cell);
      // Per side from corner k to k + 1: its family, line, index along the line, and whether it runs forward.
      struct Side {
        int family;
        int64_t line, m;
        bool forward;
      };
      const Side sides[3] = {up ? Side{1, j, i, true} : Side{0, i + 1, j, true},
                             up ? Side{2, i + j + 1, i, false} : Side{1, j + 1, i, false},
                             up ? Side{0, i, j, false} : Side{2, i + j + 1, i, true}};
      poly.clear();
      for (int k = 0; k < 3; ++k) {
        const u32 c = latticeVertex(corners[size_t(k)][0], corners[size_t(k)][1]);
        if (c == kTwice) return false;
        poly.push_back(c);
        const u64 key = edgeKey(sides[k].family, sides[k].line, sides[k].m);
        const auto first = std::lower_bound(on_side.begin(), on_side.end(),
                                            std::pair<std::pair<u64, double>, u32>{{key, -INFINITY}, 0});
        auto last = first;
        while (last != on_side.end() && last->first.first == key) ++last;
        if (sides[k].forward)
          for (auto it = first; it != last; ++it) poly.push_back(it->second);
        else
          for (auto it = last; it != first;) poly.push_back((--it)->second);
      }
      current_triangle_ = locations_[*located_.find(pointKey(corners[0][0], corners[0][1]))].triangle;
      emitFan(poly, false, cell);
    }
    return true;
  }

  // A coordinate within kSnap of an integer is that integer: the vertex is on that line. Then a vertex on two line
  // families is a lattice vertex, and its third coordinate is made exact too.
  static void completeLattice(SliceVertex& s) {
    for (int k = 0; k < 3; ++k) {
      const double r = std::round(s.f[k]);
      if (!(s.on & (1 << k)) && std::abs(s.f[k] - r) <= kSnap) {
        s.f[k] = r;
        s.on |= uint8_t(1 << k);
      }
    }
    if ((s.on & 3) == 3) s.f[2] = s.f[0] + s.f[1];
    else if ((s.on & 5) == 5) s.f[1] = s.f[2] - s.f[0];
    else if ((s.on & 6) == 6) s.f[0] = s.f[2] - s.f[1];
    else return;
    s.on = 7;
  }

  int side(u32 v, int family, double k) const {
    const double f = verts_[v].f[family];
    return f < k ? -1 : f > k ? 1 : 0;
  }

  u32 crossing(u32 a, u32 b, int family, int64_t k) {
    const u32 lo = std::min(a, b), hi = std::max(a, b);
    const CrossingKey key{lo, hi, int64_t(family) * (int64_t(1) << 40) + k};
    const auto it = crossings_.find(key);
    if (it != crossings_.end()) return it->second;
    const SliceVertex &p = verts_[lo], &q = verts_[hi];
    const double lambda = (double(k) - p.f[family]) / (q.f[family] - p.f[family]);
    SliceVertex x;
    for (int g = 0; g < 3; ++g) {
      if (g == family) {
        x.f[g] = double(k);
        x.on |= uint8_t(1 << g);
      } else if ((p.on & q.on & (1 << g)) && p.f[g] == q.f[g]) {
        x.f[g] = p.f[g];
        x.on |= uint8_t(1 << g);
      } else {
        x.f[g] = p.f[g] + lambda * (q.f[g] - p.f[g]);
      }
    }
    completeLattice(x);
    // The input edge the point is on, if any: both ends input vertices (a side of an input triangle), or one end
    // on an input edge that has the other end (or both ends on one input edge).
    const u32 n_in = u32(input_vertex_.size());
    const auto carries = [&](u32 v, u32 a0, u32 a1) {
      return v == a0 || v == a1 || (verts_[v].edge[0] == a0 && verts_[v].edge[1] == a1);
    };
    if (lo < n_in && hi < n_in) {
      x.edge[0] = lo;
      x.edge[1] = hi;
    } else {
      const SliceVertex& e = lo < n_in ? q : p;  // an added end
      if (e.edge[0] != kNone && carries(lo, e.edge[0], e.edge[1]) && carries(hi, e.edge[0], e.edge[1])) {
        x.edge[0] = e.edge[0];
        x.edge[1] = e.edge[1];
      }
    }
    const Vec3d& pa = positions_[lo];
    const Vec3d& pb = positions_[hi];
    const u32 id = u32(positions_.size());
    positions_.push_back(vadd(pa, vmul(vsub(pb, pa), lambda)));
    verts_.push_back(x);
    origin_.push_back(current_triangle_);
    crossings_.emplace(key, id);
    return id;
  }

  void slice(const Triangle& tri, bool degenerate) {
    // Zero-area triangles are sliced too: their neighbours' edges get the same crossings, so no crack opens.
    std::vector<std::vector<u32>> pieces = {{tri[0], tri[1], tri[2]}}, next;
    for (int family = 0; family < 3; ++family) {
      next.clear();
      for (std::vector<u32>& poly : pieces) {
        double lo = INFINITY, hi = -INFINITY;
        for (u32 v : poly) {
          lo = std::min(lo, verts_[v].f[family]);
          hi = std::max(hi, verts_[v].f[family]);
        }
        std::vector<u32> current = std::move(poly);
        for (int64_t k = int64_t(std::floor(lo)) + 1; double(k) < hi; ++k) {
          if (!(double(k) > lo)) continue;
          std::vector<u32> below, above;
          bool any_below = false, any_above = false;
          for (size_t i = 0; i < current.size(); ++i) {
            const u32 p = current[i], q = current[(i + 1) % current.size()];
            const int sp = side(p, family, double(k)), sq = side(q, family, double(k));
            if (sp <= 0) below.push_back(p);
            if (sp >= 0) above.push_back(p);
            any_below = any_below || sp < 0;
            any_above = any_above || sp > 0;
            if (sp * sq < 0) {
              const u32 x = crossing(p, q, family, k);
              below.push_back(x);
              above.push_back(x);
            }
          }
          if (any_below && below.size() >= 3) next.push_back(std::move(below));
          if (!any_above) {
            current.clear();
            break;
          }
          current = std::move(above);
        }
        if (current.size() >= 3) next.push_back(std::move(current));
      }
      pieces.swap(next);
    }
    for (const std::vector<u32>& poly : pieces) emitPiece(poly, degenerate);
  }

  // The piece's cell. A piece is within one strip of each family, k <= f < k + 1 with its largest f in (k, k + 1]
  // (coordinates within kSnap of an integer are that integer, so the largest is exact). The pieces of a zero-area
  // triangle (`degenerate`) may lie on a line, and are placed by their centroid, as before that rule.
  u64 pieceCell(const std::vector<u32>& poly, bool degenerate) const {
    double hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (u32 v : poly)
      for (int k = 0; k < 3; ++k) hi[k] = std::max(hi[k], verts_[v].f[k]);
    const int64_t i = int64_t(std::ceil(hi[0])) - 1, j = int64_t(std::ceil(hi[1])) - 1,
                  u = int64_t(std::ceil(hi[2])) - 1;
    if (!degenerate && (u == i + j || u == i + j + 1)) return cellId(i, j, u == i + j);
    double s = 0, t = 0;
    for (u32 v : poly) {
      s += verts_[v].f[0];
      t += verts_[v].f[1];
    }
    s /= double(poly.size());
    t /= double(poly.size());
    const double fi = std::floor(s), fj = std::floor(t);
    return cellId(int64_t(fi), int64_t(fj), (s - fi) + (t - fj) < 1);
  }

  // A piece in a cell filled directly is dropped.
  void emitPiece(const std::vector<u32>& poly, bool degenerate) {
    const u64 cell = pieceCell(poly, degenerate);
    if (!interiorCell(cell)) emitFan(poly, degenerate, cell);
  }

  void emitFan(const std::vector<u32>& poly, bool degenerate, u64 cell) {
    const size_t m = poly.size();
    // A fan from the first corner that makes no zero-area triangle (a convex polygon with points along its sides
    // has one unless all its corners are on two sides of one corner); else a fan around the centroid.
    size_t apex = m;
    if (!degenerate) {
      for (size_t a = 0; a < m && apex == m; ++a) {
        bool good = true;
        for (size_t i = 1; i + 1 < m && good; ++i)
          good = cross2(verts_[poly[a]].f, verts_[poly[(a + i) % m]].f, verts_[poly[(a + i + 1) % m]].f) > kMinArea;
        if (good) apex = a;
      }
    } else {
      apex = 0;
    }
    if (apex < m) {
      for (size_t i = 1; i + 1 < m; ++i)
        addTriangle({poly[apex], poly[(apex + i) % m], poly[(apex + i + 1) % m]}, cell);
      return;
    }
    Vec3d c{0, 0, 0};
    SliceVertex cv;
    cv.f[0] = cv.f[1] = cv.f[2] = 0;
    for (u32 v : poly) {
      c = vadd(c, positions_[v]);
      for (int k = 0; k < 3; ++k) cv.f[k] += verts_[v].f[k] / double(m);
    }
    const u32 centre = u32(positions_.size());
    positions_.push_back(vmul(c, 1.0 / double(m)));
    verts_.push_back(cv);
    origin_.push_back(current_triangle_);
    for (size_t i = 0; i < m; ++i) addTriangle({centre, poly[i], poly[(i + 1) % m]}, cell);
  }

  void addTriangle(const Triangle& t, u64 cell) {
    tris_.push_back(t);
    tri_cell_.push_back(cell);
  }

  // Fixed vertices: the caller's, the ends of boundary or non-manifold edges, and vertices whose triangles do not
  // form one closed fan.
  void findFixed() {
    const size_t n = positions_.size();
    fixed_.assign(n, 0);
    shared_.assign(n, 0);
    for (size_t v = 0; v < fixed_in_.size(); ++v) {
      fixed_[v] = (fixed_in_[v] & kFixedByCaller) ? 1 : 0;
      shared_[v] = (fixed_in_[v] & kSharedBoundary) ? 1 : 0;
    }
    for (size_t v = fixed_in_.size(); v < n; ++v) {  // added on an edge between two shared boundary vertices
      const u32 e0 = verts_[v].edge[0], e1 = verts_[v].edge[1];
      shared_[v] = e0 != kNone && shared_[e0] && shared_[e1];
    }
    incident_.assign(n, {});
    dead_.assign(tris_.size(), 0);
    for (u32 t = 0; t < tris_.size(); ++t)
      for (u32 v : tris_[t]) incident_[v].push_back(t);
    for (u32 v = 0; v < n; ++v)
      if (!fixed_[v] && !incident_[v].empty() && !isClosedFan(v)) fixed_[v] = 1;
    // Cells per vertex: those of the pieces around it (all six around a lattice vertex inside the relief).
    cells_.assign(n, {});
    for (u32 t = 0; t < tris_.size(); ++t)
      for (u32 v : tris_[t]) {
        auto& c = cells_[v];
        if (tri_cell_[t] != kNoCell && std::find(c.begin(), c.end(), tri_cell_[t]) == c.end())
          c.push_back(tri_cell_[t]);
      }
  }

  // v's live triangles (v, a, b) link a -> b into one cycle through all of v's neighbours.
  bool isClosedFan(u32 v) const {
    std::vector<std::pair<u32, u32>> next;
    for (u32 t : incident_[v]) {
      if (dead_[t]) continue;
      const Triangle& tri = tris_[t];
      const int k = tri[0] == v ? 0 : tri[1] == v ? 1 : 2;
      const u32 a = tri[size_t((k + 1) % 3)], b = tri[size_t((k + 2) % 3)];
      if (a == v || b == v || a == b) return false;
      next.push_back({a, b});
    }
    return closedCycle(next);
  }

  bool shareCell(u32 a, u32 b, u32 c) const {
    for (u64 x : cells_[a])
      if (std::find(cells_[b].begin(), cells_[b].end(), x) != cells_[b].end() &&
          std::find(cells_[c].begin(), cells_[c].end(), x) != cells_[c].end())
        return true;
    return false;
  }

  int rank(u32 v) const { return (verts_[v].on == 7) ? 0 : verts_[v].on ? 1 : 2; }
  bool removable(u32 v) const { return !fixed_[v] && verts_[v].on != 7; }

  // Collapses u onto w if allowed. incident_ lists hold live triangles only. `along_boundary`: u and w are
  // neighbours on the relief's boundary (one triangle on their edge), and the cells are not kept.
  // How a collapse along the boundary checks geometry: the projection (as inside), or the normals in space.
  enum class Check { kProjection, kSpace };

  bool tryCollapse(u32 u, u32 w, bool along_boundary = false, Check check = Check::kProjection) {
    // Every moved triangle stays counterclockwise in projection and inside one cell (kSpace: its normal in space
    // stays within 90 degrees of its old one).
    opposite_.clear();
    for (u32 t : incident_[u]) {
      Triangle tri = tris_[t];
      bool has_w = false;
      for (u32& x : tri) {
        has_w = has_w || x == w;
        if (x == u) x = w;
      }
      if (has_w) {
        for (u32 x : tri)
          if (x != w) opposite_.push_back(x);
        continue;
      }
      if (check == Check::kSpace) {
        const Triangle& old = tris_[t];
        const auto normal = [&](const Triangle& x) {
          return vcross(vsub(positions_[x[1]], positions_[x[0]]), vsub(positions_[x[2]], positions_[x[0]]));
        };
        const Vec3d before = normal(old), after = normal(tri);
        if (!(vdot(before, after) > 0)) return false;
      } else if (!(cross2(verts_[tri[0]].f, verts_[tri[1]].f, verts_[tri[2]].f) > kMinArea)) {
        return false;
      }
      if (!along_boundary && !shareCell(tri[0], tri[1], tri[2])) return false;
    }
    // The link condition: u and w share exactly the vertices opposite their edge (two inside, one on the boundary).
    if (opposite_.size() != (along_boundary ? 1u : 2u) || (opposite_.size() == 2 && opposite_[0] == opposite_[1]))
      return false;
    neighbours_u_.clear();
    for (u32 t : incident_[u])
      for (u32 x : tris_[t])
        if (x != u) neighbours_u_.push_back(x);
    std::sort(neighbours_u_.begin(), neighbours_u_.end());
    neighbours_u_.erase(std::unique(neighbours_u_.begin(), neighbours_u_.end()), neighbours_u_.end());
    for (u32 t : incident_[w])
      for (u32 x : tris_[t])
        if (x != w && x != u && std::binary_search(neighbours_u_.begin(), neighbours_u_.end(), x) &&
            std::find(opposite_.begin(), opposite_.end(), x) == opposite_.end())
          return false;
    // No chord between two vertices of a boundary shared with another relief: u's other neighbours become w's, and
    // when w is on such a boundary none of them may be (except, along the boundary, the next point on the same
    // input edge). A chord across a relief's boundary
    // path can lie over the neighbouring relief in space (each relief only checks its own projection), and two
    // reliefs would then overlap where they meet.
    if (fixed_[w] && shared_[w])
      for (u32 x : neighbours_u_) {
        if (x == w || !fixed_[x] || !shared_[x] || std::find(opposite_.begin(), opposite_.end(), x) != opposite_.end())
          continue;
        if (along_boundary && sameInputEdge(u, x)) continue;
        return false;
      }
    // Collapse: u's triangles on the edge die, the others take w for u.
    for (u32 t : incident_[u]) {
      Triangle& tri = tris_[t];
      bool has_w = false;
      for (u32 x : tri) has_w = has_w || x == w;
      if (has_w) {
        dead_[t] = 1;
        for (u32 x : tri)
          if (x != u) {
            auto& list = incident_[x];
            list.erase(std::remove(list.begin(), list.end(), t), list.end());
          }
        continue;
      }
      for (u32& x : tri)
        if (x == u) x = w;
      incident_[w].push_back(t);
    }
    incident_[u].clear();
    ++out_.collapses;
    return true;
  }

  // A work list: every removable vertex once, then again whenever a collapse changes its neighbourhood (a vertex
  // that can collapse nowhere waits until then).
  void collapseAll() {
    const size_t n = positions_.size();
    std::vector<uint8_t> queued(n, 0);
    std::vector<u32> queue;
    for (u32 u = 0; u < n; ++u)
      if (removable(u) && !incident_[u].empty()) {
        queue.push_back(u);
        queued[u] = 1;
      }
    std::vector<std::pair<std::pair<int, double>, u32>> candidates;
    for (size_t head = 0; head < queue.size(); ++head) {
      const u32 u = queue[head];
      queued[u] = 0;
      if (incident_[u].empty()) continue;
      // Candidates: u's neighbours, grid vertices first, then vertices on a line, nearest first.
      candidates.clear();
      for (u32 t : incident_[u])
        for (u32 w : tris_[t])
          if (w != u) candidates.push_back({{rank(w), vlen(vsub(positions_[w], positions_[u]))}, w});
      std::sort(candidates.begin(), candidates.end());
      candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
      for (const auto& c : candidates) {
        const u32 w = c.second;
        if (!tryCollapse(u, w)) continue;
        for (u32 t : incident_[w])
          for (u32 x : tris_[t])
            if (x != w && removable(x) && !queued[x]) {
              queued[x] = 1;
              queue.push_back(x);
            }
        break;
      }
      if (head > (size_t(1) << 20) && head * 2 > queue.size()) {  // reclaim the consumed part of the list
        queue.erase(queue.begin(), queue.begin() + std::ptrdiff_t(head + 1));
        head = size_t(-1);
      }
    }
  }

  // Removes point c of a tile border edge (c on the relief's boundary) by triangulating the hole its triangles
  // leave, in projection, with the segment between its two neighbours on that edge as a side: so the edge loses the
  // point without a triangle folding (a half-edge collapse fans the hole from one corner, which folds when the hole
  // is not star-shaped from it). c's neighbours must form a path from one neighbour on the edge to the other. The
  // hole is cut into ears, in projection counterclockwise with no other corner inside or within rounding of a side
  // (quantized scans put link vertices exactly on chords), never making an edge that exists already or that joins
  // two vertices of a boundary shared with another relief. False, with nothing changed, when that is not possible.
  // (A point inside the relief, on an edge between two fixed vertices that is not on the border, is left alone: it
  // may be a grid vertex, and nothing needs it gone.)
  bool retriangulateWithout(u32 c) {
    std::vector<std::pair<u32, u32>> ring;  // (a, b) per triangle (c, a, b)
    for (u32 t : incident_[c]) {
      const Triangle& tri = tris_[t];
      const int k = tri[0] == c ? 0 : tri[1] == c ? 1 : 2;
      const u32 a = tri[size_t((k + 1) % 3)], b = tri[size_t((k + 2) % 3)];
      if (a == c || b == c || a == b) return false;
      ring.push_back({a, b});
    }
    std::vector<u32> seconds;  // each neighbour follows at most one other
    for (const auto& e : ring) seconds.push_back(e.second);
    std::sort(seconds.begin(), seconds.end());
    if (std::adjacent_find(seconds.begin(), seconds.end()) != seconds.end()) return false;
    std::sort(ring.begin(), ring.end());
    for (size_t i = 1; i < ring.size(); ++i)
      if (ring[i].first == ring[i - 1].first) return false;
    const auto next = [&](u32 a) {
      const auto it = std::lower_bound(ring.begin(), ring.end(), std::pair<u32, u32>{a, 0});
      return it != ring.end() && it->first == a ? it->second : kNone;
    };
    // The link in order, from the neighbour with no predecessor: a path from one neighbour on the edge to the other.
    u32 start = kNone;
    for (const auto& e : ring)
      if (!std::binary_search(seconds.begin(), seconds.end(), e.first)) start = e.first;
    if (start == kNone) return false;  // a cycle: c is inside the relief
    std::vector<u32> link = {start};
    for (size_t steps = 0; steps < ring.size(); ++steps) {
      const u32 b = next(link.back());
      if (b == kNone) return false;
      link.push_back(b);
    }
    if (link.size() != ring.size() + 1) return false;
    const u32 x = link.front(), y = link.back();
    if (!sameInputEdge(c, x) || !sameInputEdge(c, y) || hasEdge(x, y)) return false;
    std::vector<u32> poly = std::move(link);
    std::vector<Triangle> made;
    while (poly.size() > 3) {
      size_t best = poly.size();
      double best_length = INFINITY;
      for (size_t i = 0; i < poly.size(); ++i) {
        const u32 p = poly[(i + poly.size() - 1) % poly.size()], q = poly[i], r = poly[(i + 1) % poly.size()];
        if (!(cross2(verts_[p].f, verts_[q].f, verts_[r].f) > kMinArea)) continue;
        bool empty = true;
        for (u32 o : poly) {
          if (o == p || o == q || o == r) continue;
          const double* f = verts_[o].f;
          if (cross2(verts_[p].f, verts_[q].f, f) >= -kMinArea && cross2(verts_[q].f, verts_[r].f, f) >= -kMinArea &&
              cross2(verts_[r].f, verts_[p].f, f) >= -kMinArea) {
            empty = false;
            break;
          }
        }
        // (An earlier ear's diagonal is a side of the polygon now, never a diagonal again.)
        if (!empty || hasEdge(p, r) || (fixed_[p] && shared_[p] && fixed_[r] && shared_[r])) continue;
        const double length = std::hypot(verts_[r].f[0] - verts_[p].f[0], verts_[r].f[1] - verts_[p].f[1]);
        if (length < best_length) {
          best_length = length;
          best = i;
        }
      }
      if (best == poly.size()) return false;
      const u32 p = poly[(best + poly.size() - 1) % poly.size()], r = poly[(best + 1) % poly.size()];
      made.push_back({p, poly[best], r});
      poly.erase(poly.begin() + std::ptrdiff_t(best));
    }
    if (!(cross2(verts_[poly[0]].f, verts_[poly[1]].f, verts_[poly[2]].f) > kMinArea)) return false;
    made.push_back({poly[0], poly[1], poly[2]});
    for (u32 t : incident_[c]) {
      dead_[t] = 1;
      for (u32 v : tris_[t])
        if (v != c) {
          auto& list = incident_[v];
          list.erase(std::remove(list.begin(), list.end(), t), list.end());
        }
    }
    incident_[c].clear();
    for (const Triangle& tri : made) {
      const u32 t = u32(tris_.size());
      tris_.push_back(tri);
      tri_cell_.push_back(kNoCell);
      dead_.push_back(0);
      for (u32 v : tri) incident_[v].push_back(t);
    }
    ++out_.retriangulated;
    return true;
  }

  // A live triangle has both a and b.
  bool hasEdge(u32 a, u32 b) const {
    for (u32 t : incident_[a])
      for (u32 v : tris_[t])
        if (v == b) return true;
    return false;
  }

  // x is on u's input edge (an end of it, or another point added on it).
  bool sameInputEdge(u32 u, u32 x) const {
    const u32 e0 = verts_[u].edge[0], e1 = verts_[u].edge[1];
    return e0 != kNone && (x == e0 || x == e1 || (verts_[x].edge[0] == e0 && verts_[x].edge[1] == e1));
  }

  // Points added on the relief's boundary (where a grid line crosses a boundary edge) are collapsed along that
  // edge onto its neighbours there, where no triangle flips: the boundary then has the input's vertices only, and
  // neighbouring reliefs (and tiles) meet along the same edges. Points that cannot go stay (ResampledRelief's
  // input_edge names their edge).
  // On a tile's border (an input edge between two vertices the caller fixed) a point that cannot go so is removed
  // by triangulating the hole it leaves (retriangulateWithout), else collapsed with normals checked in space: a
  // border edge must come back whole (a subdivided border edge makes the remesh stage keep the tile as it was).
  // Collapses checking only the topology used to be the last resort here, and folded triangles next to tile
  // borders; they are gone. Still open: two tiles' added points near a seam can round onto the same grid point
  // (remesh_stage.cpp keeps a tile's own points apart, not its neighbour's).
  void collapseBoundaryChains() {
    const u32 n_in = u32(input_vertex_.size());
    std::vector<std::pair<double, u32>> candidates;
    for (int round = 0; round < 3; ++round) {
      // Round 0: collapses checked in projection; 1: triangulating the hole; 2: collapses checked in space.
      const Check check = round == 0 ? Check::kProjection : Check::kSpace;
      for (int pass = 0; pass < 4; ++pass) {
        bool any = false;
        for (u32 c = n_in; c < positions_.size(); ++c) {
          if (incident_[c].empty() || verts_[c].edge[0] == kNone) continue;
          const u32 e0 = verts_[c].edge[0], e1 = verts_[c].edge[1];
          if (round > 0 && !((fixed_in_[e0] & kFixedByCaller) && (fixed_in_[e1] & kFixedByCaller))) continue;
          if (round == 1) {
            if (retriangulateWithout(c)) any = true;
            continue;
          }
          // Its neighbours along the same input edge, on a boundary edge (used by one triangle).
          candidates.clear();
          for (u32 t : incident_[c])
            for (u32 w : tris_[t]) {
              if (w == c || !(w == e0 || w == e1 || (verts_[w].edge[0] == e0 && verts_[w].edge[1] == e1))) continue;
              int uses = 0;
              for (u32 t2 : incident_[c])
                for (u32 x : tris_[t2]) uses += x == w;
              if (uses == 1) candidates.push_back({vlen(vsub(positions_[w], positions_[c])), w});
            }
          std::sort(candidates.begin(), candidates.end());
          for (const auto& cand : candidates)
            if (tryCollapse(c, cand.second, true, check)) {
              any = true;
              break;
            }
        }
        if (!any) break;
      }
    }
  }

  void finish() {
    // Only the vertices live triangles use, in order of first use.
    std::vector<u32> id(positions_.size(), kNone);
    for (size_t t = 0; t < tris_.size(); ++t) {
      if (dead_[t]) continue;
      Triangle tri = tris_[t];
      for (u32& v : tri) {
        if (id[v] == kNone) {
          id[v] = u32(out_.positions.size());
          const SliceVertex& s = verts_[v];
          out_.positions.push_back(positions_[v]);
          out_.input_vertex.push_back(v < input_vertex_.size() ? input_vertex_[v] : kNone);
          out_.source_triangle.push_back(v < input_vertex_.size() ? kNone : origin_[v - input_vertex_.size()]);
          out_.input_edge.push_back(s.edge[0] == kNone
                                        ? std::array<u32, 2>{kNone, kNone}
                                        : std::array<u32, 2>{input_vertex_[s.edge[0]], input_vertex_[s.edge[1]]});
          out_.kind.push_back(uint8_t((s.on == 7 ? kLatticeVertex
                                       : s.on    ? kOnGridLine
                                                 : kFreeVertex) |
                                      (fixed_[v] ? kFixedVertex : 0)));
          out_.lattice_ij.push_back(s.on == 7 ? std::array<int32_t, 2>{int32_t(s.f[0]), int32_t(s.f[1])}
                                              : std::array<int32_t, 2>{0, 0});
        }
        v = id[v];
      }
      out_.triangles.push_back(tri);
      bool regular = tri[0] != tri[1] && tri[1] != tri[2] && tri[0] != tri[2];
      for (u32 v : tri) regular = regular && (out_.kind[v] & 3) == kLatticeVertex;
      if (regular) {  // the corners are one cell's: all within one step, one of the two cell shapes
        int64_t si = 0, sj = 0, mini = INT64_MAX, minj = INT64_MAX;
        for (u32 v : tri) {
          si += out_.lattice_ij[v][0];
          sj += out_.lattice_ij[v][1];
          mini = std::min<int64_t>(mini, out_.lattice_ij[v][0]);
          minj = std::min<int64_t>(minj, out_.lattice_ij[v][1]);
        }
        const int64_t di = si - 3 * mini, dj = sj - 3 * minj;
        regular = (di == 1 && dj == 1) || (di == 2 && dj == 2);
        if (regular)
          for (u32 v : tri)
            regular = regular && out_.lattice_ij[v][0] - mini <= 1 && out_.lattice_ij[v][1] - minj <= 1;
      }
      out_.regular.push_back(regular ? 1 : 0);
    }
  }

  const int relief_;
  const HexLattice lattice_;
  const bool direct_;        // fill cells inside good triangles directly (planInterior)
  bool needs_full_ = false;  // see needsFull()
  // The direct fill's plan: each cell's state, where lattice points are on the input, which triangles to slice,
  // and the kept pieces' lattice vertices.
  KeyMap cell_state_, located_, lattice_id_;
  std::vector<Location> locations_;
  std::vector<uint8_t> band_;
  std::vector<Triangle> triangles_in_;  // local vertex ids
  std::vector<Vec3d> positions_;        // the used input vertices, then the added ones
  std::vector<u32> input_vertex_;       // per used input vertex: its input index
  std::vector<uint8_t> fixed_in_;       // per used input vertex: the caller's flags
  std::vector<uint8_t> shared_;         // per vertex: on a boundary shared with another relief
  std::vector<u32> origin_;             // per added vertex: the input triangle it was made in
  u32 current_triangle_ = 0;            // the input triangle being sliced
  ResampledRelief out_;
  std::vector<SliceVertex> verts_;
  std::unordered_map<CrossingKey, u32, CrossingHash> crossings_;
  std::vector<Triangle> tris_;
  std::vector<u64> tri_cell_;
  std::vector<uint8_t> dead_, fixed_;
  std::vector<std::vector<u32>> incident_;
  std::vector<std::vector<u64>> cells_;
  std::vector<u32> opposite_, neighbours_u_;  // tryCollapse's scratch
};

}  // namespace

HexLattice HexLattice::withSpacing(uint32_t spacing) {
  HexLattice l;
  l.spacing = spacing;
  l.row = uint32_t(std::lround(double(spacing) * std::sqrt(3.0) / 2));
  return l;
}

std::array<double, 2> reliefBase(const Vec3d& p, int relief) {
  const int a = relief / 2;
  const double b0 = p[size_t((a + 1) % 3)], b1 = p[size_t((a + 2) % 3)];
  return relief % 2 == 0 ? std::array<double, 2>{b0, b1} : std::array<double, 2>{b1, b0};
}

double reliefHeight(const Vec3d& p, int relief) {
  return relief % 2 == 0 ? p[size_t(relief / 2)] : -p[size_t(relief / 2)];
}

std::array<double, 2> latticeCoordinates(const HexLattice& lattice, const std::array<double, 2>& base) {
  const double G = lattice.spacing, H = lattice.row;
  return {(2 * H * base[0] - G * base[1]) / (2 * G * H), base[1] / H};
}

Result<ResampledRelief> resampleRelief(std::span<const Vec3d> positions, std::span<const Triangle> triangles,
                                       int relief, const HexLattice& lattice, std::span<const uint8_t> fixed,
                                       ResampleMethod method) {
  if (lattice.spacing < 2 || lattice.spacing % 2 != 0 || lattice.row == 0)
    return makeError(ErrorCode::kInvalidArgument,
                     "resampling: grid spacing " + std::to_string(lattice.spacing) + " is not an even number >= 2");
  if (relief < 0 || relief >= 6)
    return makeError(ErrorCode::kInvalidArgument, "resampling: relief id " + std::to_string(relief));
  if (!fixed.empty() && fixed.size() != positions.size())
    return makeError(ErrorCode::kInvalidArgument, "resampling: fixed flags do not match the vertices");
  for (size_t t = 0; t < triangles.size(); ++t)
    for (uint32_t v : triangles[t]) {
      if (v >= positions.size())
        return makeError(ErrorCode::kInvalidArgument,
                         "resampling: triangle " + std::to_string(t) + " uses vertex " + std::to_string(v));
      for (double c : positions[v])
        if (!(std::abs(c) < kMaxCoordinate))
          return makeError(ErrorCode::kInvalidArgument,
                           "resampling: triangle " + std::to_string(t) + " has a corner beyond 2^25 grid units");
    }
  if (method == ResampleMethod::kSliceAll) return Resampler(positions, triangles, relief, lattice, fixed, false).run();
  Resampler direct(positions, triangles, relief, lattice, fixed, true);
  auto r = direct.run();
  if (!r.isOk() || !direct.needsFull()) return r;
  return Resampler(positions, triangles, relief, lattice, fixed, false).run();
}

}  // namespace scanpress
