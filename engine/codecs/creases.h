// Creases and texture seams through the coarse levels of kdtree and octree (payload version 4; issue 22 part 2). After
// ../shared/papers/attributes-selective-refinement.md §3 (the corner graph and its sharp edges), adapted to a
// hierarchy of cells:
//
// - A tile's points are (position, attributes) pairs, so a vertex with several normals (a crease) or texture
//   coordinates (a seam) is several points at one position: its wedges. A *cut edge* is an edge of a triangle over
//   points whose positions are also joined by a triangle over other points: the two sides of a crease or seam.
// - A coarse level's edge (between two cells) is *sharp* when a cut edge joins points of those cells. Sharpness only
//   refines: an edge whose parent (the edge between the cells it came from at the previous level) exists and is
//   smooth is smooth, so a level codes one flag for each edge inside a cell that split, each edge whose parent was
//   sharp and each edge without a parent, and nothing else. A tile without cut edges is written as version 3.
// - Around a cell, the corners of its triangles that meet across smooth edges form a *group*. A cell of one group is
//   one vertex showing its representative's attributes (attributes.h, CoarseAttributes, unchanged from version 3);
//   a cell of k >= 2 groups is k vertices at its center, one per group (the coarse level's wedges), each showing the
//   attributes of a point at one of the group's corners.
// - A group's attributes: either a *slot* (the cell's representative's, or one of the groups' of the cell it came
//   from at the previous level; a bit and the slot's index) or a new value, the attributes of a point at one of its
//   corners: the normal predicted from the group's triangles at the level (with a flip bit, as version 2's), the
//   colors and scalars from the representative's. The encoder reuses a slot whose point lies at one of the group's
//   corners.
//
// Octree (version 4) shows every three-clique of a level's edges, so its levels carry three more things (Rules):
// which triangles around a crease are the tile's (a clique that is not, a *ghost*, would join groups across the
// crease), which groups of a vertex are one (a vertex's fan cut by a gap into pieces between the same sharp edges:
// without merging, a fine level of a tile cut by its border shows more vertices than the tile has points, and kdtree
// then codes the tile as version 3), and a level that would still show too many shows fewer groups rather than
// failing. Kdtree's version 4 predates the last two rules and keeps its bytes; its version 5 has them (a kdtree level
// has only the projections of the tile's triangles: no ghosts).
//
// Where we depart from the paper: it codes edge types with every vertex split and merges the attributes of a
// contraction into new values; we code the types per level (only where the parent does not decide them) and show
// the scan's own values, as version 3 does. Semi-sharp edges (normals apart, colors not) are sharp here: a group
// carries every attribute of one point. Wedge values are coded again in the lossless level (measured in
// bench/RESULTS.md, "Creases through coarse levels").
#pragma once

#include <algorithm>
#include <numeric>
#include <string>
#include <string_view>

#include "engine/codecs/attributes.h"

namespace scanpress::hierarchy {

constexpr uint16_t kCoarseCreases = 4;
// kdtree v5: v4 with Rules::merges and Rules::fit (octree v4 has them from the start).
constexpr uint16_t kCreaseMerges = 5;

inline u64 edgeKey(u32 a, u32 b) { return a < b ? (u64(a) << 32) | b : (u64(b) << 32) | a; }

// The cut edges of Morton-ordered points (points at one position are consecutive), as point pairs (edgeKey), sorted.
inline std::vector<u64> cutEdges(const Points& pts) {
  const u32 n = u32(pts.pos.size());
  std::vector<u32> first(n);
  for (u32 p = 0; p < n; ++p) first[p] = p > 0 && pts.pos[p] == pts.pos[p - 1] ? first[p - 1] : p;
  std::vector<std::pair<u64, u64>> es;  // (position edge, point edge)
  es.reserve(3 * pts.tri_keys.size());
  for (const TriKey& k : pts.tri_keys)
    for (int j = 0; j < 3; ++j) {
      const u32 a = k[j], b = k[(j + 1) % 3];
      if (first[a] != first[b]) es.push_back({edgeKey(first[a], first[b]), edgeKey(a, b)});
    }
  std::sort(es.begin(), es.end());
  es.erase(std::unique(es.begin(), es.end()), es.end());
  std::vector<u64> cut;
  for (size_t i = 0, j = 0; i < es.size(); i = j) {
    while (j < es.size() && es[j].first == es[i].first) ++j;
    if (j - i > 1)
      for (size_t x = i; x < j; ++x) cut.push_back(es[x].second);
  }
  std::sort(cut.begin(), cut.end());
  return cut;
}

class CoarseCreases {
 public:
  static constexpr u32 kNone = UINT32_MAX;
  static constexpr u32 kPoint = 1u << 31;  // a value that is a point's (points are fewer than 2^26)

  // What differs between the codecs' formats (kdtree v4: none; kdtree v5: merges and fit; octree v4: all three).
  struct Rules {
    // A level's triangles are every three-clique of its edges, not only the projections of the tile's triangles:
    // a level codes which of the triangles around its creases are projections.
    bool cliques = false;
    // A level codes, for each group after the first at a vertex, whether it is one of the vertex's earlier groups
    // (mergeGroups).
    bool merges = false;
    // A level that would show more vertices than the tile has shows fewer groups (endLevel), instead of failing.
    bool fit = false;
  };
  CoarseCreases(const AttributeLayout& layout, u32 n, std::string_view codec, Rules rules)
      : layout_(layout), models_(layout), stride_(size_t(layout.scalarStride())), n_(n), codec_(codec), rules_(rules) {}

