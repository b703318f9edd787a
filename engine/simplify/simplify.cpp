// Shape-preserving QEM simplification.
//
// Follows Ahn, Chang, Ho, "Shape-preserving progressive coding of 3-D models", section 2 (../shared/papers/
// shape-preserving-progressive-qem.md), on Garland and Heckbert's quadrics ("Surface simplification using quadric
// error metrics", SIGGRAPH 97): each vertex carries the area-weighted quadric of its triangles' planes, an edge's
// cost is weight * Q(v') at its placement v', and the paper's weights are:
//   complex edge (more than two triangles): the number of its triangles;
//   exactly one end on the boundary: the interior vertex collapses onto the boundary one (v' = the boundary
//     vertex's position), weight 1 + (#edges of the boundary vertex - 2), at least 1;
//   both ends on the boundary, along a boundary edge: 1 + max(cos theta1, cos theta2);
//   interior: 1.
//
// Where this departs from the paper, and what it leaves open:
// - Figure 4's angles: theta_i is the angle, at end i, between the edge and the other boundary edge at that end
//   (the boundary polyline's interior angle). A straight boundary gives cos = -1, a spike cos -> 1, so spikes are
//   expensive. The weight is floored at kMinBoundaryEdgeWeight = 1: with the paper's range [0, 2] a straight run
//   would cost less than the interior around it (nothing at all at 0, whatever the surface does there); measured
//   at 10% (bench/RESULTS.md), the floor at 1 gives a smaller Hausdorff distance than 0.5 on parasaurolophus and
//   bun_zipper, the same on lato000, a slightly larger one on rs1.
// - "Boundary vertex" means a vertex on an open edge (one triangle) or on a complex edge: both are discontinuities
//   the paper wants kept, and a complex vertex pulled inward tears the non-manifold junction the same way.
//   A boundary vertex is only ever removed along an edge of its own kind (open along open, complex along complex);
//   an interior edge between two boundary vertices is never collapsed (it would pinch the surface).
// - Open edges also get Garland and Heckbert's perpendicular constraint planes (weight kBoundaryPlaneWeight times
//   the squared edge length), so that boundaries do not drift (both weight sets, kPlain included).
// - Placement (the paper's index 0/1/2): the least cost among both endpoints, the midpoint and the quadric's
//   optimum when its 3x3 system is well conditioned and the optimum lies near the edge; rounded to the integer
//   grid (positions stay on the scan's grid); index 0 when it lands on an endpoint (that endpoint is `kept`).
// - Not one collapse at a time from a heap but in passes (what the pm codec needs, and faster): each pass builds a
//   vertex->triangle adjacency (CSR) of the current mesh, computes every candidate edge's cost once, sorts them,
//   and takes them cheapest first when legal and when their closed one-rings are disjoint from those already taken
//   in the pass. Disjoint closed one-rings also make every legality test made on the pass's starting mesh still
//   exact when the collapse is applied. Like meshoptimizer's simplifier, a pass only considers candidates up to
//   1.5x the cost of the candidate whose rank is the number of collapses the pass needs, so that a pass does not
//   reach far up the cost order just because cheap collapses conflict (unless nothing within that bound is legal).
// - Legality beyond the paper: no triangle changes orientation (normals before and after have a positive dot
//   product) or gets two corners in one grid cell, no duplicate triangle, no manifold edge becomes complex, an
//   interior edge between two open-boundary vertices is never collapsed, and no edge other than the collapsed one
//   disappears (which keeps boundary and border chains, and never shrinks a component to a dangling vertex).
// - error: sqrt(Q(v') / sum of the quadric's weights), the area-weighted RMS distance (grid cells) from v' to the
//   planes gathered so far, without the paper's weight. It is an estimate, not a bound on the Hausdorff distance.
// - Vertices of degenerate input triangles (a repeated index, or two corners in one grid cell) are frozen like
//   locked ones, so those triangles stay as they are.
//
// Soups must be welded by the caller (the readers weld STL; a soup has no shared edges, so nothing is collapsible).
#include "engine/simplify/simplify.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <string>

namespace scanpress {
namespace {

constexpr double kMinBoundaryEdgeWeight = 1.0;
constexpr double kBoundaryPlaneWeight = 4.0;
// Largest condition number (Frobenius norms) of the quadric's 3x3 system for which its optimum is used.
constexpr double kMaxCondition = 1e5;

struct Quadric {
  double a00 = 0, a01 = 0, a02 = 0, a11 = 0, a12 = 0, a22 = 0;
  double b0 = 0, b1 = 0, b2 = 0, c = 0;
  double weight = 0;

