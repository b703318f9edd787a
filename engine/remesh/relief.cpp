// Relief construction (see relief.h), after section 2.1 of Szymczak, Rossignac, King, "Piecewise Regular
// Meshes: Construction and Compression" (../shared/papers/prm-piecewise-regular-meshes.md).
//
// As in the paper: the six axis vectors; for each vector v the set A_v of triangles whose unit normal n has
// n.v < tau; d_v, the geodesic distance from A_v, approximated by Dijkstra's algorithm along the mesh edges and
// kept as values at the vertices (piecewise linear over each triangle); relief v is where d_v is the largest.
//
// Departures:
// - The regions are traced from the corners' labels (the v with the largest d_v at each corner), as marching
//   triangles do: a triangle whose corners have two labels is cut along the line where those two distances are
//   equal; one with three labels along three such lines meeting where all three are equal (or, when that point
//   is not inside the triangle or is undefined, at the centroid of the three cut points). A label that is the
//   largest only between the corners of an edge is not traced (the paper's exact upper envelope would also
//   trace it). Cut points sit between 1/64 and 63/64 of their edge, so no piece is a sliver at a corner.
//   A cut point depends only on its edge (its two end vertices), so neighbouring triangles, including all
//   triangles of a non-manifold edge, are cut at the same point: the refined mesh has no T-junction.
// - Ties (equal distances, for instance two infinite ones on a part of the surface no A_v reaches) go to the
//   vector the vertex's area-weighted normal faces most, then to the lower relief id.
// - With distances known only at the vertices, a refined triangle can face its relief with a cosine below tau
//   (near corners where several A_v meet). Such triangles are given the relief their normal faces most, whose
//   cosine is at least 1/sqrt(3) > tau. So every non-degenerate refined triangle faces its relief with a cosine of
//   at least tau: every relief is a height field, as in the paper.
// - Zero-area triangles are never in an A_v (they have no normal) and are cut like the others, so that the
//   refinement stays conforming; their pieces have zero area. Triangles that repeat a vertex are kept whole, with
//   their first corner's relief.
// - Tiles (beyond the paper): an edge between two locked vertices that is on the tile's border (one triangle, or
//   more than two) is never cut; a relief boundary that meets it goes through its nearer end instead, and the
//   empty piece that leaves is dropped. So the tile's border edges stay edges (engine/tile.h's contract).
#include "engine/remesh/relief.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <queue>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>

#include "engine/geometry.h"

namespace scanpress {
namespace {

using u32 = uint32_t;
using u64 = uint64_t;
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kMinCut = 1.0 / 64, kMaxCut = 63.0 / 64;

struct Adjacency {
  std::vector<u32> start;  // per vertex, into `to` and `length`
  std::vector<u32> to;
  std::vector<double> length;
};

Adjacency adjacencyOf(const std::vector<Vec3d>& p, const std::vector<Triangle>& triangles) {
  // Each vertex's neighbours through its triangles' sides (two per triangle), then sorted and made unique per vertex.
  Adjacency adj;
  const size_t n = p.size();
  std::vector<u32> start(n + 1, 0);
  for (const Triangle& t : triangles)
    for (u32 v : t) start[v + 1] += 2;
  for (size_t v = 0; v < n; ++v) start[v + 1] += start[v];
  std::vector<u32> fill(start.begin(), start.end() - 1), to(start[n]);
  for (const Triangle& t : triangles)
    for (size_t k = 0; k < 3; ++k) {
      const u32 v = t[k];
      to[fill[v]++] = t[(k + 1) % 3];
      to[fill[v]++] = t[(k + 2) % 3];
    }
  adj.start.assign(n + 1, 0);
  adj.to.reserve(start[n] / 2 + n);
  for (size_t v = 0; v < n; ++v) {
    const auto first = to.begin() + start[v], last = to.begin() + start[v + 1];
    std::sort(first, last);
    for (auto it = first; it != last; ++it)
      if (*it != v && (it == first || *it != *(it - 1))) adj.to.push_back(*it);
    adj.start[v + 1] = u32(adj.to.size());
  }
  adj.length.resize(adj.to.size());
  for (size_t v = 0; v < n; ++v)
    for (u32 e = adj.start[v]; e < adj.start[v + 1]; ++e) adj.length[e] = vlen(vsub(p[v], p[adj.to[e]]));
  return adj;
}

// Multi-source Dijkstra: d[v * kReliefCount + r] is the shortest edge path from v to a source (infinite when
// none is connected to v).
void geodesicDistances(const Adjacency& adj, const std::vector<uint8_t>& source, int r, std::vector<double>& d) {
  using Entry = std::pair<double, u32>;
  std::priority_queue<Entry, std::vector<Entry>, std::greater<>> queue;
  const size_t n = source.size();
  for (size_t v = 0; v < n; ++v) d[v * kReliefCount + size_t(r)] = source[v] ? 0.0 : kInf;
  for (size_t v = 0; v < n; ++v) {  // only sources next to a vertex that is not one have anything to relax
    if (!source[v]) continue;
    bool frontier = false;
    for (u32 e = adj.start[v]; e < adj.start[v + 1] && !frontier; ++e) frontier = !source[adj.to[e]];
    if (frontier) queue.push({0.0, u32(v)});
  }
  while (!queue.empty()) {
    const auto [dv, v] = queue.top();
    queue.pop();
    if (dv > d[size_t(v) * kReliefCount + size_t(r)]) continue;
    for (u32 e = adj.start[v]; e < adj.start[v + 1]; ++e) {
      const u32 w = adj.to[e];
      const double nd = dv + adj.length[e];
      double& dw = d[size_t(w) * kReliefCount + size_t(r)];
      if (nd < dw) {
        dw = nd;
        queue.push({nd, w});
      }
    }
  }
}

// The relief a unit normal faces most (largest component along a defining vector).
uint8_t mostFaced(const Vec3d& n) {
  int best = 0;
  for (int r = 1; r < kReliefCount; ++r)
    if (alongRelief(n, r) > alongRelief(n, best)) best = r;
  return uint8_t(best);
}

class Builder {
 public:
  Builder(const QuantizedMesh& mesh, std::span<const uint8_t> locked, double tau)
      : in_(mesh), tau_(tau), border_(tileBorderEdges(mesh, locked)) {}