  // At the start of the first segment of a version 4 payload with attributes.
  void begin() {
    on_ = true;
    anc_.resize(n_);
    std::iota(anc_.begin(), anc_.end(), 0u);
    count_.assign(n_, 0);
    show_.assign(n_, kNone);
    mark_.assign(n_, 0);
    touch_.assign(n_, 0);
  }
  bool on() const { return on_; }
  // The encoder's: a level it cannot code with its creases (the tile is then coded without them).
  void fail() { failed_ = true; }
  // Whether endLevel failed: a level would show more vertices than allowed, or (encoder) the tile's cut edges do
  // not map onto the level as they should (not seen); the encoder then codes the tile as version 3.
  bool failed() const { return failed_; }
  // Vertex v appears at a split of `parent` (within the level).
  void birth(u32 v, u32 parent) {
    if (!on_) return;
    anc_[v] = anc_[parent];
    show_[v] = show_[parent];
    born_.push_back(v);
  }

  // What a level shows: its triangle keys and, per corner (3 x key + position in the key), the group of the corner
  // within its vertex; per vertex of k >= 2 groups, the groups' values (into values_).
  using Wedged = std::vector<std::array<u32, 3>>;  // (vertex, first value, groups), by vertex
  static const std::array<u32, 3>* findWedged(const Wedged& wedged, u32 v) {
    auto it = std::lower_bound(wedged.begin(), wedged.end(), std::array<u32, 3>{v, 0, 0},
                               [](const auto& a, const auto& b) { return a[0] < b[0]; });
    return it != wedged.end() && (*it)[0] == v ? &*it : nullptr;
  }
  struct Level {
    std::vector<TriKey> keys;
    std::vector<u32> corner_group;
    Wedged wedged;
    const std::array<u32, 3>* find(u32 v) const { return findWedged(wedged, v); }
  };
  const Level& level() const { return level_; }

