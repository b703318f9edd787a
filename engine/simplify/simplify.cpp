// TEMPORARY simplifier (replaced at merge by the real one, engine/simplify/simplify.h). It exists only so that the
// `pm` codec can be built and tested before the real simplifier lands; the codec must not depend on its choices.
//
// Shortest legal edge first, no quadrics: the kept vertex stays (placement 0), moves onto the removed vertex
// (placement 1) or to the rounded midpoint (placement 2), whichever is legal first in that order when neither is
// locked. Legal: no locked vertex moved or removed, only manifold edges (one or two faces) whose link condition
// holds, an interior edge between two boundary vertices is not collapsed, no degenerate, duplicate or flipped
// triangle. Passes as the header says (closed one-rings of one pass's collapses are disjoint); a pass ends when
// it removed pass_fraction of its starting faces or ran out of candidates. The error is the distance the moved
// vertices travel (grid cells), not a quadric error.
#include "engine/simplify/simplify.h"

#include <algorithm>
#include <cmath>

namespace scanpress {
namespace {

struct State {
  std::vector<Vec3u> pos;
  std::vector<Triangle> faces;
  std::vector<uint8_t> face_alive;
  std::vector<std::vector<uint32_t>> vf;  // vertex -> faces (may hold dead faces)

  void neighbours(uint32_t v, std::vector<uint32_t>& out) const {
    out.clear();
    for (uint32_t f : vf[v])
      if (face_alive[f])
        for (uint32_t w : faces[f])
          if (w != v) out.push_back(w);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
  }
};

std::array<double, 3> cross(const Vec3u& a, const Vec3u& b, const Vec3u& c) {
  const double e1[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
  const double e2[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
  return {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
}

Triangle sortedTri(Triangle t) {
  std::sort(t.begin(), t.end());
  return t;
}

}  // namespace

Result<Simplification> simplify(const QuantizedMesh& mesh, std::span<const uint8_t> locked,
                                const SimplifyOptions& options) {
  const size_t n = mesh.positions.size();
  if (!locked.empty() && locked.size() != n) return makeError(ErrorCode::kInvalidArgument, "lock flags do not match");
  for (const auto& t : mesh.triangles)
    for (uint32_t v : t)
      if (v >= n) return makeError(ErrorCode::kInvalidArgument, "triangle index out of range");
  auto isLocked = [&](uint32_t v) { return !locked.empty() && locked[v]; };
  State s;
  s.pos = mesh.positions;
  s.faces = mesh.triangles;
  s.face_alive.assign(s.faces.size(), 1);
  s.vf.resize(n);
  for (uint32_t f = 0; f < s.faces.size(); ++f) {
    const Triangle& t = s.faces[f];
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
      s.vf[t[0]].push_back(f);  // kept as it is: its vertices are pinned below
      continue;
    }
    for (uint32_t v : t) s.vf[v].push_back(f);
  }
  std::vector<uint8_t> pinned(n, 0);  // vertices of faces that repeat a vertex: never touched
  for (const auto& t : s.faces)
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2])
      for (uint32_t v : t) pinned[v] = 1;
  uint64_t face_count = s.faces.size();
  Simplification result;
  float max_err = 0;
  std::vector<uint8_t> used(n, 0);
  std::vector<uint32_t> na, nb, tmp;
  while (true) {
    if (options.target_faces && face_count <= options.target_faces) break;
    // Candidate edges, shortest first.
    std::vector<std::pair<uint64_t, std::pair<uint32_t, uint32_t>>> edges;
    for (uint32_t f = 0; f < s.faces.size(); ++f) {
      if (!s.face_alive[f]) continue;
      const Triangle& t = s.faces[f];
      if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;
      for (int i = 0; i < 3; ++i) {
        uint32_t a = t[i], b = t[(i + 1) % 3];
        if (a > b) std::swap(a, b);
        uint64_t d = 0;
        for (int k = 0; k < 3; ++k) {
          const int64_t x = int64_t(s.pos[a][k]) - s.pos[b][k];
          d += uint64_t(x * x);
        }
        edges.push_back({d, {a, b}});
      }
    }
    std::sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
    const uint64_t start_faces = face_count;
    const size_t pass_start = result.collapses.size();
    std::fill(used.begin(), used.end(), 0);
    for (const auto& [d2, e] : edges) {
      if (options.target_faces && face_count <= options.target_faces) break;
      if (double(start_faces - face_count) >= options.pass_fraction * double(start_faces)) break;
      const auto [a, b] = e;
      if (used[a] || used[b] || pinned[a] || pinned[b]) continue;
      if (isLocked(a) && isLocked(b)) continue;
      // Faces on the edge; only manifold edges.
      std::vector<uint32_t> edge_faces;
      for (uint32_t f : s.vf[a])
        if (s.face_alive[f]) {
          const Triangle& t = s.faces[f];
          if (t[0] == b || t[1] == b || t[2] == b) edge_faces.push_back(f);
        }
      if (edge_faces.empty() || edge_faces.size() > 2) continue;
      s.neighbours(a, na);
      s.neighbours(b, nb);
      bool ring_used = false;
      for (uint32_t w : na) ring_used |= used[w] != 0;
      for (uint32_t w : nb) ring_used |= used[w] != 0;
      if (ring_used) continue;
      tmp.clear();
      std::set_intersection(na.begin(), na.end(), nb.begin(), nb.end(), std::back_inserter(tmp));
      std::vector<uint32_t> thirds;
      for (uint32_t f : edge_faces)
        for (uint32_t w : s.faces[f])
          if (w != a && w != b) thirds.push_back(w);
      std::sort(thirds.begin(), thirds.end());
      thirds.erase(std::unique(thirds.begin(), thirds.end()), thirds.end());
      if (thirds != tmp) continue;  // link condition
      // Boundary status: a vertex on an edge with one face.
      auto onBoundary = [&](uint32_t v) {
        std::vector<std::pair<uint32_t, uint32_t>> es;
        for (uint32_t f : s.vf[v])
          if (s.face_alive[f])
            for (int i = 0; i < 3; ++i) {
              uint32_t x = s.faces[f][i], y = s.faces[f][(i + 1) % 3];
              if (x == v || y == v) es.push_back({std::min(x, y), std::max(x, y)});
            }
        std::sort(es.begin(), es.end());
        for (size_t i = 0; i < es.size(); ++i) {
          size_t j = i;
          while (j < es.size() && es[j] == es[i]) ++j;
          if (j - i != 2) return true;
          i = j - 1;
        }
        return false;
      };
      const bool ba = onBoundary(a), bb = onBoundary(b);
      if (ba && bb && edge_faces.size() == 2) continue;
      // Placements to try: (kept, removed, position, index).
      struct Option {
        uint32_t kept, removed;
        Vec3u p;
        uint8_t index;
      };
      std::vector<Option> opts;
      Vec3u mid;
      for (int k = 0; k < 3; ++k) mid[k] = uint32_t((uint64_t(s.pos[a][k]) + s.pos[b][k] + 1) / 2);
      if (isLocked(a) || (ba && !bb)) {
        if (!isLocked(b)) opts.push_back({a, b, s.pos[a], 0});
      } else if (isLocked(b) || (bb && !ba)) {
        opts.push_back({b, a, s.pos[b], 0});
      } else {
        opts.push_back({a, b, s.pos[a], 0});
        opts.push_back({a, b, s.pos[b], 1});
        if (mid != s.pos[a] && mid != s.pos[b]) opts.push_back({a, b, mid, 2});
      }
      const double len = std::sqrt(double(d2));
      bool done = false;
      for (const Option& o : opts) {
        const double err = o.index == 2 ? len / 2 : len;
        if (err > options.max_error) continue;
        // Check every surviving face of kept and removed.
        bool ok = true;
        std::vector<Triangle> after;
        for (uint32_t v : {o.kept, o.removed}) {
          for (uint32_t f : s.vf[v]) {
            if (!s.face_alive[f]) continue;
            const Triangle& t = s.faces[f];
            const bool has_k = t[0] == o.kept || t[1] == o.kept || t[2] == o.kept;
            const bool has_r = t[0] == o.removed || t[1] == o.removed || t[2] == o.removed;
            if (has_k && has_r) continue;
            if (v == o.kept && has_r) continue;
            Triangle nt = t;
            Vec3u old_p[3], new_p[3];
            for (int i = 0; i < 3; ++i) {
              old_p[i] = s.pos[t[i]];
              if (nt[i] == o.removed) nt[i] = o.kept;
              new_p[i] = nt[i] == o.kept ? o.p : s.pos[nt[i]];
            }
            if (new_p[0] == new_p[1] || new_p[1] == new_p[2] || new_p[0] == new_p[2]) ok = false;
            const auto n0 = cross(old_p[0], old_p[1], old_p[2]);
            const auto n1 = cross(new_p[0], new_p[1], new_p[2]);
            if (n0[0] * n1[0] + n0[1] * n1[1] + n0[2] * n1[2] <= 0) ok = false;
            after.push_back(sortedTri(nt));
            if (!ok) break;
          }
          if (!ok) break;
        }
        if (!ok) continue;
        std::sort(after.begin(), after.end());
        if (std::adjacent_find(after.begin(), after.end()) != after.end()) continue;
        // Apply.
        for (uint32_t w : na) used[w] = 1;
        for (uint32_t w : nb) used[w] = 1;
        used[a] = used[b] = 1;
        for (uint32_t f : s.vf[o.removed]) {
          if (!s.face_alive[f]) continue;
          Triangle& t = s.faces[f];
          const bool has_k = t[0] == o.kept || t[1] == o.kept || t[2] == o.kept;
          if (has_k) {
            s.face_alive[f] = 0;
            --face_count;
            continue;
          }
          for (uint32_t& v : t)
            if (v == o.removed) v = o.kept;
          s.vf[o.kept].push_back(f);
        }
        s.vf[o.removed].clear();
        s.pos[o.kept] = o.p;
        EdgeCollapse c;
        c.kept = o.kept;
        c.removed = o.removed;
        c.position = o.p;
        c.placement = o.index;
        c.error = float(err);
        max_err = std::max(max_err, c.error);
        result.collapses.push_back(c);
        done = true;
        break;
      }
      (void)done;
    }
    if (result.collapses.size() == pass_start) break;
    result.pass_ends.push_back(uint32_t(result.collapses.size()));
    result.pass_errors.push_back(max_err);
    result.pass_faces.push_back(face_count);
  }
  result.mesh.positions = s.pos;
  for (uint32_t f = 0; f < s.faces.size(); ++f)
    if (s.face_alive[f]) result.mesh.triangles.push_back(s.faces[f]);
  return result;
}

}  // namespace scanpress