  void addPlane(double nx, double ny, double nz, double d, double w) {
    a00 += w * nx * nx, a01 += w * nx * ny, a02 += w * nx * nz;
    a11 += w * ny * ny, a12 += w * ny * nz, a22 += w * nz * nz;
    b0 += w * nx * d, b1 += w * ny * d, b2 += w * nz * d;
    c += w * d * d;
    weight += w;
  }
  void add(const Quadric& q) {
    a00 += q.a00, a01 += q.a01, a02 += q.a02, a11 += q.a11, a12 += q.a12, a22 += q.a22;
    b0 += q.b0, b1 += q.b1, b2 += q.b2, c += q.c, weight += q.weight;
  }
  double eval(double x, double y, double z) const {
    const double r = x * (a00 * x + 2 * (a01 * y + a02 * z + b0)) + y * (a11 * y + 2 * (a12 * z + b1)) +
                     z * (a22 * z + 2 * b2) + c;
    return r > 0 ? r : 0;
  }
};

using Vec3 = std::array<double, 3>;

// std::array's == is a memcmp call here; this one inlines.
inline bool same(const Vec3u& a, const Vec3u& b) { return a[0] == b[0] && a[1] == b[1] && a[2] == b[2]; }

Vec3 sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// A candidate collapse as stored for sorting (24 bytes: candidates are the largest per-pass array). Which end is
// kept follows from the position (the end it lands on, else v0), the error is recomputed when it is taken, and
// v0 < v1 exactly when the edge was interior (see evaluateCandidates).
struct Candidate {
  uint32_t v0;
  uint32_t v1;
  Vec3u position;
  float cost;
};

struct Collapse {
  uint32_t kept;
  uint32_t removed;
  Vec3u position;
  float cost;
  float error;
  uint8_t placement;
};

class Simplifier {
 public:
  Simplifier(const QuantizedMesh& mesh, std::span<const uint8_t> locked, const SimplifyOptions& options,
             std::span<const uint32_t> corner_wedges)
      : options_(options), pos_(mesh.positions), tris_(mesh.triangles) {
    const size_t n = pos_.size();
    if (!corner_wedges.empty()) {
      wedges_.resize(tris_.size());
      for (size_t f = 0; f < tris_.size(); ++f)
        for (int i = 0; i < 3; ++i) wedges_[f][i] = corner_wedges[3 * f + size_t(i)];
    }
    frozen_.assign(n, 0);
    for (size_t v = 0; v < locked.size(); ++v) frozen_[v] = locked[v] ? 1 : 0;
    face_alive_.assign(tris_.size(), 1);
    // Coordinates relative to the box center halve the magnitudes the quadrics square.
    if (n > 0) {
      Vec3u lo = pos_[0], hi = pos_[0];
      for (const Vec3u& p : pos_)
        for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
      lo_ = lo, hi_ = hi;
      for (int a = 0; a < 3; ++a) center_[a] = std::floor((double(lo[a]) + double(hi[a])) / 2);
    }
    quadrics_.assign(n, Quadric{});
    for (size_t f = 0; f < tris_.size(); ++f) {
      const Triangle& t = tris_[f];
      if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || pos_[t[0]] == pos_[t[1]] || pos_[t[1]] == pos_[t[2]] ||
          pos_[t[0]] == pos_[t[2]]) {
        for (uint32_t v : t) frozen_[v] = 1;
        continue;
      }
      const Vec3 p0 = rel(t[0]), p1 = rel(t[1]), p2 = rel(t[2]);
      Vec3 nrm = cross(sub(p1, p0), sub(p2, p0));
      const double len = std::sqrt(dot(nrm, nrm));
      if (len == 0) continue;
      for (double& x : nrm) x /= len;
      Quadric q;
      q.addPlane(nrm[0], nrm[1], nrm[2], -dot(nrm, p0), len / 2);
      for (uint32_t v : t) quadrics_[v].add(q);
    }
    faces_ = tris_.size();
    live_.resize(tris_.size());
    for (size_t f = 0; f < tris_.size(); ++f) live_[f] = uint32_t(f);
    count_.assign(n, 0);
    local_.assign(n, 0);
    for (const Triangle& t : tris_)
      for (uint32_t v : t) count_[v] = 1;
    for (size_t v = 0; v < n; ++v)
      if (count_[v]) verts_.push_back(uint32_t(v));
    kept_pass_.assign(n, 0);
    cand_begin_.assign(n, 0);
    cand_end_.assign(n, 0);
    blocked_.assign(n, 0);
    open_.assign(n, 0);
    complex_.assign(n, 0);
    degree_.assign(n, 0);
    open_nb_.assign(n, {0, 0});
  }