  // The end of a level's segment (after CoarseAttributes::endLevel). `keys`: the level's triangle keys (sorted,
  // distinct); `cells`: its vertex count; cell_of(point): the cell holding a point (encoder); c2(v): twice the
  // center of cell v; rep(v): the point whose attributes v shows (CoarseAttributes::shown), whose values are in
  // `normals`, `colors`, `scalars` (by point). `max_vertices`: the most the level may show (the header's count).
  // Encoder: `cut` (cutEdges) and `truth`. An error when the level would show more vertices (the encoder then
  // codes the tile without creases).
  template <class Io, class CellOf, class Center2, class Rep>
  Status endLevel(Io& io, std::vector<TriKey> keys, u32 cells, const CellOf& cell_of, const Center2& c2,
                  const Rep& rep, const std::vector<OctNormal>& normals, const std::vector<Rgba8>& colors,
                  const ScalarValues& scalars, const std::vector<u64>* cut, const Points* truth, u32 max_vertices) {
    if (!on_) return Status::ok();
    point_normals_ = &normals, point_colors_ = &colors, point_scalars_ = &scalars;
    const size_t nk = keys.size();
    // The level's edges in order, each with the triangles on it (bucketed by the smaller end, not sorted whole).
    std::vector<std::pair<u64, u32>> on_edge;
    {
      const EdgeThirds adj(keys);
      on_edge.reserve(adj.items.size());
      for (u32 lo = 0; lo + 1 < adj.start.size(); ++lo)
        for (u32 i = adj.start[lo]; i < adj.start[lo + 1]; ++i)
          on_edge.push_back({edgeKey(lo, adj.items[i][0]), adj.items[i][2]});
    }
    std::vector<u64> truth_sharp;
    if (truth) {
      for (u64 e : *cut) {
        const u32 a = cell_of(u32(e >> 32)), b = cell_of(u32(e));
        if (a != b) truth_sharp.push_back(edgeKey(a, b));
      }
      std::sort(truth_sharp.begin(), truth_sharp.end());
    }
    // Sharp flags, where the previous level does not decide them: an edge inside a cell that split, an edge whose
    // parent was sharp and one of whose cells split (one whose cells did not is the same edge), an edge without a
    // parent.
    for (u32 v : born_) mark_[v] = mark_[anc_[v]] = 1;
    std::vector<u64> edges, sharp;
    for (size_t i = 0; i < on_edge.size();) {
      const u64 e = on_edge[i].first;
      while (i < on_edge.size() && on_edge[i].first == e) ++i;
      edges.push_back(e);
      const u32 pa = anc_[u32(e >> 32)], pb = anc_[u32(e)];
      int context = -1;
      bool known_sharp = false;
      if (pa == pb) context = std::binary_search(prev_touch_.begin(), prev_touch_.end(), pa) ? 3 : 0;
      else if (std::binary_search(prev_sharp_.begin(), prev_sharp_.end(), edgeKey(pa, pb)))
        context = mark_[u32(e >> 32)] || mark_[u32(e)] ? 1 : -1, known_sharp = context < 0;
      else if ((mark_[u32(e >> 32)] || mark_[u32(e)]) &&  // (between cells that did not split: an old edge)
               !std::binary_search(prev_edges_.begin(), prev_edges_.end(), edgeKey(pa, pb)))
        context = 2;
      const bool truly = truth && std::binary_search(truth_sharp.begin(), truth_sharp.end(), e);
      if (context < 0) {
        if (truth && truly != known_sharp) {
          for (u32 v : born_) mark_[v] = mark_[anc_[v]] = 0;
          failed_ = true;
          return makeError(ErrorCode::kInternal, codec_ + " encoder: an edge's sharpness changed without a split");
        }
        if (known_sharp) sharp.push_back(e);
        continue;
      }
      if (io.bit(flag_[context], truly ? 1 : 0)) sharp.push_back(e);
    }
    for (u32 v : born_) mark_[v] = mark_[anc_[v]] = 0;
    // Corners that meet across smooth edges: one group (union-find over the corners).
    std::vector<u32> parent(3 * nk);
    std::iota(parent.begin(), parent.end(), 0u);
    const auto find = [&](u32 x) {
      while (parent[x] != x) x = parent[x] = parent[parent[x]];
      return x;
    };
    const auto corner = [&](u32 t, u32 v) {
      const TriKey& k = keys[t];
      return 3 * t + (k[0] == v ? 0 : k[1] == v ? 1 : 2);
    };
    // Only around a vertex on a sharp edge: any other is one group (a non-manifold vertex is not split).
    for (u64 e : sharp) touch_[u32(e >> 32)] = touch_[u32(e)] = 1;
    // Cliques (octree): a flag per triangle with a corner on a sharp edge, whether it is the projection of one of the
    // tile's triangles. One that is not (a *ghost*: three edges of the surface closing a triangle it does not have)
    // would join groups across a crease; it joins none, and each of its corners takes the group of a triangle
    // beside it.
    std::vector<u8> ghost;
    if (rules_.cliques) {
      ghost.assign(nk, 0);
      std::vector<u8> projected;
      if (truth) {
        projected.assign(nk, 0);
        Corners cp;
        u32 t = 0;
        for (const TriKey& f : truth->tri_keys)
          if (project(
                  f, cell_of, keys, [&](u32 v) { return touch_[v] != 0; }, cp, t) == Projection::kFound)
            projected[t] = 1;
      }
      for (u32 t = 0; t < nk; ++t)
        if (touch_[keys[t][0]] || touch_[keys[t][1]] || touch_[keys[t][2]])
          ghost[t] = !io.bit(projection_, truth ? projected[t] : 0);
    }
    const auto isGhost = [&](u32 t) { return !ghost.empty() && ghost[t]; };
    for (size_t i = 0, j = 0; i < on_edge.size(); i = j) {
      const u64 e = on_edge[i].first;
      while (j < on_edge.size() && on_edge[j].first == e) ++j;
      if (!touch_[u32(e >> 32)] && !touch_[u32(e)]) continue;
      if (std::binary_search(sharp.begin(), sharp.end(), e)) continue;
      for (u32 v : {u32(e >> 32), u32(e)}) {
        if (!touch_[v]) continue;
        u32 r0 = kNone;
        for (auto it = on_edge.begin() + ptrdiff_t(i); it != on_edge.begin() + ptrdiff_t(j); ++it) {
          if (isGhost(it->second)) continue;
          if (r0 == kNone) r0 = find(corner(it->second, v));
          else parent[find(corner(it->second, v))] = r0;
        }
      }
    }
    if (!ghost.empty()) {
      // Per vertex on a sharp edge, its first corner of a triangle that is not a ghost, else its first corner.
      std::vector<std::pair<u32, u32>> first_corner;  // (vertex, corner), sorted
      for (u32 c = 0; c < 3 * nk; ++c)
        if (touch_[keys[c / 3][c % 3]]) first_corner.push_back({keys[c / 3][c % 3], ghost[c / 3] ? 3 * nk + c : c});
      std::sort(first_corner.begin(), first_corner.end());
      // Per edge (at the index of its first entry in on_edge), its first triangle that is not a ghost (kNone).
      std::vector<u32> first_kept(on_edge.size(), kNone);
      for (size_t i = 0, j = 0; i < on_edge.size(); i = j) {
        while (j < on_edge.size() && on_edge[j].first == on_edge[i].first) ++j;
        for (size_t x = i; x < j && first_kept[i] == kNone; ++x)
          if (!ghost[on_edge[x].second]) first_kept[i] = on_edge[x].second;
      }
      for (u32 t = 0; t < nk; ++t) {
        if (!ghost[t]) continue;
        for (u32 v : keys[t]) {
          if (!touch_[v]) continue;
          // The first triangle that is not a ghost on one of its two edges at v (smooth or not), else v's first
          // corner as above: no group of its own.
          u32 beside = kNone;
          for (u32 o : keys[t]) {
            if (o == v || beside != kNone) continue;
            const u64 e = edgeKey(v, o);
            const auto it = std::lower_bound(on_edge.begin(), on_edge.end(), std::pair<u64, u32>{e, 0});
            if (it != on_edge.end() && it->first == e) beside = first_kept[size_t(it - on_edge.begin())];
          }
          u32 to = kNone;
          if (beside != kNone) {
            to = corner(beside, v);
          } else {
            const auto it = std::lower_bound(first_corner.begin(), first_corner.end(), std::pair<u32, u32>{v, 0});
            to = it->second >= 3 * nk ? it->second - 3 * nk : it->second;
          }
          parent[find(corner(t, v))] = find(to);
        }
      }
    }
    Level next;
    next.corner_group.assign(3 * nk, 0);
    std::vector<u32> number(3 * nk, kNone);
    std::vector<u32> touched;
    for (u32 c = 0; c < 3 * nk; ++c) {
      const u32 v = keys[c / 3][c % 3];
      if (!touch_[v]) {
        if (count_[v] == 0) touched.push_back(v), count_[v] = 1;
        continue;
      }
      const u32 r = find(c);
      if (number[r] == kNone) {
        if (count_[v] == 0) touched.push_back(v);
        number[r] = count_[v]++;
      }
      next.corner_group[c] = number[r];
    }
    std::sort(touched.begin(), touched.end());
    if (rules_.merges) mergeGroups(io, keys, touched, next.corner_group, cell_of, truth);
    u64 shown = cells;
    for (u32 v : touched) shown += count_[v] - 1;
    for (u64 e : sharp) touch_[u32(e >> 32)] = touch_[u32(e)] = 0;
    const auto reset = [&] {
      for (u32 v : touched) count_[v] = 0;
    };
    if (shown > max_vertices && rules_.fit) {
      // A vertex's corners may be several groups without a crease between them (its fan cut by the tile's border
      // into pieces): a level can show more vertices than the tile has points. The last vertices of several groups
      // then show one each, until the level shows at most the tile's count (at worst one vertex per cell).
      std::vector<u32> merged;
      for (auto it = touched.rbegin(); it != touched.rend() && shown > max_vertices; ++it)
        if (count_[*it] > 1) shown -= count_[*it] - 1, count_[*it] = 1, merged.push_back(*it), mark_[*it] = 1;
      for (u32 c = 0; c < 3 * nk; ++c)
        if (mark_[keys[c / 3][c % 3]]) next.corner_group[c] = 0;
      for (u32 v : merged) mark_[v] = 0;
    }
    if (shown > max_vertices) {
      reset();
      failed_ = true;
      return makeError(truth ? ErrorCode::kInternal : ErrorCode::kMalformed,
                       codec_ + " payload: a coarse level with its creases shows " + std::to_string(shown) +
                           " vertices, more than the tile's " + std::to_string(max_vertices));
    }
    // The vertices whose values are chosen here: the wedged ones and those of the cells that split at this level
    // (a value a cell inherited may come from across a crease now). Each group takes one of its slots' values or a
    // new one. A vertex whose representative was coded at this level (attributes.h, CoarseAttributes) shows it
    // unless chosen here.
    for (u32 v : born_)
      if (rep(v) == v) show_[v] = kNone;
    values_.clear();
    for (u32 v : born_) mark_[v] = mark_[anc_[v]] = 1;
    std::vector<u32> chosen;
    // (With merges, also a vertex whose groups became one: what it showed were its groups' values.)
    for (u32 v : touched)
      if (count_[v] > 1 || mark_[v] || (rules_.merges && findWedged(prev_wedged_, v))) chosen.push_back(v);
    for (u32 v : born_) mark_[v] = mark_[anc_[v]] = 0;
    for (u32 v : chosen) mark_[v] = 1;
    const auto unmark = [&] {
      for (u32 v : chosen) mark_[v] = 0;
    };
    // Encoder: per group of a chosen vertex, the points at its corners (v, group, point), sorted.
    std::vector<std::array<u32, 3>> at_corner;
    if (truth && !chosen.empty())
      for (const TriKey& f : truth->tri_keys) {
        Corners cp;
        u32 t = 0;
        const Projection found = project(
            f, cell_of, keys, [&](u32 v) { return mark_[v] != 0; }, cp, t);
        if (found == Projection::kSkip) continue;
        if (found == Projection::kMissing) {
          reset();
          unmark();
          failed_ = true;
          return makeError(ErrorCode::kInternal, codec_ + " encoder: a coarse triangle without its fine one");
        }
        for (int j = 0; j < 3; ++j)
          if (mark_[cp[j].first]) at_corner.push_back({cp[j].first, next.corner_group[3 * t + j], cp[j].second});
      }
    std::sort(at_corner.begin(), at_corner.end());
    // Per chosen vertex and group, its triangles (for the normal's prediction): (v, group, triangle), sorted.
    std::vector<std::array<u32, 3>> group_tris;
    for (u32 c = 0; c < 3 * nk; ++c)
      if (const u32 v = keys[c / 3][c % 3]; mark_[v]) group_tris.push_back({v, next.corner_group[c], c / 3});
    std::sort(group_tris.begin(), group_tris.end());

    const int nb = layout_.normal_bits, m = layout_.hasNormals() ? (1 << (nb - 1)) - 1 : 0;
    size_t gt = 0;
    std::vector<u32> slots;  // pool indices
    for (u32 v : chosen) {
      const u32 k = count_[v];
      // The slots: what v shows now (its override, else its representative's), then the groups' of the cell it
      // came from.
      slots.clear();
      if (show_[v] != kNone) slots.push_back(show_[v]);
      else if (const u32 r = rep(v); r != kNone) slots.push_back(r | kPoint);
      if (const auto* w = findWedged(prev_wedged_, anc_[v]))
        for (u32 g = 0; g < (*w)[2]; ++g) slots.push_back(prev_values_[(*w)[1] + g]);
      if (k > 1) next.wedged.push_back({v, u32(values_.size()), k});
      for (u32 g = 0; g < k; ++g) {
        const std::array<u32, 3> lo{v, g, 0}, hi{v, g, UINT32_MAX};
        const auto c0 = std::lower_bound(at_corner.begin(), at_corner.end(), lo);
        const auto c1 = std::upper_bound(at_corner.begin(), at_corner.end(), hi);
        // The group's triangles' normal sum (twice the area-weighted normal, on the level's cell centers; each
        // triangle turned to agree with the sum so far: coarse triangles have no orientation of their own).
        while (gt < group_tris.size() && (group_tris[gt][0] < v || (group_tris[gt][0] == v && group_tris[gt][1] < g)))
          ++gt;
        Sum3 sum{0, 0, 0};
        for (size_t x = gt; x < group_tris.size() && group_tris[x][0] == v && group_tris[x][1] == g; ++x) {
          const TriKey& t = keys[group_tris[x][2]];
          const Vec3u &a = c2(t[0]), &b = c2(t[1]), &c = c2(t[2]);
          const int64_t u0 = int64_t(b[0]) - a[0], u1 = int64_t(b[1]) - a[1], u2 = int64_t(b[2]) - a[2];
          const int64_t w0 = int64_t(c[0]) - a[0], w1 = int64_t(c[1]) - a[1], w2 = int64_t(c[2]) - a[2];
          const Sum3 cross{i128(u1) * w2 - i128(u2) * w1, i128(u2) * w0 - i128(u0) * w2, i128(u0) * w1 - i128(u1) * w0};
          // (The sum scaled below 2^70, the cross product is below 2^52: the dot product fits in 128 bits.)
          i128 big = 0;
          for (const i128& x : sum) big = std::max(big, x < 0 ? -x : x);
          int shift = 0;
          while ((big >> shift) >= (i128(1) << 70)) ++shift;
          const bool against =
              (sum[0] >> shift) * cross[0] + (sum[1] >> shift) * cross[1] + (sum[2] >> shift) * cross[2] < 0;
          for (int i = 0; i < 3; ++i) sum[i] += against ? -cross[i] : cross[i];
        }
        const u32 ns = u32(slots.size());
        const u32 predicted = predictSlot(slots, sum, g);
        u32 pick = kNone, truth_point = v;
        if (truth && c0 != c1) {
          // The predicted slot, else the first, whose values lie within the range of the group's corners' points'
          // values (widened): one from across a crease or seam does not.
          rangeOf(*truth, c0, c1);
          if (ns > 0 && admits(slots[predicted])) pick = predicted;
          for (u32 i = 0; i < ns && pick == kNone; ++i)
            if (admits(slots[i])) pick = i;
          if (pick == kNone) truth_point = (*c0)[2];
        } else if (truth && ns > 0) {
          pick = predicted;
        }
        u32 value = kNone;
        if (ns > 0 && io.bit(predicted_[std::min<u32>(ns, 3) - 1], pick == predicted ? 1 : 0)) {
          value = slots[predicted];
        } else if (ns > 0 && io.bit(reuse_[std::min<u32>(ns, 3) - 1], pick != kNone ? 1 : 0)) {
          value = slots[ns > 1 ? std::min(io.uniform(pick == kNone ? 0 : pick, ns), ns - 1) : 0];
        } else {
          value = codeValue(io, sum, ns > 0 ? slots[0] : kNone, truth, truth_point, nb, m);
        }
        if (k > 1) values_.push_back(value);
        else show_[v] = value;
      }
    }
    unmark();
    reset();
    for (u32 v : born_) anc_[v] = v;
    born_.clear();
    prev_edges_ = std::move(edges);
    prev_touch_.clear();
    for (u64 e : sharp) prev_touch_.insert(prev_touch_.end(), {u32(e >> 32), u32(e)});
    std::sort(prev_touch_.begin(), prev_touch_.end());
    prev_touch_.erase(std::unique(prev_touch_.begin(), prev_touch_.end()), prev_touch_.end());
    prev_sharp_ = std::move(sharp);
    next.keys = std::move(keys);
    level_ = std::move(next);
    // The previous level's wedged vertices and their values, for the next level's choices.
    prev_wedged_ = level_.wedged;
    compactPool();
    prev_values_ = values_;
    return Status::ok();
  }