  ReliefLayout run() {
    const size_t n = in_.positions.size();
    out_.positions.reserve(n);
    for (const Vec3u& q : in_.positions) out_.positions.push_back({double(q[0]), double(q[1]), double(q[2])});
    computeNormals();
    computeDistances();
    labelVertices();
    out_.triangles.reserve(in_.triangles.size() + in_.triangles.size() / 8);
    for (u32 t = 0; t < in_.triangles.size(); ++t) refine(t);
    reface();
    return std::move(out_);
  }

 private:
  void computeNormals() {
    const auto& p = out_.positions;
    unit_normal_.resize(in_.triangles.size());
    vertex_normal_.assign(p.size(), Vec3d{0, 0, 0});
    for (size_t t = 0; t < in_.triangles.size(); ++t) {
      const Triangle& tri = in_.triangles[t];
      // Integer corners below 2^25 (checked): the cross product is exact, so zero area is decided exactly.
      const Vec3d c = vcross(vsub(p[tri[1]], p[tri[0]]), vsub(p[tri[2]], p[tri[0]]));
      const double len = vlen(c);
      unit_normal_[t] = len > 0 ? vmul(c, 1 / len) : Vec3d{0, 0, 0};
      for (u32 v : tri) vertex_normal_[v] = vadd(vertex_normal_[v], c);
    }
  }

  void computeDistances() {
    const size_t n = out_.positions.size();
    const Adjacency adj = adjacencyOf(out_.positions, in_.triangles);
    distance_.assign(n * kReliefCount, kInf);
    std::vector<uint8_t> source(n);
    for (int r = 0; r < kReliefCount; ++r) {
      std::fill(source.begin(), source.end(), 0);
      for (size_t t = 0; t < in_.triangles.size(); ++t) {
        const Vec3d& nt = unit_normal_[t];
        if (nt == Vec3d{0, 0, 0} || alongRelief(nt, r) >= tau_) continue;
        for (u32 v : in_.triangles[t]) source[v] = 1;
      }
      geodesicDistances(adj, source, r, distance_);
    }
  }

  double d(u32 v, int r) const { return distance_[size_t(v) * kReliefCount + size_t(r)]; }

  void labelVertices() {
    const size_t n = out_.positions.size();
    label_.assign(n, 0);
    for (u32 v = 0; v < n; ++v) {
      int best = 0;
      for (int r = 1; r < kReliefCount; ++r) {
        const double a = d(v, r), b = d(v, best);
        if (a > b || (a == b && alongRelief(vertex_normal_[v], r) > alongRelief(vertex_normal_[v], best))) best = r;
      }
      label_[v] = uint8_t(best);
    }
  }