  Simplification run() {
    Simplification out;
    bool first = true;
    while (true) {
      if (options_.target_faces > 0 && faces_ <= options_.target_faces) break;
      uint64_t goal = uint64_t(std::ceil(options_.pass_fraction * double(faces_)));
      if (goal < 1) goal = 1;
      if (options_.target_faces > 0) goal = std::min(goal, faces_ - options_.target_faces);
      buildAdjacency();
      gatherEdges(first);
      first = false;
      evaluateCandidates();
      // Memory: what a pass no longer needs goes before the next array is built (the peak is the evaluation of
      // the second pass: edges and two passes' candidates).
      std::vector<std::array<uint32_t, 3>>().swap(edges_);
      const size_t before = out.collapses.size();
      runPass(goal, out);
      std::vector<uint64_t>().swap(keys_);
      if (out.collapses.size() == before) break;
      out.pass_ends.push_back(uint32_t(out.collapses.size()));
      out.pass_errors.push_back(max_error_);
      out.pass_faces.push_back(faces_);
    }
    out.mesh.positions = std::move(pos_);
    out.mesh.triangles.reserve(faces_);
    for (size_t f = 0; f < tris_.size(); ++f)
      if (face_alive_[f]) {
        out.mesh.triangles.push_back(tris_[f]);
        if (!wedges_.empty()) out.corner_wedges.insert(out.corner_wedges.end(), wedges_[f].begin(), wedges_[f].end());
      }
    return out;
  }

 private:
  Vec3 rel(uint32_t v) const {
    return {double(pos_[v][0]) - center_[0], double(pos_[v][1]) - center_[1], double(pos_[v][2]) - center_[2]};
  }
  Vec3 relOf(const Vec3u& p) const {
    return {double(p[0]) - center_[0], double(p[1]) - center_[1], double(p[2]) - center_[2]};
  }

  // The live triangles and the vertices they use (ascending), and a CSR vertex -> triangles over those vertices.
  // Only what is live is visited, so a pass costs what is left of the mesh.
  void buildAdjacency() {
    size_t m = 0;
    for (uint32_t f : live_)
      if (face_alive_[f]) live_[m++] = f;
    live_.resize(m);
    for (uint32_t v : verts_) count_[v] = 0;
    for (uint32_t f : live_)
      for (uint32_t v : tris_[f]) count_[v]++;
    size_t k = 0;
    offsets_.resize(verts_.size() + 1);
    offsets_[0] = 0;
    for (uint32_t v : verts_) {
      if (count_[v] == 0) continue;
      local_[v] = uint32_t(k);
      offsets_[k + 1] = offsets_[k] + count_[v];
      verts_[k++] = v;
    }
    verts_.resize(k);
    offsets_.resize(k + 1);
    adj_.resize(offsets_[k]);
    for (uint32_t v : verts_) count_[v] = offsets_[local_[v]];
    for (uint32_t f : live_)
      for (uint32_t v : tris_[f]) adj_[count_[v]++] = f;
  }

  std::span<const uint32_t> facesOf(uint32_t v) const {
    const uint32_t i = local_[v];
    return {adj_.data() + offsets_[i], adj_.data() + offsets_[i + 1]};
  }

  // Edges (a < b) with their triangle counts, and per vertex: on an open edge, on a complex edge, its number of
  // edges, its open-edge neighbours. The first pass also adds the open edges' constraint planes.
  void gatherEdges(bool add_boundary_planes) {
    edges_.clear();
    std::vector<uint64_t>& nb = scratch_;
    for (uint32_t v : verts_) {
      open_[v] = complex_[v] = 0;
      degree_[v] = 0;
      nb.clear();
      for (uint32_t f : facesOf(v))
        for (uint32_t w : tris_[f])
          if (w != v) nb.push_back(uint64_t(w) << 32 | f);
      std::sort(nb.begin(), nb.end());
      uint32_t open_count = 0;
      for (size_t i = 0; i < nb.size();) {
        const uint32_t w = uint32_t(nb[i] >> 32);
        size_t j = i + 1;
        while (j < nb.size() && uint32_t(nb[j] >> 32) == w) ++j;
        const uint32_t count = uint32_t(j - i);
        degree_[v]++;
        if (count == 1) {
          if (open_count < 2) open_nb_[v][open_count] = w;
          open_count++;
          if (add_boundary_planes) addBoundaryPlane(v, w, uint32_t(nb[i]));
        } else if (count > 2) {
          complex_[v] = 1;
        }
        if (w > v) edges_.push_back({v, w, count});
        i = j;
      }
      open_[v] = uint8_t(std::min<uint32_t>(open_count, 255));
    }
  }