  // A vertex's override: the pool value it shows instead of its representative's (kNone: none).
  u32 showOverride(u32 v) const { return on_ ? show_[v] : kNone; }
  // The values of the level's wedged vertices' groups, into the pool (Level::wedged indexes it).
  u32 groupValue(u32 i) const { return values_[i]; }
  // A value: a point's (kPoint | point: the arrays endLevel was given, by point) or the pool's.
  OctNormal normal(u32 value) const {
    if (!layout_.hasNormals()) return {0, 0};
    return value & kPoint ? (*point_normals_)[value & ~kPoint] : pool_.n[value];
  }
  Rgba8 color(u32 value) const {
    if (!layout_.hasColors()) return {0, 0, 0, 255};
    return value & kPoint ? (*point_colors_)[value & ~kPoint] : pool_.c[value];
  }
  const uint32_t* scalarsOf(u32 value) const {
    return value & kPoint ? point_scalars_->data() + size_t(value & ~kPoint) * stride_
                          : pool_.s.data() + size_t(value) * stride_;
  }

 private:
  // A tile's triangle f at a level (encoder): its corners' cells with their points, by cell (`cp`), and the index of
  // its key in `keys` (`t`). kSkip when two of its corners share a cell or none of its cells is `wanted`; kMissing
  // when its key is not among the level's.
  using Corners = std::array<std::pair<u32, u32>, 3>;
  enum class Projection { kFound, kSkip, kMissing };
  template <class CellOf, class Wanted>
  static Projection project(const TriKey& f, const CellOf& cell_of, const std::vector<TriKey>& keys,
                            const Wanted& wanted, Corners& cp, u32& t) {
    for (int j = 0; j < 3; ++j) cp[j] = {cell_of(f[j]), f[j]};
    if (!wanted(cp[0].first) && !wanted(cp[1].first) && !wanted(cp[2].first)) return Projection::kSkip;
    std::sort(cp.begin(), cp.end());
    if (cp[0].first == cp[1].first || cp[1].first == cp[2].first) return Projection::kSkip;
    const TriKey k{cp[0].first, cp[1].first, cp[2].first};
    const auto it = std::lower_bound(keys.begin(), keys.end(), k);
    if (it == keys.end() || *it != k) return Projection::kMissing;
    t = u32(it - keys.begin());
    return Projection::kFound;
  }