  // The point on edge (a, b) where the distances of the two ends' reliefs are equal, made once per edge.
  u32 cutPoint(u32 a, u32 b) {
    const u32 lo = std::min(a, b), hi = std::max(a, b);
    const u64 key = (u64(lo) << 32) | hi;
    const auto it = cuts_.find(key);
    if (it != cuts_.end()) return it->second;
    const int la = label_[lo], lb = label_[hi];
    const double f0 = d(lo, la) - d(lo, lb), f1 = d(hi, la) - d(hi, lb);
    double t = 0.5;
    if (std::isfinite(f0) && std::isfinite(f1) && f0 - f1 > 0) t = f0 / (f0 - f1);
    if (border_.count(key)) {  // a tile border edge is not cut: the boundary goes through its nearer end
      const u32 end = t <= 0.5 ? lo : hi;
      cuts_.emplace(key, end);
      return end;
    }
    t = std::clamp(t, kMinCut, kMaxCut);
    const Vec3d& pa = out_.positions[lo];
    const Vec3d& pb = out_.positions[hi];
    const u32 id = u32(out_.positions.size());
    out_.positions.push_back(vadd(pa, vmul(vsub(pb, pa), t)));
    cuts_.emplace(key, id);
    return id;
  }

  // The point of triangle (c0, c1, c2) where its three corner labels' distances are equal, if inside; else the
  // centroid of the three cut points.
  u32 centerPoint(const Triangle& c, const std::array<u32, 3>& cut) {
    const int l0 = label_[c[0]], l1 = label_[c[1]], l2 = label_[c[2]];
    // Barycentric b with sum 1, sum b_i (d_l0 - d_l1)(c_i) = 0 and sum b_i (d_l0 - d_l2)(c_i) = 0.
    double m[3][3];
    bool finite = true;
    for (int i = 0; i < 3; ++i) {
      m[0][i] = d(c[size_t(i)], l0) - d(c[size_t(i)], l1);
      m[1][i] = d(c[size_t(i)], l0) - d(c[size_t(i)], l2);
      m[2][i] = 1;
      finite = finite && std::isfinite(m[0][i]) && std::isfinite(m[1][i]);
    }
    Vec3d point{0, 0, 0};
    bool inside = false;
    if (finite) {
      const auto det3 = [](const double a[3][3]) {
        return a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
               a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
      };
      const double det = det3(m);
      if (std::abs(det) > 1e-12) {
        double b[3];
        for (int i = 0; i < 3; ++i) {
          double mi[3][3];
          for (int r = 0; r < 3; ++r)
            for (int k = 0; k < 3; ++k) mi[r][k] = k == i ? (r == 2 ? 1.0 : 0.0) : m[r][k];
          b[i] = det3(mi) / det;
        }
        inside = b[0] > kMinCut && b[1] > kMinCut && b[2] > kMinCut;
        if (inside)
          for (int i = 0; i < 3; ++i) point = vadd(point, vmul(out_.positions[c[size_t(i)]], b[i]));
      }
    }
    if (!inside) {
      for (u32 k : cut) point = vadd(point, out_.positions[k]);
      point = vmul(point, 1.0 / 3);
    }
    out_.positions.push_back(point);
    return u32(out_.positions.size() - 1);
  }

  // A piece with a repeated corner (a cut moved to the end of a tile border edge) is empty and dropped.
  void emit(u32 a, u32 b, u32 c, int label, u32 source) {
    if (a == b || b == c || a == c) return;
    out_.triangles.push_back({a, b, c});
    out_.relief.push_back(uint8_t(label));
    out_.source.push_back(source);
  }

  void refine(u32 t) {
    const Triangle& c = in_.triangles[t];
    const int l[3] = {label_[c[0]], label_[c[1]], label_[c[2]]};
    if (c[0] == c[1] || c[1] == c[2] || c[0] == c[2] || (l[0] == l[1] && l[1] == l[2])) {
      out_.triangles.push_back(c);  // whole (also when it repeats a vertex)
      out_.relief.push_back(uint8_t(l[0]));
      out_.source.push_back(t);
      return;
    }
    ++out_.split_triangles;
    if (l[0] != l[1] && l[1] != l[2] && l[0] != l[2]) {
      const std::array<u32, 3> cut = {cutPoint(c[0], c[1]), cutPoint(c[1], c[2]), cutPoint(c[2], c[0])};
      const u32 center = centerPoint(c, cut);
      for (int k = 0; k < 3; ++k) {  // corner k's piece: (c_k, cut on k->k+1, center, cut on k+2->k)
        emit(c[size_t(k)], cut[size_t(k)], center, l[k], t);
        emit(c[size_t(k)], center, cut[size_t((k + 2) % 3)], l[k], t);
      }
      return;
    }
    // Two labels: corner k is the odd one, i and j the others in the triangle's order.
    const int k = l[1] == l[2] ? 0 : l[0] == l[2] ? 1 : 2;
    const u32 ck = c[size_t(k)], ci = c[size_t((k + 1) % 3)], cj = c[size_t((k + 2) % 3)];
    const u32 ski = cutPoint(ck, ci), skj = cutPoint(ck, cj);
    emit(ck, ski, skj, l[k], t);
    const int other = l[(k + 1) % 3];
    const auto& p = out_.positions;
    // The quad (ski, ci, cj, skj) along its shorter diagonal.
    if (vlen(vsub(p[ski], p[cj])) <= vlen(vsub(p[ci], p[skj]))) {
      emit(ski, ci, cj, other, t);
      emit(ski, cj, skj, other, t);
    } else {
      emit(ski, ci, skj, other, t);
      emit(ci, cj, skj, other, t);
    }
  }