  void addBoundaryPlane(uint32_t v, uint32_t w, uint32_t f) {
    const Triangle& t = tris_[f];
    const Vec3 p0 = rel(t[0]), p1 = rel(t[1]), p2 = rel(t[2]);
    Vec3 fn = cross(sub(p1, p0), sub(p2, p0));
    const double fl = std::sqrt(dot(fn, fn));
    if (fl == 0) return;
    const Vec3 pv = rel(v), e = sub(rel(w), pv);
    const double el2 = dot(e, e);
    Vec3 m = cross(e, fn);
    const double ml = std::sqrt(dot(m, m));
    if (ml == 0) return;
    for (double& x : m) x /= ml;
    quadrics_[v].addPlane(m[0], m[1], m[2], -dot(m, pv), kBoundaryPlaneWeight * el2);
  }

  bool isBoundary(uint32_t v) const { return open_[v] != 0 || complex_[v] != 0; }

  // cos of the angle at v between the edge (v, w) and v's other open edge; 1 (a spike) when v has not exactly two.
  double boundaryCos(uint32_t v, uint32_t w) const {
    if (open_[v] != 2) return 1;
    const uint32_t u = open_nb_[v][0] == w ? open_nb_[v][1] : open_nb_[v][0];
    const Vec3 pv = rel(v), a = sub(rel(w), pv), b = sub(rel(u), pv);
    const double l = std::sqrt(dot(a, a) * dot(b, b));
    return l > 0 ? dot(a, b) / l : 1;
  }

  Vec3u roundToGrid(const Vec3& p) const {
    Vec3u r;
    for (int a = 0; a < 3; ++a) {
      const double x = std::clamp(p[a] + center_[a], double(lo_[a]), double(hi_[a]));
      r[a] = uint32_t(x + 0.5);  // x >= 0: rounds half up
    }
    return r;
  }

  // Every edge's collapse: its placement, cost and error. An interior edge (two triangles, neither end on a
  // boundary, a complex edge or frozen) costs what it cost in the previous pass unless an end was a kept vertex
  // there (only kept vertices change position or quadric), so its candidate is copied from that pass.
  void evaluateCandidates() {
    std::swap(previous_, candidates_);
    std::vector<Candidate>().swap(candidates_);
    candidates_.reserve(edges_.size());  // at most one per edge, and no growth beyond it
    const bool paper = options_.weights == SimplifyWeights::kShapePreserving;
    const uint32_t last_pass = pass_;
    uint32_t current = UINT32_MAX, old_begin = 0, old_end = 0;
    for (const auto& e : edges_) {
      const uint32_t a = e[0], b = e[1], count = e[2];
      if (a != current) {
        if (current != UINT32_MAX) cand_end_[current] = uint32_t(candidates_.size());
        current = a;
        old_begin = cand_begin_[a], old_end = std::min<uint32_t>(cand_end_[a], uint32_t(previous_.size()));
        cand_begin_[a] = cand_end_[a] = uint32_t(candidates_.size());
      }
      if (frozen_[a] && frozen_[b]) continue;
      const bool interior = count == 2 && !open_[a] && !open_[b] && !complex_[a] && !complex_[b] && !frozen_[a] &&
                            !frozen_[b];
      if (interior && last_pass > 0 && kept_pass_[a] != last_pass && kept_pass_[b] != last_pass) {
        bool found = false;
        for (uint32_t i = old_begin; i < old_end; ++i) {
          const Candidate& p = previous_[i];
          if (p.v0 == a && p.v1 == b) {  // and so interior
            candidates_.push_back(p);
            found = true;
            break;
          }
        }
        if (found) continue;
      }
      int forced = -1;  // 0: kept a at its position, 1: kept b at its position
      if (frozen_[a]) forced = 0;
      if (frozen_[b]) forced = 1;
      double weight = 1;
      const bool ba = isBoundary(a), bb = isBoundary(b);
      // An interior edge between two open-boundary vertices would pinch the surface (in both modes).
      if (count == 2 && open_[a] && open_[b]) continue;
      if (paper) {
        if (count > 2) {
          weight = count;
        } else if (ba != bb) {
          if (count != 2) continue;
          const int want = ba ? 0 : 1;
          if (forced >= 0 && forced != want) continue;  // would pull a boundary vertex inward
          forced = want;
          weight = std::max(1.0, double(degree_[ba ? a : b]) - 1);
        } else if (ba && bb) {
          if (count != 1) continue;
          weight = std::max(kMinBoundaryEdgeWeight, 1 + std::max(boundaryCos(a, b), boundaryCos(b, a)));
        }
        // A complex vertex leaves only along a complex edge.
        if (count <= 2 && forced < 0 && (complex_[a] || complex_[b])) continue;
        if (count <= 2 && forced >= 0 && complex_[forced == 0 ? b : a]) continue;
      }
      Quadric q = quadrics_[a];
      q.add(quadrics_[b]);
      Collapse c;
      if (forced >= 0) {
        c.kept = forced == 0 ? a : b;
        c.removed = forced == 0 ? b : a;
        c.position = pos_[c.kept];
        c.placement = 0;
        const Vec3 p = rel(c.kept);
        const double qe = q.eval(p[0], p[1], p[2]);
        c.cost = float(weight * qe);
        c.error = float(std::sqrt(q.weight > 0 ? qe / q.weight : 0));
      } else {
        const Vec3 pa = rel(a), pb = rel(b);
        double best = q.eval(pa[0], pa[1], pa[2]);
        Vec3u best_pos = pos_[a];
        int which = 0;  // 0 a, 1 b, 2 other
        auto consider = [&](const Vec3u& cand, int kind) {
          const Vec3 p = relOf(cand);
          const double qe = q.eval(p[0], p[1], p[2]);
          if (qe < best) best = qe, best_pos = cand, which = kind;
        };
        consider(pos_[b], 1);
        const Vec3 mid{(pa[0] + pb[0]) / 2, (pa[1] + pb[1]) / 2, (pa[2] + pb[2]) / 2};
        const Vec3u mid_u = roundToGrid(mid);
        if (!options_.endpoints_only && !same(mid_u, pos_[a]) && !same(mid_u, pos_[b])) consider(mid_u, 2);
        Vec3 opt;
        if (!options_.endpoints_only && solve(q, opt)) {
          const Vec3 d = sub(opt, mid), ab = sub(pb, pa);
          if (dot(d, d) <= 4 * dot(ab, ab)) {
            const Vec3u u = roundToGrid(opt);
            if (!same(u, pos_[a]) && !same(u, pos_[b])) consider(u, 2);
          }
        }
        c.kept = which == 1 ? b : a;
        c.removed = which == 1 ? a : b;
        c.position = best_pos;
        c.placement = which == 2 ? 2 : 0;
        c.cost = float(weight * best);
        c.error = float(std::sqrt(q.weight > 0 ? best / q.weight : 0));
      }
      // Over the error bound: not a candidate in this pass (a later pass evaluates the edge again).
      if (!(double(c.error) <= options_.max_error)) continue;
      candidates_.push_back(interior ? Candidate{a, b, c.position, c.cost} : Candidate{b, a, c.position, c.cost});
    }
    if (current != UINT32_MAX) cand_end_[current] = uint32_t(candidates_.size());
  }