  // The groups of a vertex are the pieces of its fan between sharp edges; a fan cut by a gap (the tile's border, a
  // hole) has more pieces than the vertex has values, and a fine level would show more vertices than the tile has
  // points. So, per vertex of k >= 2 groups, each group g >= 1 codes whether it is one with an earlier group
  // (a bit) and which (uniform over the g before it); the encoder says so when both groups' corners are one point.
  template <class Io, class CellOf>
  void mergeGroups(Io& io, const std::vector<TriKey>& keys, const std::vector<u32>& touched,
                   std::vector<u32>& corner_group, const CellOf& cell_of, const Points* truth) {
    const u32 nk = u32(keys.size());
    std::vector<std::pair<u32, u32>> corners;  // (vertex, corner) of the vertices of several groups
    for (u32 c = 0; c < 3 * nk; ++c)
      if (count_[keys[c / 3][c % 3]] > 1) corners.push_back({keys[c / 3][c % 3], c});
    if (corners.empty()) return;
    std::sort(corners.begin(), corners.end());
    // Encoder: per (vertex, group), the point at all its corners (kNone: several), sorted.
    std::vector<std::array<u32, 3>> point_of;
    if (truth) {
      Corners cp;
      u32 t = 0;
      for (const TriKey& f : truth->tri_keys)
        if (project(
                f, cell_of, keys, [&](u32 v) { return count_[v] > 1; }, cp, t) == Projection::kFound)
          for (int j = 0; j < 3; ++j)  // (a missing key: endLevel fails on it)
            if (count_[cp[j].first] > 1) point_of.push_back({cp[j].first, corner_group[3 * t + j], cp[j].second});
      std::sort(point_of.begin(), point_of.end());
      point_of.erase(std::unique(point_of.begin(), point_of.end()), point_of.end());
    }
    const auto pointOf = [&](u32 v, u32 g) {
      auto it = std::lower_bound(point_of.begin(), point_of.end(), std::array<u32, 3>{v, g, 0});
      if (it == point_of.end() || (*it)[0] != v || (*it)[1] != g) return kNone;
      const u32 p = (*it)[2];
      return ++it != point_of.end() && (*it)[0] == v && (*it)[1] == g ? kNone : p;
    };
    std::vector<u32> to;
    size_t at = 0;
    for (u32 v : touched) {
      const u32 k = count_[v];
      if (k < 2) continue;
      to.assign(k, 0);
      u32 groups = 1;
      for (u32 g = 1; g < k; ++g) {
        u32 same = kNone;
        if (truth)
          if (const u32 p = pointOf(v, g); p != kNone)
            for (u32 h = 0; h < g && same == kNone; ++h)
              if (pointOf(v, h) == p) same = h;
        if (io.bit(merge_[std::min<u32>(g, 2) - 1], same != kNone ? 1 : 0)) {
          const u32 h = g > 1 ? std::min(io.uniform(same == kNone ? 0 : same, g), g - 1) : 0;
          to[g] = to[h];
        } else {
          to[g] = groups++;
        }
      }
      count_[v] = groups;
      while (at < corners.size() && corners[at].first < v) ++at;
      for (; at < corners.size() && corners[at].first == v; ++at)
        corner_group[corners[at].second] = to[corner_group[corners[at].second]];
    }
  }