  void reface() {
    for (size_t i = 0; i < out_.triangles.size(); ++i) {
      const Vec3d& nt = unit_normal_[out_.source[i]];
      if (nt == Vec3d{0, 0, 0} || alongRelief(nt, out_.relief[i]) >= tau_) continue;
      out_.relief[i] = mostFaced(nt);
      ++out_.refaced_triangles;
    }
  }

  const QuantizedMesh& in_;
  const double tau_;
  ReliefLayout out_;
  std::vector<Vec3d> unit_normal_;    // per input triangle (0 for zero area)
  std::vector<Vec3d> vertex_normal_;  // per input vertex, area-weighted (for ties)
  std::vector<double> distance_;      // per input vertex and relief
  std::vector<uint8_t> label_;        // per input vertex
  std::unordered_map<u64, u32> cuts_;
  const std::unordered_set<u64> border_;  // tile border edges (never cut)
};

}  // namespace

Result<ReliefLayout> buildReliefs(const QuantizedMesh& mesh, std::span<const uint8_t> locked,
                                  const ReliefOptions& options) {
  if (!locked.empty() && locked.size() != mesh.positions.size())
    return makeError(ErrorCode::kInvalidArgument, "relief construction: " + std::to_string(locked.size()) +
                                                      " lock flags for " + std::to_string(mesh.positions.size()) +
                                                      " vertices");
  if (!(options.tau > 0 && options.tau < 1 / std::sqrt(3.0)))
    return makeError(ErrorCode::kInvalidArgument,
                     "relief tau " + std::to_string(options.tau) + " is outside (0, 1/sqrt(3) = 0.577)");
  for (const Vec3u& p : mesh.positions)
    if (p[0] >= (1u << 25) || p[1] >= (1u << 25) || p[2] >= (1u << 25))
      return makeError(ErrorCode::kInvalidArgument, "relief construction: a vertex beyond 2^25 grid units");
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    for (u32 v : mesh.triangles[t])
      if (v >= mesh.positions.size())
        return makeError(ErrorCode::kInvalidArgument, "relief construction: triangle " + std::to_string(t) +
                                                          " uses vertex " + std::to_string(v) + " of " +
                                                          std::to_string(mesh.positions.size()));
  return Builder(mesh, locked, options.tau).run();
}

std::unordered_set<uint64_t> tileBorderEdges(const QuantizedMesh& mesh, std::span<const uint8_t> locked) {
  std::unordered_set<u64> border;
  if (locked.size() != mesh.positions.size()) return border;
  std::unordered_map<u64, int> uses;
  for (const Triangle& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      const u32 a = t[size_t(k)], b = t[size_t((k + 1) % 3)];
      if (a != b && locked[a] && locked[b]) ++uses[(u64(std::min(a, b)) << 32) | std::max(a, b)];
    }
  for (const auto& [key, n] : uses)
    if (n != 2) border.insert(key);
  return border;
}

std::vector<uint32_t> reliefComponents(const ReliefLayout& layout, uint32_t* count) {
  const size_t m = layout.triangles.size();
  std::vector<u32> parent(m);
  std::iota(parent.begin(), parent.end(), 0u);
  const auto find = [&](u32 x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  std::vector<std::pair<u64, u32>> edges;  // (edge key, triangle)
  edges.reserve(m * 3);
  for (u32 t = 0; t < m; ++t)
    for (int k = 0; k < 3; ++k) {
      const u32 a = layout.triangles[t][size_t(k)], b = layout.triangles[t][size_t((k + 1) % 3)];
      if (a != b) edges.push_back({(u64(std::min(a, b)) << 32) | std::max(a, b), t});
    }
  std::sort(edges.begin(), edges.end());
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j].first == edges[i].first) ++j;
    u32 first[kReliefCount];  // the edge's first triangle of each relief; the others join it
    std::fill(first, first + kReliefCount, UINT32_MAX);
    for (size_t a = i; a < j; ++a) {
      const u32 t = edges[a].second;
      u32& f = first[layout.relief[t]];
      if (f == UINT32_MAX) f = t;
      else parent[find(t)] = find(f);
    }
    i = j;
  }
  std::vector<u32> id(m, UINT32_MAX), root_id(m, UINT32_MAX);
  u32 next = 0;
  for (u32 t = 0; t < m; ++t) {
    const u32 r = find(t);
    if (root_id[r] == UINT32_MAX) root_id[r] = next++;
    id[t] = root_id[r];
  }
  if (count) *count = next;
  return id;
}

}  // namespace scanpress