  static bool solve(const Quadric& q, Vec3& out) {
    const double a00 = q.a00, a01 = q.a01, a02 = q.a02, a11 = q.a11, a12 = q.a12, a22 = q.a22;
    const double c00 = a11 * a22 - a12 * a12, c01 = a02 * a12 - a01 * a22, c02 = a01 * a12 - a02 * a11;
    const double det = a00 * c00 + a01 * c01 + a02 * c02;
    const double norm2 = a00 * a00 + a11 * a11 + a22 * a22 + 2 * (a01 * a01 + a02 * a02 + a12 * a12);
    if (!(std::abs(det) > 0) || norm2 == 0) return false;
    const double c11 = a00 * a22 - a02 * a02, c12 = a01 * a02 - a00 * a12, c22 = a00 * a11 - a01 * a01;
    const double inv_norm2 = (c00 * c00 + c11 * c11 + c22 * c22 + 2 * (c01 * c01 + c02 * c02 + c12 * c12)) /
                             (det * det);
    if (norm2 * inv_norm2 > kMaxCondition * kMaxCondition) return false;
    const double id = 1 / det;
    out[0] = -(c00 * q.b0 + c01 * q.b1 + c02 * q.b2) * id;
    out[1] = -(c01 * q.b0 + c11 * q.b1 + c12 * q.b2) * id;
    out[2] = -(c02 * q.b0 + c12 * q.b1 + c22 * q.b2) * id;
    return std::isfinite(out[0]) && std::isfinite(out[1]) && std::isfinite(out[2]);
  }