  // A new value in the pool: the attributes of `truth_point` (encoder), the normal predicted from the group's
  // triangles (`sum`, with a flip bit) else from `base` (a pool value or kNone), colors and scalars from `base`.
  template <class Io>
  u32 codeValue(Io& io, const Sum3& sum, u32 base, const Points* truth, u32 truth_point, int nb, int m) {
    int act = 0;
    OctNormal coded_normal{0, 0};
    if (layout_.hasNormals()) {
      std::array<int, 2> pred = base == kNone ? std::array<int, 2>{0, 0}
                                              : std::array<int, 2>{int(normal(base)[0]) - m, int(normal(base)[1]) - m};
      const std::array<int, 2> actual =
          truth ? std::array<int, 2>{int(truth->normals[truth_point][0]) - m, int(truth->normals[truth_point][1]) - m}
                : std::array<int, 2>{0, 0};
      int flipped = 0;
      if (sum[0] != 0 || sum[1] != 0 || sum[2] != 0)
        pred = flippedPrediction(io, flip_, sum, nb, actual, truth != nullptr, flipped);
      coded_normal = codeNormal(io, models_, nb, pred, actual, truth != nullptr, 0, act);
    }
    Rgba8 coded_color{0, 0, 0, 255};
    if (layout_.hasColors()) {
      int pred[4];
      for (int c = 0; c < 4; ++c)
        pred[c] = base != kNone ? int(colorLevel(color(base)[c], layout_.color_bits))
                  : c == 3      ? (1 << layout_.color_bits) - 1
                                : (1 << layout_.color_bits) / 2;
      coded_color = colorOfLevels(codeColorLevels(io, models_, layout_, pred,
                                                  truth ? &truth->colors[truth_point] : nullptr, 0, act),
                                  layout_);
    }
    const u32 value = u32(pool_.n.size());
    pool_.n.push_back(coded_normal);
    pool_.c.push_back(coded_color);
    pool_.s.resize(pool_.s.size() + stride_);
    size_t offset = 0;
    for (size_t ch = 0; ch < layout_.scalars.size(); ++ch) {
      const ScalarChannel& c = layout_.scalars[ch];
      const int64_t pred = base == kNone ? 0 : channelOrdered(c, scalarsOf(base) + offset);
      const int64_t actual = truth ? channelOrdered(c, truth->scalars.data() + size_t(truth_point) * stride_ + offset)
                                   : 0;
      int cls = 0;
      const int64_t x = codeScalar(io, models_.scalar[ch], codedType(c), pred, actual, 0, cls);
      channelFromOrdered(c, x, pool_.s.data() + size_t(value) * stride_ + offset);
      offset += size_t(scalarTypeWords(c.type));
    }
    return value;
  }
  // The slot a group most likely takes: the one whose normal is nearest its triangles' (either side; in exact
  // integers, L1-normalised as every octahedral vector is), else the g-th of the groups' of the cell it came from.
  u32 predictSlot(const std::vector<u32>& slots, const Sum3& sum, u32 g) const {
    if (slots.empty()) return 0;
    if (layout_.hasNormals() && (sum[0] != 0 || sum[1] != 0 || sum[2] != 0)) {
      const int m = (1 << (layout_.normal_bits - 1)) - 1;
      u32 best = 0;
      i128 best_dot = -1;
      for (u32 i = 0; i < slots.size(); ++i) {
        const OctNormal n = normal(slots[i]);
        const auto d = octahedralVector({int(n[0]) - m, int(n[1]) - m}, m);
        i128 dot = sum[0] * d[0] + sum[1] * d[1] + sum[2] * d[2];
        if (dot < 0) dot = -dot;
        if (dot > best_dot) best_dot = dot, best = i;
      }
      return best;
    }
    return std::min<u32>(g + 1, u32(slots.size()) - 1);
  }

