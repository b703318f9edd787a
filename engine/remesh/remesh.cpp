// Piecewise regular remeshing (see remesh.h): relief construction, resampling of each relief's connected parts,
// and merging, after sections 2.1 to 2.3 of Szymczak, Rossignac, King, "Piecewise Regular Meshes: Construction
// and Compression" (../shared/papers/prm-piecewise-regular-meshes.md).
//
// Merging departs from the paper. The paper fills the loop between two reliefs' resampled boundaries with
// zero-area triangles, then collapses boundary vertices onto grid vertices and flips edges to reduce area. Here the
// points grid lines add on a relief's boundary are first collapsed along their boundary edge within the relief
// (resample.cpp), so two reliefs meet along the input's own edges with the same vertices, and merging is joining
// vertices by identity. A point that could not be collapsed (a triangle would flip) is inserted into the other
// reliefs' triangles on that edge, by splitting them at it: the mesh is then conforming, with no zero-area
// triangle. On a tile's border edge (which must stay an edge) such points get the paper's fan of zero-area
// triangles instead. Resampling never joins two boundary vertices by a new edge (resample.cpp), so two reliefs'
// triangles never overlap where they meet. After merging, the paper's collapse of relief boundary vertices onto
// grid vertices (collapseOntoGrid), then its area-reducing edge flips in the irregular band (flipToReduceArea), both
// with a bound on how far the surface moves that the paper does not have.
#include "engine/remesh/remesh.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <span>
#include <string>
#include <unordered_map>
#include <unordered_set>

#include "engine/geometry.h"
#include "engine/remesh/relief.h"
#include "engine/remesh/resample.h"