  // Two collapses have disjoint closed one-rings exactly when neither end of the second lies in the closed
  // neighbourhood of the first's closed one-ring; so taking a collapse blocks that neighbourhood, and testing a
  // candidate looks at its two ends only.
  bool free(uint32_t a, uint32_t b) const { return blocked_[a] != pass_ && blocked_[b] != pass_; }
  void block(uint32_t a, uint32_t b) {
    ring_vertices_.clear();
    for (uint32_t v : {a, b})
      for (uint32_t f : facesOf(v))
        for (uint32_t w : tris_[f]) ring_vertices_.push_back(w);
    std::sort(ring_vertices_.begin(), ring_vertices_.end());
    ring_vertices_.erase(std::unique(ring_vertices_.begin(), ring_vertices_.end()), ring_vertices_.end());
    for (uint32_t v : ring_vertices_)
      for (uint32_t f : facesOf(v))
        for (uint32_t w : tris_[f]) blocked_[w] = pass_;
  }

  struct RingEdge {
    uint32_t w;
    uint32_t ck, cr, d;
  };

  bool legal(const Collapse& c) {
    const uint32_t k = c.kept, r = c.removed;
    if (frozen_[r]) return false;
    if (frozen_[k] && !same(c.position, pos_[k])) return false;
    ring_.clear();
    auto entry = [&](uint32_t w) -> RingEdge& {
      for (RingEdge& e : ring_)
        if (e.w == w) return e;
      ring_.push_back({w, 0, 0, 0});
      return ring_.back();
    };
    const Vec3 pk = relOf(c.position);
    // Triangles around r and k: deleted when they hold both; others must keep their orientation, stay
    // non-degenerate, and not duplicate another triangle.
    for (uint32_t v : {k, r}) {
      for (uint32_t f : facesOf(v)) {
        const Triangle& t = tris_[f];
        const bool has_k = t[0] == k || t[1] == k || t[2] == k;
        const bool has_r = t[0] == r || t[1] == r || t[2] == r;
        if (has_k && has_r) {
          if (v == r) continue;  // counted once, from k
          for (uint32_t w : t)
            if (w != k && w != r) {
              RingEdge& e = entry(w);
              e.ck++, e.cr++, e.d++;
            }
          continue;
        }
        for (uint32_t w : t)
          if (w != v) {
            RingEdge& e = entry(w);
            (v == k ? e.ck : e.cr)++;
          }
        Vec3u q[3];
        Vec3 before[3], after[3];
        for (int i = 0; i < 3; ++i) {
          const uint32_t w = t[i];
          before[i] = rel(w);
          q[i] = (w == k || w == r) ? c.position : pos_[w];
          after[i] = (w == k || w == r) ? pk : before[i];
        }
        if (same(q[0], q[1]) || same(q[1], q[2]) || same(q[0], q[2])) return false;
        const Vec3 nb = cross(sub(before[1], before[0]), sub(before[2], before[0]));
        const Vec3 na = cross(sub(after[1], after[0]), sub(after[2], after[0]));
        if (dot(nb, nb) > 0 && !(dot(nb, na) > 0)) return false;
        if (v == r) {
          // The new triangle: k with r's two other corners; a triangle of k with the same corners would be a twin.
          uint32_t o[2], m = 0;
          for (uint32_t w : t)
            if (w != r) o[m++] = w;
          for (uint32_t g : facesOf(k)) {
            const Triangle& s = tris_[g];
            const bool hk = s[0] == k || s[1] == k || s[2] == k;
            const bool hr = s[0] == r || s[1] == r || s[2] == r;
            if (!hk || hr) continue;
            const bool h0 = s[0] == o[0] || s[1] == o[0] || s[2] == o[0];
            const bool h1 = s[0] == o[1] || s[1] == o[1] || s[2] == o[1];
            if (h0 && h1) return false;
          }
        }
      }
    }
    // Edges (k, w) after the collapse: a manifold edge must not become complex, and no edge may vanish (that would
    // cut a boundary chain, a border chain, or a component down to a dangling vertex).
    for (const RingEdge& e : ring_) {
      const uint32_t after = e.ck + e.cr - 2 * e.d;
      if (after > 2 && e.ck <= 2 && e.cr <= 2) return false;
      if (after == 0) return false;
    }
    return wedges_.empty() || wedgesKept(k, r);
  }

  static bool has(const Triangle& t, uint32_t v) { return t[0] == v || t[1] == v || t[2] == v; }
  uint32_t wedgeAt(uint32_t f, uint32_t v) const {
    const Triangle& t = tris_[f];
    return wedges_[f][t[0] == v ? 0 : (t[1] == v ? 1 : 2)];
  }