  // Keeps only the pool values something still shows (a group's, a cell's choice), in their order: the pool holds
  // at most one value per cell and group of the level, not every value ever coded.
  void compactPool() {
    if (pool_.n.empty()) return;
    std::vector<u32> remap(pool_.n.size(), kNone);
    Values kept;
    const auto keep = [&](u32& ref) {
      if (ref == kNone || (ref & kPoint)) return;
      if (remap[ref] == kNone) {
        remap[ref] = u32(kept.n.size());
        kept.n.push_back(pool_.n[ref]);
        kept.c.push_back(pool_.c[ref]);
        kept.s.insert(kept.s.end(), pool_.s.begin() + ptrdiff_t(size_t(ref) * stride_),
                      pool_.s.begin() + ptrdiff_t(size_t(ref + 1) * stride_));
      }
      ref = remap[ref];
    };
    for (u32& ref : values_) keep(ref);
    for (u32& ref : show_) keep(ref);
    pool_ = std::move(kept);
  }

  // The values the encoder compares, as doubles: a normal's integer vector on the octahedron, the colors' 8-bit
  // channels, each scalar channel's value (floats') or integer; into `out` (its memory reused). Only comparisons,
  // subtractions and a division by 16 follow: every machine makes the same choices.
  void valuesInto(const OctNormal& n, const Rgba8& c, const uint32_t* s, std::vector<double>& out) const {
    out.clear();
    if (layout_.hasNormals()) {  // in integers (on the octahedron |x| + |y| + |z| = M): the same on every machine
      const int m = (1 << (layout_.normal_bits - 1)) - 1;
      const auto d = octahedralVector({int(n[0]) - m, int(n[1]) - m}, m);
      out.insert(out.end(), {double(d[0]), double(d[1]), double(d[2])});
    }
    for (int ch = 0; ch < layout_.color_channels; ++ch) out.push_back(c[ch]);
    size_t offset = 0;
    for (const ScalarChannel& ch : layout_.scalars) {
      out.push_back(isFloatScalar(ch.type) ? floatChannelValue(ch, s + offset)
                                           : double(scalarOrdered(ch.type, s + offset)));
      offset += size_t(scalarTypeWords(ch.type));
    }
  }
  void poolValuesInto(u32 value, std::vector<double>& out) const {
    valuesInto(normal(value), color(value), scalarsOf(value), out);
  }
  void pointValuesInto(const Points& truth, u32 p, std::vector<double>& out) const {
    valuesInto(layout_.hasNormals() ? truth.normals[p] : OctNormal{0, 0},
               layout_.hasColors() ? truth.colors[p] : Rgba8{0, 0, 0, 255}, truth.scalars.data() + size_t(p) * stride_,
               out);
  }
  // Whether pool value `value` lies in the range of the values of the points [c0, c1) (third entries), widened by
  // its width and at least a floor per value: 0.2 M for a normal's components (about 11 degrees), 24 for a color
  // channel (of 255), 1/16 of the tile's range for a scalar.
  template <class It>
  void rangeOf(const Points& truth, It c0, It c1) {
    if (!floors_known_) {  // once per tile
      floors_known_ = true;
      const size_t first = (layout_.hasNormals() ? 3 : 0) + size_t(layout_.color_channels);
      if (layout_.hasNormals()) floor_.assign(3, 0.2 * double((1 << (layout_.normal_bits - 1)) - 1));
      floor_.insert(floor_.end(), size_t(layout_.color_channels), 24.0);
      for (u32 p = 0; p < truth.pos.size(); ++p) {
        pointValuesInto(truth, p, x_);
        if (p == 0) lo_ = hi_ = x_;
        for (size_t i = first; i < x_.size(); ++i) lo_[i] = std::min(lo_[i], x_[i]), hi_[i] = std::max(hi_[i], x_[i]);
      }
      for (size_t i = first; i < lo_.size(); ++i)
        floor_.push_back(std::isfinite(hi_[i] - lo_[i]) ? (hi_[i] - lo_[i]) / 16 : 0);
    }
    for (It it = c0; it != c1; ++it) {
      pointValuesInto(truth, (*it)[2], x_);
      if (it == c0) lo_ = hi_ = x_;
      for (size_t i = 0; i < x_.size(); ++i) lo_[i] = std::min(lo_[i], x_[i]), hi_[i] = std::max(hi_[i], x_[i]);
    }
    for (size_t i = 0; i < lo_.size(); ++i) {
      const double w = std::max(hi_[i] - lo_[i], floor_[i]);
      lo_[i] -= w, hi_[i] += w;
    }
  }
  bool admits(u32 value) {
    poolValuesInto(value, x_);
    for (size_t i = 0; i < x_.size(); ++i)
      if (!(x_[i] >= lo_[i] && x_[i] <= hi_[i])) return false;
    return true;
  }