namespace scanpress {
namespace {

using u32 = uint32_t;
using u64 = uint64_t;
constexpr u32 kNone = UINT32_MAX;
// Resampling makes at most about this many pieces per input triangle (plus a million per tile), or refuses.
constexpr double kMaxPiecesPerTriangle = 64;

// A point added on an input edge that stays on a relief's boundary: where along the edge, which merged vertex, and
// which relief part it came from.
struct EdgePoint {
  double t;
  u32 vertex;
  u32 part;
};

// A tile border edge (a, b) that a relief part left subdivided by `points`: for each part, a fan from the chain's
// start over its points and the edge's other end, so that the edge (a, b) is an edge again, oriented as the part's
// boundary runs. The fan's triangles have zero area (their corners are on one segment).
void closeBorderEdge(Remeshed& out, std::vector<u32>& triangle_part, const std::vector<int>& part_relief, u32 a, u32 b,
                     const std::vector<EdgePoint>& points) {
  std::map<u32, std::vector<u32>> chain_of_part;  // points in order from a to b
  for (const EdgePoint& p : points) chain_of_part[p.part].push_back(p.vertex);
  for (const auto& [part, inner] : chain_of_part) {
    std::vector<u32> chain = {a};
    chain.insert(chain.end(), inner.begin(), inner.end());
    chain.push_back(b);
    // The part's boundary runs a -> b when its triangle on (a, chain[1]) has that directed edge.
    bool forward = true;
    for (size_t t = 0; t < out.triangles.size(); ++t) {
      if (triangle_part[t] != part) continue;
      const Triangle& tri = out.triangles[t];
      for (int k = 0; k < 3; ++k) {
        const u32 x = tri[size_t(k)], y = tri[size_t((k + 1) % 3)];
        if (x == chain[0] && y == chain[1]) forward = true;
        if (x == chain[1] && y == chain[0]) forward = false;
      }
    }
    if (!forward) std::reverse(chain.begin(), chain.end());
    // Boundary edges chain[i] -> chain[i+1]; fill triangles use them reversed, and the new edge chain[0] -> end.
    const u32 apex = chain.front();
    const uint8_t relief = uint8_t(part_relief[part]);
    for (size_t i = 1; i + 1 < chain.size(); ++i) {  // (apex, c[i+1], c[i]); the last is (apex, end, c[k])
      out.triangles.push_back({apex, chain[i + 1], chain[i]});
      out.relief.push_back(relief);
      out.regular.push_back(0);
      triangle_part.push_back(part);
    }
    ++out.border_fans;
  }
}

// The paper's collapses after merging (section 2.3): every vertex that is not a grid vertex (on relief boundaries,
// where resampling left irregular triangles) and is not kept (a locked tile vertex), with a closed fan of
// triangles around it, is collapsed onto a neighbouring grid vertex: the nearest one whose collapse keeps the
// topology (the link condition) and turns no triangle by more than 90 degrees against its old normal or against the
// fan's mean normal, nor makes one degenerate. Then unused vertices are dropped. Vertices on a boundary (the tile's or the
// scan's) never move, so the boundary polylines stay.
void collapseOntoGrid(Remeshed& out, const std::vector<uint8_t>& keep, const std::vector<uint8_t>& on_lattice,
                      double spacing) {
  const u32 nv = u32(out.positions.size());
  std::vector<std::vector<u32>> inc(nv);
  for (u32 t = 0; t < out.triangles.size(); ++t)
    for (u32 v : out.triangles[t]) inc[v].push_back(t);
  std::vector<uint8_t> dead(out.triangles.size(), 0);
  const auto normal = [&](const Triangle& t) {
    return vcross(vsub(out.positions[t[1]], out.positions[t[0]]), vsub(out.positions[t[2]], out.positions[t[0]]));
  };
  std::vector<u32> ring;  // neighbours of v, with multiplicity
  for (u32 v = 0; v < nv; ++v) {
    if (keep[v] || on_lattice[v] || inc[v].size() < 3) continue;
    // A closed fan: every neighbour twice, and as many neighbours as triangles; no triangle repeats v.
    ring.clear();
    bool ok = true;
    for (u32 t : inc[v]) {
      const Triangle& tri = out.triangles[t];
      int mine = 0;
      for (u32 x : tri)
        if (x == v) ++mine;
        else ring.push_back(x);
      ok &= mine == 1;
    }
    if (!ok) continue;
    std::sort(ring.begin(), ring.end());
    for (size_t i = 0; i < ring.size(); i += 2)
      ok &= i + 1 < ring.size() && ring[i] == ring[i + 1] && (i + 2 >= ring.size() || ring[i + 2] != ring[i]);
    if (!ok || ring.size() != 2 * inc[v].size()) continue;
    Vec3d mean{0, 0, 0};
    for (u32 t : inc[v]) mean = vadd(mean, normal(out.triangles[t]));
    // Candidates: lattice neighbours, nearest first.
    std::vector<std::pair<double, u32>> targets;
    for (size_t i = 0; i < ring.size(); i += 2)
      if (on_lattice[ring[i]]) targets.push_back({vlen(vsub(out.positions[ring[i]], out.positions[v])), ring[i]});
    std::sort(targets.begin(), targets.end());
    for (const auto& [dist, w] : targets) {
      // Link condition: v and w share exactly the two neighbours opposite edge vw.
      size_t shared = 0, on_edge = 0;
      for (u32 t : inc[v]) {
        const Triangle& tri = out.triangles[t];
        if (tri[0] == w || tri[1] == w || tri[2] == w) ++on_edge;
      }
      if (on_edge != 2) continue;
      for (size_t i = 0; i < ring.size(); i += 2) {
        const u32 x = ring[i];
        if (x == w) continue;
        for (u32 t : inc[w]) {
          const Triangle& tri = out.triangles[t];
          if (tri[0] == x || tri[1] == x || tri[2] == x) {
            ++shared;
            break;
          }
        }
      }
      if (shared != 2) continue;
      bool fine = true;
      for (u32 t : inc[v]) {
        Triangle tri = out.triangles[t];
        if (tri[0] == w || tri[1] == w || tri[2] == w) continue;
        const Vec3d before = normal(tri);
        for (u32& x : tri)
          if (x == v) x = w;
        const Vec3d after = normal(tri);
        const double la = vlen(after);
        if (!(la > 1e-9 * (1 + vdot(before, before))) || vdot(after, before) <= 0 || vdot(after, mean) <= 0) {
          fine = false;
          break;
        }
        // v's distance from the new triangle's plane: at most a quarter of the spacing (the surface moves by
        // that much at most; without this bound the max error of scans grew by a fifth, bench/RESULTS.md).
        if (std::abs(vdot(vsub(out.positions[v], out.positions[w]), after)) > 0.25 * spacing * la) {
          fine = false;
          break;
        }
      }
      if (!fine) continue;
      for (u32 t : inc[v]) {
        Triangle& tri = out.triangles[t];
        if (tri[0] == w || tri[1] == w || tri[2] == w) {
          dead[t] = 1;
          for (u32 x : tri) {
            if (x == v) continue;
            auto& list = inc[x];
            list.erase(std::remove(list.begin(), list.end(), t), list.end());
          }
          continue;
        }
        for (u32& x : tri)
          if (x == v) x = w;
        out.regular[t] = 0;
        inc[w].push_back(t);
      }
      inc[v].clear();
      ++out.grid_collapses;
      break;
    }
  }
  // Compact: live triangles, used vertices.
  std::vector<u32> id(nv, kNone);
  Remeshed c;
  c.reliefs = out.reliefs;
  c.merge_splits = out.merge_splits;
  c.border_fans = out.border_fans;
  c.grid_collapses = out.grid_collapses;
  c.edge_flips = out.edge_flips;
  for (u32 t = 0; t < out.triangles.size(); ++t) {
    if (dead[t]) continue;
    Triangle tri = out.triangles[t];
    for (u32& x : tri) {
      if (id[x] == kNone) {
        id[x] = u32(c.positions.size());
        c.positions.push_back(out.positions[x]);
        c.input_vertex.push_back(out.input_vertex[x]);
        c.source_triangle.push_back(out.source_triangle[x]);
      }
      x = id[x];
    }
    c.triangles.push_back(tri);
    c.relief.push_back(out.relief[t]);
    c.regular.push_back(out.regular[t]);
  }
  out = std::move(c);
}

// The paper's edge flips after the collapses (§2.3): an edge between two irregular triangles is flipped when that
// reduces their area, repeatedly (each flip queues the quad's four sides again), which straightens the irregular
// band between reliefs. The paper flips the edges joining vertices from different reliefs; ours are all the edges
// of the irregular band, which holds those and the irregular faces around holes and tile borders. Regular
// triangles are never touched. A flip is refused when the new edge exists already,
// when a new triangle would be degenerate or turn against either old one (no fold), or when an old corner is more
// than a quarter of the spacing off the new triangles' planes (the surface moves by that much at most, as for the
// collapses). Edges used by other than two triangles, or not in opposite directions, are never flipped; edges
// between two locked vertices are kept too (a tile's border stays as it is).
void flipToReduceArea(Remeshed& out, std::span<const uint8_t> locked_vertex, double spacing) {
  const u32 nt = u32(out.triangles.size());
  const auto key = [](u32 a, u32 b) { return a < b ? (u64(a) << 32 | b) : (u64(b) << 32 | a); };
  // Per undirected edge, its two triangles (kNone: fewer; a third makes it unflippable).
  struct Uses {
    u32 t[2] = {kNone, kNone};
    bool extra = false;
  };
  std::unordered_map<u64, Uses> edges;
  edges.reserve(size_t(nt) * 2);
  for (u32 t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      Uses& u = edges[key(out.triangles[t][size_t(k)], out.triangles[t][size_t((k + 1) % 3)])];
      if (u.t[0] == kNone) u.t[0] = t;
      else if (u.t[1] == kNone) u.t[1] = t;
      else u.extra = true;
    }
  const auto normal = [&](u32 a, u32 b, u32 c) {
    return vcross(vsub(out.positions[b], out.positions[a]), vsub(out.positions[c], out.positions[a]));
  };
  const auto locked = [&](u32 v) { return v < locked_vertex.size() && locked_vertex[v]; };
  std::vector<std::array<u32, 2>> queue;  // edges as vertex pairs, in triangle order
  for (u32 t = 0; t < nt; ++t)
    if (!out.regular[t])
      for (int k = 0; k < 3; ++k)
        queue.push_back({out.triangles[t][size_t(k)], out.triangles[t][size_t((k + 1) % 3)]});
  // Each flip lowers the total area, so this ends; the bound only caps the work on pathological input.
  const size_t max_steps = 20 * queue.size() + 1024;
  for (size_t head = 0; head < queue.size() && head < max_steps; ++head) {
    const u32 a0 = queue[head][0], b0 = queue[head][1];
    const auto it = edges.find(key(a0, b0));
    if (it == edges.end() || it->second.extra || it->second.t[1] == kNone) continue;
    u32 t1 = it->second.t[0], t2 = it->second.t[1];
    if (out.regular[t1] || out.regular[t2] || (locked(a0) && locked(b0))) continue;
    // t1 = (a, b, c) and t2 = (b, a, d), rotated so.
    if (t1 == t2) continue;
    const auto rotate = [&](u32 t, u32 from) {
      Triangle tri = out.triangles[t];
      for (int k = 0; k < 3 && tri[0] != from; ++k) std::rotate(tri.begin(), tri.begin() + 1, tri.end());
      return tri;
    };
    Triangle p = rotate(t1, a0), q;
    if (p[0] != a0 || p[1] != b0) std::swap(t1, t2), p = rotate(t1, a0);
    if (p[0] != a0 || p[1] != b0) continue;
    q = rotate(t2, b0);
    if (q[0] != b0 || q[1] != a0) continue;  // not in opposite directions
    const u32 a = a0, b = b0, c = p[2], d = q[2];
    if (c == d || c == a || c == b || d == a || d == b || edges.count(key(c, d))) continue;
    const Vec3d n1 = normal(a, b, c), n2 = normal(b, a, d), m1 = normal(a, d, c), m2 = normal(d, b, c);
    const double before = vlen(n1) + vlen(n2), l1 = vlen(m1), l2 = vlen(m2);
    if (!(l1 + l2 < before * (1 - 1e-9)) || !(l1 > 1e-9 * before) || !(l2 > 1e-9 * before)) continue;
    if (vdot(m1, n1) <= 0 || vdot(m1, n2) <= 0 || vdot(m2, n1) <= 0 || vdot(m2, n2) <= 0) continue;
    // a and b within a quarter of the spacing of the new triangles' planes.
    if (std::abs(vdot(vsub(out.positions[b], out.positions[a]), m1)) > 0.25 * spacing * l1 ||
        std::abs(vdot(vsub(out.positions[a], out.positions[b]), m2)) > 0.25 * spacing * l2)
      continue;
    out.triangles[t1] = {a, d, c};
    out.triangles[t2] = {d, b, c};
    edges.erase(key(a, b));
    edges[key(c, d)] = Uses{{t1, t2}, false};
    for (u32& slot : edges[key(b, c)].t)
      if (slot == t1) slot = t2;
    for (u32& slot : edges[key(a, d)].t)
      if (slot == t2) slot = t1;
    ++out.edge_flips;
    queue.push_back({a, c});
    queue.push_back({c, b});
    queue.push_back({b, d});
    queue.push_back({d, a});
  }
}

}  // namespace

Result<Remeshed> remeshPiecewiseRegular(const QuantizedMesh& mesh, std::span<const uint8_t> locked,
                                        const RemeshOptions& options) {
  if (options.spacing < 2 || options.spacing % 2 != 0)
    return makeError(ErrorCode::kInvalidArgument,
                     "remesh: grid spacing " + std::to_string(options.spacing) + " is not an even number >= 2");
  SP_ASSIGN_OR_RETURN(const ReliefLayout layout, buildReliefs(mesh, locked, ReliefOptions{.tau = options.tau}));
  u32 parts = 0;
  const std::vector<u32> part_of = reliefComponents(layout, &parts);
  std::vector<std::vector<Triangle>> part_triangles(parts);
  std::vector<std::vector<u32>> part_sources(parts);  // per part triangle: its input triangle
  std::vector<int> part_relief(parts, 0);
  std::vector<u32> source_of_layout(layout.positions.size(), kNone);  // an input triangle holding the vertex
  for (size_t i = 0; i < layout.triangles.size(); ++i) {
    part_triangles[part_of[i]].push_back(layout.triangles[i]);
    part_sources[part_of[i]].push_back(layout.source[i]);
    part_relief[part_of[i]] = layout.relief[i];
    for (u32 v : layout.triangles[i])
      if (source_of_layout[v] == kNone) source_of_layout[v] = layout.source[i];
  }
  // The output grows with the area over the grid's cell: refuse a grid so fine that a tile would explode (each
  // piece costs about 100 bytes while resampling).
  {
    const HexLattice l = HexLattice::withSpacing(options.spacing);
    const double cell = 0.5 * double(l.spacing) * double(l.row);
    double pieces = 0;
    for (size_t i = 0; i < layout.triangles.size(); ++i) {
      const Triangle& t = layout.triangles[i];
      const auto a = reliefBase(layout.positions[t[0]], layout.relief[i]);
      const auto b = reliefBase(layout.positions[t[1]], layout.relief[i]);
      const auto c = reliefBase(layout.positions[t[2]], layout.relief[i]);
      const double area = 0.5 * std::abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]));
      const double perimeter = std::hypot(b[0] - a[0], b[1] - a[1]) + std::hypot(c[0] - b[0], c[1] - b[1]) +
                               std::hypot(a[0] - c[0], a[1] - c[1]);
      pieces += area / cell + 2 * perimeter / double(l.row) + 1;  // about what slicing makes (within 2x)
    }
    const double limit = kMaxPiecesPerTriangle * double(mesh.triangles.size()) + double(1 << 20);
    if (pieces > limit)
      return makeError(ErrorCode::kLimitExceeded,
                       "remesh: grid spacing " + std::to_string(options.spacing) +
                           " cells is too fine for this tile (" + std::to_string(mesh.triangles.size()) +
                           " triangles would make about " + std::to_string(uint64_t(pieces)) + " pieces; at most " +
                           std::to_string(uint64_t(kMaxPiecesPerTriangle)) + " per triangle): use a coarser grid");
  }
  // Layout vertices: the input's first (locked ones stay fixed), then the relief boundaries' cut points.
  std::vector<uint8_t> fixed(layout.positions.size(), 0);
  for (size_t v = 0; v < locked.size(); ++v) fixed[v] = locked[v] ? kFixedByCaller : 0;
  {                                          // vertices of edges between two parts
    std::vector<std::pair<u64, u32>> edges;  // (edge, part)
    for (size_t i = 0; i < layout.triangles.size(); ++i)
      for (int k = 0; k < 3; ++k) {
        const u32 a = layout.triangles[i][size_t(k)], b = layout.triangles[i][size_t((k + 1) % 3)];
        edges.push_back({(u64(std::min(a, b)) << 32) | std::max(a, b), part_of[i]});
      }
    std::sort(edges.begin(), edges.end());
    for (size_t i = 0; i + 1 < edges.size(); ++i)
      if (edges[i].first == edges[i + 1].first && edges[i].second != edges[i + 1].second) {
        fixed[edges[i].first >> 32] |= kSharedBoundary;
        fixed[edges[i].first & 0xffffffffu] |= kSharedBoundary;
      }
  }
  const HexLattice lattice = HexLattice::withSpacing(options.spacing);

  Remeshed out;
  out.reliefs = parts;
  std::vector<u32> merged_of_layout(layout.positions.size(), kNone);
  std::vector<u32> triangle_part;
  std::vector<uint8_t> on_lattice;                             // per merged vertex: a grid vertex of its relief
  std::map<std::pair<u32, u32>, std::vector<EdgePoint>> left;  // by layout edge (lower index first)
  for (u32 part = 0; part < parts; ++part) {
    SP_ASSIGN_OR_RETURN(ResampledRelief r, resampleRelief(layout.positions, part_triangles[part], part_relief[part],
                                                          lattice, fixed, options.resample));
    std::vector<u32> merged(r.positions.size());
    for (size_t v = 0; v < r.positions.size(); ++v) {
      const u32 lv = r.input_vertex[v];
      u32& id = lv != kNone ? merged_of_layout[lv] : merged[v];
      if (lv == kNone || id == kNone) {
        id = u32(out.positions.size());
        out.positions.push_back(r.positions[v]);
        const bool input = lv != kNone && lv < mesh.positions.size();
        out.input_vertex.push_back(input ? lv : kNone);
        out.source_triangle.push_back(input         ? kNone
                                      : lv != kNone ? source_of_layout[lv]
                                                    : part_sources[part][r.source_triangle[v]]);
        on_lattice.push_back(0);
      }
      if ((r.kind[v] & ~kFixedVertex) == kLatticeVertex) on_lattice[id] = 1;
      merged[v] = id;
      if (lv == kNone && r.input_edge[v][0] != kNone && (r.kind[v] & kFixedVertex)) {
        const u32 a = std::min(r.input_edge[v][0], r.input_edge[v][1]);
        const u32 b = std::max(r.input_edge[v][0], r.input_edge[v][1]);
        const Vec3d ab = vsub(layout.positions[b], layout.positions[a]);
        const double t = vdot(vsub(r.positions[v], layout.positions[a]), ab) / vdot(ab, ab);
        left[{a, b}].push_back({t, id, part});
      }
    }
    for (size_t t = 0; t < r.triangles.size(); ++t) {
      const Triangle& tri = r.triangles[t];
      out.triangles.push_back({merged[tri[0]], merged[tri[1]], merged[tri[2]]});
      out.relief.push_back(uint8_t(part_relief[part]));
      out.regular.push_back(r.regular[t]);
      triangle_part.push_back(part);
    }
  }

  const std::unordered_set<u64> border = left.empty() ? std::unordered_set<u64>() : tileBorderEdges(mesh, locked);
  // Points left on a boundary edge between reliefs: every other part on that edge gets them too, by splitting its
  // triangle on the sub-edge that holds each point. Points left on a tile border edge: the edge is restored by a
  // fan of zero-area triangles over them (the paper's loop filling).
  if (!left.empty()) {
    std::vector<std::vector<u32>> incident(out.positions.size());
    for (u32 t = 0; t < out.triangles.size(); ++t)
      for (u32 v : out.triangles[t]) incident[v].push_back(t);
    for (auto& [edge, points] : left) {
      std::sort(points.begin(), points.end(), [](const EdgePoint& x, const EdgePoint& y) { return x.t < y.t; });
      const u32 a = merged_of_layout[edge.first], b = merged_of_layout[edge.second];
      if (a == kNone || b == kNone) continue;
      if (border.count((u64(edge.first) << 32) | edge.second)) {
        closeBorderEdge(out, triangle_part, part_relief, a, b, points);
        continue;
      }
      // Where each vertex on the edge is along it.
      std::unordered_map<u32, double> along = {{a, 0.0}, {b, 1.0}};
      for (const EdgePoint& p : points) along[p.vertex] = p.t;
      // Every triangle with a side on this edge, once: the other parts' points strictly inside that side become
      // a fan from the opposite corner, in order along the side.
      std::vector<u32> on_edge;
      for (const auto& [v, where] : along)
        for (u32 t : incident[v]) on_edge.push_back(t);
      std::sort(on_edge.begin(), on_edge.end());
      on_edge.erase(std::unique(on_edge.begin(), on_edge.end()), on_edge.end());
      std::vector<u32> inside;
      for (u32 t : on_edge) {
        const Triangle tri = out.triangles[t];
        for (int k = 0; k < 3; ++k) {
          const u32 x = tri[size_t(k)], y = tri[size_t((k + 1) % 3)], z = tri[size_t((k + 2) % 3)];
          const auto ix = along.find(x), iy = along.find(y);
          if (ix == along.end() || iy == along.end()) continue;
          if (along.count(z)) break;  // a zero-area triangle along the edge: left as it is
          const double tx = ix->second, ty = iy->second;
          inside.clear();
          for (const EdgePoint& p : points)  // sorted by t
            if (p.part != triangle_part[t] && p.t > std::min(tx, ty) && p.t < std::max(tx, ty))
              inside.push_back(p.vertex);
          if (inside.empty()) continue;
          if (tx > ty) std::reverse(inside.begin(), inside.end());  // in order from x to y
          // (x, y, z) -> (x, p1, z), (p1, p2, z), ..., (pk, y, z).
          u32 from = x;
          for (size_t q = 0; q <= inside.size(); ++q) {
            const u32 to = q < inside.size() ? inside[q] : y;
            if (q == 0) {
              out.triangles[t] = {from, to, z};
              out.regular[t] = 0;
              auto& list = incident[y];  // y leaves t (the last new triangle takes it)
              list.erase(std::remove(list.begin(), list.end(), t), list.end());
              incident[to].push_back(t);
            } else {
              const u32 added = u32(out.triangles.size());
              out.triangles.push_back({from, to, z});
              out.relief.push_back(out.relief[t]);
              out.regular.push_back(0);
              triangle_part.push_back(triangle_part[t]);
              for (u32 v : {from, to, z}) incident[v].push_back(added);
            }
            from = to;
          }
          out.merge_splits += inside.size();
          break;  // its other sides reach z, off the edge
        }
      }
    }
  }
  if (out.border_fans == 0 && options.collapse_onto_grid) {
    std::vector<uint8_t> keep(out.positions.size(), 0);
    for (u32 v = 0; v < out.positions.size(); ++v) {
      const u32 lv = out.input_vertex[v];
      keep[v] = on_lattice[v] || (lv != kNone && lv < locked.size() && locked[lv]);
    }
    collapseOntoGrid(out, keep, on_lattice, options.spacing);
  }
  if (out.border_fans == 0 && options.flip_edges) {
    std::vector<uint8_t> locked_out(out.positions.size(), 0);
    for (u32 v = 0; v < out.positions.size(); ++v) {
      const u32 lv = out.input_vertex[v];
      locked_out[v] = lv != kNone && lv < locked.size() && locked[lv];
    }
    flipToReduceArea(out, locked_out, options.spacing);
  }
  return out;
}

}  // namespace scanpress