  // The wedge rules of a collapse of r onto k (simplify.h, corner_wedges).
  bool wedgesKept(uint32_t k, uint32_t r) {
    pairs_.clear();  // (r's wedge, k's wedge, still used after the collapse)
    for (uint32_t f : facesOf(k)) {
      if (!face_alive_[f] || !has(tris_[f], r)) continue;
      const uint32_t wr = wedgeAt(f, r), wk = wedgeAt(f, k);
      bool found = false;
      for (const auto& p : pairs_) {
        if ((p[0] == wr) != (p[1] == wk)) return false;  // M is not one to one
        found |= p[0] == wr;
      }
      if (!found) pairs_.push_back({wr, wk, 0});
      // The third corner's wedge must be used by another of its triangles.
      const Triangle& t = tris_[f];
      const uint32_t x = t[0] != k && t[0] != r ? t[0] : (t[1] != k && t[1] != r ? t[1] : t[2]);
      const uint32_t wx = wedgeAt(f, x);
      bool used = false;
      for (uint32_t g : facesOf(x))
        if (face_alive_[g] && !(has(tris_[g], k) && has(tris_[g], r)) && wedgeAt(g, x) == wx) {
          used = true;
          break;
        }
      if (!used) return false;
    }
    for (uint32_t f : facesOf(r)) {
      if (!face_alive_[f] || has(tris_[f], k)) continue;
      const uint32_t wr = wedgeAt(f, r);
      auto it = std::find_if(pairs_.begin(), pairs_.end(), [&](const auto& p) { return p[0] == wr; });
      if (it == pairs_.end()) return false;  // a wedge of r the deleted triangles do not pair
      (*it)[2] = 1;
    }
    for (uint32_t f : facesOf(k)) {
      if (!face_alive_[f] || has(tris_[f], r)) continue;
      const uint32_t wk = wedgeAt(f, k);
      for (auto& p : pairs_)
        if (p[1] == wk) p[2] = 1;
    }
    for (const auto& p : pairs_)
      if (!p[2]) return false;
    return true;
  }

  void apply(const Collapse& c) {
    const uint32_t k = c.kept, r = c.removed;
    if (!wedges_.empty()) {
      pairs_.clear();  // M (wedgesKept), from the triangles the collapse deletes
      for (uint32_t f : facesOf(k))
        if (face_alive_[f] && has(tris_[f], r)) pairs_.push_back({wedgeAt(f, r), wedgeAt(f, k), 0});
    }
    for (uint32_t f : facesOf(r)) {
      if (!face_alive_[f]) continue;
      Triangle& t = tris_[f];
      if (t[0] == k || t[1] == k || t[2] == k) {
        face_alive_[f] = 0;
        faces_--;
        continue;
      }
      if (!wedges_.empty()) {
        // The moving corner takes k's wedge that the deleted triangles pair with its own (wedgesKept).
        uint32_t& wr = wedges_[f][t[0] == r ? 0 : (t[1] == r ? 1 : 2)];
        for (const auto& p : pairs_)
          if (p[0] == wr) {
            wr = p[1];
            break;
          }
      }
      for (uint32_t& w : t)
        if (w == r) w = k;
    }
    pos_[k] = c.position;
    quadrics_[k].add(quadrics_[r]);
  }

  Collapse expand(const Candidate& s) const {
    Collapse c;
    const bool on_v1 = same(s.position, pos_[s.v1]);
    c.kept = on_v1 ? s.v1 : s.v0;
    c.removed = on_v1 ? s.v0 : s.v1;
    c.position = s.position;
    c.placement = (on_v1 || same(s.position, pos_[s.v0])) ? 0 : 2;
    c.cost = s.cost;
    // As evaluateCandidates computed it (same operands, same order).
    Quadric q = quadrics_[std::min(s.v0, s.v1)];
    q.add(quadrics_[std::max(s.v0, s.v1)]);
    const Vec3 p = relOf(s.position);
    const double qe = q.eval(p[0], p[1], p[2]);
    c.error = float(std::sqrt(q.weight > 0 ? qe / q.weight : 0));
    return c;
  }