 private:
  // Attribute values, one after another (normals and colors one each, scalars stride words).
  struct Values {
    std::vector<OctNormal> n;
    std::vector<Rgba8> c;
    ScalarValues s;
  };

  AttributeLayout layout_;
  AttributeModels models_;
  size_t stride_;
  u32 n_;
  std::string codec_;
  Rules rules_;
  bool on_ = false, failed_ = false, floors_known_ = false;
  // Sharp flags by context: inside a cell that split (0; 3: a cell on a sharp edge), under a sharp edge (1), without
  // a parent (2).
  BitModel flag_[4], predicted_[3], reuse_[3], flip_, projection_, merge_[2];
  std::vector<u32> anc_, count_, born_, show_;
  std::vector<u8> mark_, touch_;
  std::vector<u64> prev_edges_, prev_sharp_;
  std::vector<u32> prev_touch_;  // the vertices on a sharp edge at the previous level
  Level level_;
  Wedged prev_wedged_;                     // the previous level's
  std::vector<u32> values_, prev_values_;  // the wedged vertices' groups' values (pool indices), by Level::wedged
  Values pool_;                            // the values coded so far (new ones)
  const std::vector<OctNormal>* point_normals_ = nullptr;  // the points' values (endLevel's arrays)
  const std::vector<Rgba8>* point_colors_ = nullptr;
  const ScalarValues* point_scalars_ = nullptr;
  std::vector<double> floor_, lo_, hi_, x_;  // encoder: rangeOf's floors, the range, scratch
};

// A coarse level with its creases (CoarseCreases on, its level's keys not empty), appended to `m` (empty): cell i
// (of `cells`) is vertex name(i) of the n the codec names, at position(i); a cell of several groups is a vertex per
// group, each triangle corner the vertex of its group. A cell shows its representative's values (coarse.shown,
// from `normals`, `colors`, `scalars`, by point), a wedged cell its groups' and a chosen cell the chosen ones.
// False, with the attributes left empty, when the level shows no representatives yet (the caller derives them).
template <class Name, class Position>
bool showCreasedLevel(const CoarseCreases& creases, const CoarseAttributes& coarse, u32 n, u32 cells, const Name& name,
                      const Position& position, const AttributeLayout& layout, const std::vector<OctNormal>& normals,
                      const std::vector<Rgba8>& colors, const ScalarValues& scalars, QuantizedMesh& m) {
  const auto& level = creases.level();
  std::vector<u32> index(n, UINT32_MAX);
  for (u32 i = 0; i < cells; ++i) {
    const u32 v = name(i);
    index[v] = u32(m.positions.size());
    const auto* w = level.find(v);
    m.positions.insert(m.positions.end(), w ? (*w)[2] : 1, position(i));
  }
  m.triangles = orientedTriangles(level.keys);
  for (size_t t = 0; t < m.triangles.size(); ++t)
    for (u32& v : m.triangles[t]) {
      const auto& k = level.keys[t];
      v = index[v] + level.corner_group[3 * t + (k[0] == v ? 0 : k[1] == v ? 1 : 2)];
    }
  if (!coarse.showable(cells, name)) return false;
  const size_t stride = size_t(layout.scalarStride());
  const auto append = [&](OctNormal nrm, Rgba8 c, const uint32_t* s) {
    if (layout.hasNormals()) m.normals.push_back(nrm);
    if (layout.hasColors()) m.colors.push_back(c);
    m.scalars.insert(m.scalars.end(), s, s + stride);
  };
  for (u32 i = 0; i < cells; ++i) {
    const u32 v = name(i);
    if (const auto* w = level.find(v)) {
      for (u32 g = 0; g < (*w)[2]; ++g) {
        const u32 x = creases.groupValue((*w)[1] + g);
        append(creases.normal(x), creases.color(x), creases.scalarsOf(x));
      }
    } else if (const u32 x = creases.showOverride(v); x != CoarseCreases::kNone) {
      append(creases.normal(x), creases.color(x), creases.scalarsOf(x));
    } else {
      const u32 r = coarse.shown(v);
      append(layout.hasNormals() ? normals[r] : OctNormal{0, 0}, layout.hasColors() ? colors[r] : Rgba8{0, 0, 0, 255},
             scalars.data() + size_t(r) * stride);
    }
  }
  return true;
}

}  // namespace scanpress::hierarchy