  void runPass(uint64_t goal, Simplification& out) {
    ++pass_;
    const size_t n = candidates_.size();
    if (n == 0) return;
    keys_.resize(n);
    for (size_t i = 0; i < n; ++i) {
      uint32_t bits;
      std::memcpy(&bits, &candidates_[i].cost, 4);  // non-negative floats order as their bits
      keys_[i] = (uint64_t(bits) << 32) | i;
    }
    // The cost bound of the pass: 1.5x the cost at the rank of the collapses it needs (about two faces each).
    const size_t rank = std::min<size_t>(n - 1, size_t(goal / 2));
    std::nth_element(keys_.begin(), keys_.begin() + rank, keys_.end());
    const float bound_cost = candidates_[uint32_t(keys_[rank])].cost * 1.5f;
    auto end = std::partition(keys_.begin(), keys_.end(),
                              [&](uint64_t key) { return candidates_[uint32_t(key)].cost <= bound_cost; });
    std::sort(keys_.begin(), end);
    const uint64_t start_faces = faces_;
    const size_t start_collapses = out.collapses.size();
    auto take = [&](std::vector<uint64_t>::iterator from, std::vector<uint64_t>::iterator to) {
      for (auto it = from; it != to; ++it) {
        if (start_faces - faces_ >= goal) break;
        const Candidate& candidate = candidates_[uint32_t(*it)];
        if (!free(candidate.v0, candidate.v1)) continue;
        const Collapse c = expand(candidate);
        if (!legal(c)) continue;
        block(c.kept, c.removed);
        apply(c);
        kept_pass_[c.kept] = pass_;
        out.collapses.push_back({c.kept, c.removed, c.position, c.placement, c.error});
        max_error_ = std::max(max_error_, c.error);
      }
    };
    take(keys_.begin(), end);
    // Nothing legal within the bound (cheap collapses that would all flip or pinch): the pass goes on up the cost
    // order rather than ending the simplification.
    if (out.collapses.size() == start_collapses && end != keys_.end()) {
      std::sort(end, keys_.end());
      take(end, keys_.end());
    }
  }

  SimplifyOptions options_;
  std::vector<Vec3u> pos_;
  std::vector<Triangle> tris_;
  std::vector<uint8_t> face_alive_;
  std::vector<uint8_t> frozen_;  // locked, or a corner of a degenerate input triangle
  std::vector<Quadric> quadrics_;
  Vec3 center_{0, 0, 0};
  Vec3u lo_{}, hi_{};
  uint64_t faces_ = 0;
  float max_error_ = 0;
  uint32_t pass_ = 0;
  std::vector<uint32_t> blocked_;  // per vertex: the last pass whose collapses block it
  std::vector<uint32_t> ring_vertices_;
  // Per pass.
  std::vector<uint32_t> live_;   // triangles alive at the pass's start
  std::vector<uint32_t> verts_;  // vertices they use, ascending
  std::vector<uint32_t> count_, local_, offsets_, adj_;
  std::vector<uint32_t> kept_pass_;  // per vertex: the last pass it was a collapse's kept vertex in (0: none)
  std::vector<uint8_t> open_, complex_;
  std::vector<uint32_t> degree_;
  std::vector<std::array<uint32_t, 2>> open_nb_;
  std::vector<std::array<uint32_t, 3>> edges_;
  std::vector<Candidate> candidates_, previous_;
  std::vector<uint32_t> cand_begin_, cand_end_;  // per vertex a: candidates of its edges (a, b > a)
  std::vector<uint64_t> keys_;
  std::vector<uint64_t> scratch_;
  std::vector<RingEdge> ring_;
  std::vector<std::array<uint32_t, 3>> wedges_;  // per triangle: its corners' wedges (empty: none given)
  std::vector<std::array<uint32_t, 3>> pairs_;
};

}  // namespace

Result<Simplification> simplify(const QuantizedMesh& mesh, std::span<const uint8_t> locked,
                                const SimplifyOptions& options, std::span<const uint32_t> corner_wedges) {
  const size_t n = mesh.positions.size();
  if (!locked.empty() && locked.size() != n)
    return makeError(ErrorCode::kInvalidArgument, "simplify: " + std::to_string(locked.size()) + " lock flags for " +
                                                      std::to_string(n) + " vertices");
  if (n > 0xFFFFFFFFull || mesh.triangles.size() > 0xFFFFFFFFull)
    return makeError(ErrorCode::kLimitExceeded, "simplify: more than 2^32-1 vertices or triangles");
  for (size_t f = 0; f < mesh.triangles.size(); ++f)
    for (uint32_t v : mesh.triangles[f])
      if (v >= n)
        return makeError(ErrorCode::kInvalidArgument, "simplify: triangle " + std::to_string(f) + " indexes vertex " +
                                                          std::to_string(v) + " of " + std::to_string(n));
  if (!(options.pass_fraction > 0 && options.pass_fraction <= 1))
    return makeError(ErrorCode::kInvalidArgument, "simplify: pass_fraction must be in (0, 1]");
  if (!(options.max_error >= 0)) return makeError(ErrorCode::kInvalidArgument, "simplify: max_error must be >= 0");
  if (!corner_wedges.empty() && corner_wedges.size() != 3 * mesh.triangles.size())
    return makeError(ErrorCode::kInvalidArgument, "simplify: " + std::to_string(corner_wedges.size()) +
                                                      " corner wedges for " + std::to_string(mesh.triangles.size()) +
                                                      " triangles");
  Simplifier s(mesh, locked, options, corner_wedges);
  return s.run();
}

}  // namespace scanpress
