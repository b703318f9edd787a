// Codec `kdtree` (id 2): progressive lossless coding of arbitrary triangle meshes.
//
// Paper: P.-M. Gandoin, O. Devillers, "Progressive Lossless Compression of Arbitrary Simplicial Complexes",
// SIGGRAPH 2002 (../shared/papers/kdtree-progressive-simplicial-complexes.md).
//
// Geometry (§1.1.2): the points are the tile's distinct vertices. A kd-tree splits cells of the scan's global grid in
// halves along x, y, z in turn; for every split of a cell holding p points, the number in the lower half is coded.
// Connectivity (§2): the decoder keeps a simplicial complex over the current cells (vertices at cell centers, edges
// and triangles of the input projected onto the cells). When a split leaves both halves non-empty, the cell's
// vertex V splits into V1 (lower) and V2 (upper), and the code that follows says how V's star is shared: an edge
// expansion (two cut edges and a side bit, §2.2.1) or a generalized vertex split (codes 1-4 per simplex of the star
// with the two compatibility rules, §2.2.2). The encoder computes those codes fine to coarse by merging cells in
// the exact reverse of the decoder's split order (§2.1), then codes coarse to fine.
//
// Where this departs from the paper, and why:
//  - The tree is aligned to the scan's global grid (root = the smallest grid-aligned cube holding the tile), so
//    that level L means cells of 2^(bits-L) grid cells in every tile and tiles decoded at one level weld together.
//    Progressive levels are these cube levels (three kd splits each); each level is its own range-coder segment so
//    that any level can be decoded from a prefix of the payload.
//  - Counts are coded with adaptive models (the paper: arithmetic coding with uniform probabilities). Context: the
//    cell's count p and where the centroid of the cell's neighbours in the current complex lies relative to the
//    split plane (geometry predicted from connectivity, the paper's "future work"); p = 1 cells use a binary model
//    per axis and centroid bin; p >= 16 codes a ratio bucket adaptively, then the offset uniformly.
//  - Cut edges are not coded through normalized scores but by their rank under the paper's two predictors (the
//    distance criterion |d(N,V1) - d(N,V2)| and the circumradius of V1 V2 N), with adaptive rank models: the models
//    learn how reliable the prediction is on each mesh. The side bit uses the paper's barycenter proximity test.
//  - Generalized vertex split: codes 1/2 are coded as "near / far" from the proximity of the simplex to V1 and V2
//    (the paper's §2.4 prediction), with adaptive models by the split's edge code and the simplex's link degree.
//  - An edge expansion is tried whenever the star's link is one cycle or one path: the encoder checks that the
//    expansion reproduces the true split exactly, otherwise it codes the general split (no manifold test needed).
//  - Vertices at one grid position (different attributes) are split apart after the last level by unit splits.
//  - Orientation and multiplicity (the paper codes unoriented complexes): after the last split, triangles are
//    visited breadth-first across shared edges; each codes whether it has one copy oriented as its parent predicts
//    (almost free on oriented manifolds), one copy the other way, or explicit counts of both orientations.
//  - Attributes (normals, colors) are coded per vertex in the final segment: raw in v1, predicted from the decoded
//    positions, triangles and neighbours in v2 (attributes.h). In v2 coarse levels get normals computed from their
//    triangles and gray colors; from v3 each coarse vertex shows the attributes of a point of its cell, those of
//    the first levels coded at the end of their segments (attributes.h, CoarseAttributes); v4 keeps them at every
//    coarse level: sharp edges, a vertex per group of corners between them, and the groups' values (creases.h);
//    v5 (written only for a tile with creases or texture seams, else v3) also merges a vertex's groups that are one
//    point (a fan cut into pieces by a gap: the tile's border), where v4 fell back to v3.
//
// Payload v1 to v5 (the same layout; they differ in the attributes' coding):
//   varint N (points), varint T (triangles, with multiplicity); if N == 0 nothing follows.
//   u8 k0 (root level), 3 x varint root cell index (coordinate >> (bits - k0)),
//   varint S (= bits - k0 + 1 segments), S x varint segment length, then the segments.
//   Segment i < S-1 holds the splits from level k0+i to k0+i+1 (x, y, z), then (v3) the attributes of the cells it
//   created while there are few, then (v4) the level's sharp flags, (v5) its merges, (v4) its chosen values;
//   segment S-1 the unit splits of coincident vertices, orientation and multiplicity, and the attributes (v3: of
//   the points not coded yet). Each is one range-coder stream.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <string>

#include "engine/codecs/codec.h"
#include "engine/codecs/attributes.h"
#include "engine/codecs/creases.h"
#include "engine/codecs/hierarchy.h"
#include "engine/entropy/range_coder.h"
#include "engine/io/bytes.h"
#include "engine/octahedral.h"

namespace scanpress {
namespace {

using namespace hierarchy;

constexpr u32 kRankEscape = 15;
constexpr int kSmallCounts = 15;  // p in [2, kSmallCounts] has a model per p
inline u64 packPair(u32 a, u32 b) { return a < b ? (u64(a) << 32) | b : (u64(b) << 32) | a; }
inline u32 pairLo(u64 p) { return u32(p >> 32); }
inline u32 pairHi(u64 p) { return u32(p); }

// Number of splits along `axis` after `depth` kd splits from the grid's root (x, y, z in turn).
inline int splitsAlong(int depth, int axis) { return (depth + 2 - axis) / 3; }

// The simplicial complex over the current cells. A cell is named by the index of its first point in kd order,
// which never changes while the cell shrinks; a split keeps the name for the lower half. Every edge is stored at
// both ends, every triangle at its three corners (as the packed pair of the other two).
struct Complex {
  std::vector<std::vector<u32>> nb;
  std::vector<std::vector<u64>> tr;
  void init(size_t n) {
    nb.assign(n, {});
    tr.assign(n, {});
  }
};

// The split codes of one vertex split, in the order the decoder enumerates the star: V's code (3: no edge V1V2,
// 4: edge V1V2), then one code per neighbour (sorted by name), then one per star triangle (sorted pairs).
// Edge codes: 1 V1N, 2 V2N, 3 both, 4 both and triangle V1V2N. Triangle codes: 1 V1NM, 2 V2NM, 3 both.

// Encoder, fine to coarse: merges cell v2 into v1 (the reverse of the split) and appends the split's codes.
void mergeCells(Complex& cx, u32 v1, u32 v2, std::vector<u8>& codes) {
  auto& n1 = cx.nb[v1];
  auto& n2 = cx.nb[v2];
  auto& t1 = cx.tr[v1];
  auto& t2 = cx.tr[v2];
  thread_local std::vector<std::pair<u32, u8>> e;
  thread_local std::vector<std::pair<u64, u8>> t;
  e.clear();
  t.clear();
  bool e12 = false;
  for (u32 n : n1)
    if (n == v2) e12 = true;
    else e.push_back({n, 1});
  for (u32 n : n2)
    if (n != v1) e.push_back({n, 2});
  for (u64 pr : t1) {
    if (pairLo(pr) == v2) e.push_back({pairHi(pr), 4});
    else if (pairHi(pr) == v2) e.push_back({pairLo(pr), 4});
  }
  sortAndMergeFlags(e);
  for (u64 pr : t1)
    if (pairLo(pr) != v2 && pairHi(pr) != v2) t.push_back({pr, 1});
  for (u64 pr : t2)
    if (pairLo(pr) != v1 && pairHi(pr) != v1) t.push_back({pr, 2});
  sortAndMergeFlags(t);

  codes.push_back(e12 ? 4 : 3);
  for (const auto& [n, f] : e) codes.push_back((f & 3) == 3 ? ((f & 4) ? 4 : 3) : ((f & 1) ? 1 : 2));
  for (const auto& [pr, f] : t) codes.push_back(f);

  auto flagOf = [&](u32 n) -> u8 {
    auto it = std::lower_bound(e.begin(), e.end(), std::pair<u32, u8>{n, 0});
    return (it != e.end() && it->first == n) ? it->second : 0;
  };
  for (u32 n : n2) {
    if (n == v1) continue;
    if (flagOf(n) & 1) eraseOne(cx.nb[n], v2);
    else replaceOne(cx.nb[n], v2, v1);
  }
  for (u64 pr : t2) {
    const u32 a = pairLo(pr), b = pairHi(pr);
    if (a == v1 || b == v1) {
      eraseOne(cx.tr[a == v1 ? b : a], packPair(v1, v2));
      continue;
    }
    auto it = std::lower_bound(t.begin(), t.end(), std::pair<u64, u8>{pr, 0});
    if (it->second & 1) {
      eraseOne(cx.tr[a], packPair(v2, b));
      eraseOne(cx.tr[b], packPair(v2, a));
    } else {
      replaceOne(cx.tr[a], packPair(v2, b), packPair(v1, b));
      replaceOne(cx.tr[b], packPair(v2, a), packPair(v1, a));
    }
  }
  n1.clear();
  for (const auto& x : e) n1.push_back(x.first);
  t1.clear();
  for (const auto& x : t) t1.push_back(x.first);
  n2.clear();
  n2.shrink_to_fit();
  t2.clear();
  t2.shrink_to_fit();
}

// Decoder (and encoder's forward pass), coarse to fine: splits v into v (V1) and v2 (V2) by the codes.
void applySplit(Complex& cx, u32 v, u32 v2, const std::vector<u32>& nbrs, const std::vector<u64>& tris, int vcode,
                const std::vector<u8>& ecode, const std::vector<u8>& tcode) {
  auto& nv = cx.nb[v];
  auto& tv = cx.tr[v];
  auto& nv2 = cx.nb[v2];
  auto& tv2 = cx.tr[v2];
  nv.clear();
  tv.clear();
  nv2.clear();
  tv2.clear();
  for (size_t i = 0; i < nbrs.size(); ++i) {
    const u32 n = nbrs[i];
    switch (ecode[i]) {
      case 1: nv.push_back(n); break;
      case 2:
        replaceOne(cx.nb[n], v, v2);
        nv2.push_back(n);
        break;
      default:
        cx.nb[n].push_back(v2);
        nv.push_back(n);
        nv2.push_back(n);
        if (ecode[i] == 4) {
          tv.push_back(packPair(v2, n));
          tv2.push_back(packPair(v, n));
          cx.tr[n].push_back(packPair(v, v2));
        }
    }
  }
  for (size_t j = 0; j < tris.size(); ++j) {
    const u32 a = pairLo(tris[j]), b = pairHi(tris[j]);
    switch (tcode[j]) {
      case 1: tv.push_back(tris[j]); break;
      case 2:
        replaceOne(cx.tr[a], packPair(v, b), packPair(v2, b));
        replaceOne(cx.tr[b], packPair(v, a), packPair(v2, a));
        tv2.push_back(tris[j]);
        break;
      default:
        cx.tr[a].push_back(packPair(v2, b));
        cx.tr[b].push_back(packPair(v2, a));
        tv.push_back(tris[j]);
        tv2.push_back(tris[j]);
    }
  }
  if (vcode == 4) {
    nv.push_back(v2);
    nv2.push_back(v);
  }
}

// What only the encoder knows: the points in kd order, the split codes, triangle copies, attributes.
struct Truth : Points {
  std::vector<u64> cut;                    // cutEdges (creases.h), when the layout has attributes
  std::vector<std::array<u32, 3>> splits;  // (s, s+c, e) of every vertex split, in decoder order
  std::vector<u8> codes;
  std::vector<u32> code_start;  // per split, into codes; one extra entry at the end
};

struct Models {
  BitModel single[3][kCentroidBins];
  std::vector<SymbolModel> small;  // [(p - 2) * 4 + centroid class]
  std::vector<SymbolModel> large;  // by log2 class: ratio bucket of 16
  BitModel op[2];                  // edge expansion (0) or general split (1), by link kind
  BitModel two_cuts;
  std::vector<SymbolModel> rank_first, rank_second;  // by link kind and cut count
  BitModel side_wrong[2];
  BitModel vcode[3];
  std::vector<SymbolModel> edge;  // [vcode - 3][link degree class]
  std::vector<SymbolModel> tri;   // by the number of code-4 edges
  std::vector<SymbolModel> orient;
  Models() {
    for (int p = 2; p <= kSmallCounts; ++p)
      for (int c = 0; c < kCentroidBins; ++c) small.emplace_back(p + 1);
    for (int i = 0; i < 24; ++i) large.emplace_back(16);
    for (int i = 0; i < 3; ++i) rank_first.emplace_back(kRankEscape + 1), rank_second.emplace_back(kRankEscape + 1);
    for (int i = 0; i < 4; ++i) edge.emplace_back(3);
    for (int i = 0; i < 4; ++i) edge.emplace_back(4);
    for (int i = 0; i < 3; ++i) tri.emplace_back(3);
    for (int i = 0; i < 2; ++i) orient.emplace_back(3);
  }
};

// The link of V (the graph of its star triangles' opposite edges), when it is one cycle or one path through all
// of V's neighbours: the only stars an edge expansion can split.
struct Link {
  int kind = 2;               // 0 cycle, 1 path, 2 neither
  std::vector<u32> order;     // neighbour indices along the link (path: from its smaller end)
  std::vector<u32> edge_tri;  // triangle index of link edge t (order[t], order[t+1 mod k])
};

template <class Io>
class Engine {
 public:
  Engine(Io& io, int bits, u32 n, int k0, Vec3u root_lo, const Truth* truth)
      : io_(io), bits_(bits), n_(n), k0_(k0), truth_(truth) {
    cx_.init(n);
    lo_.assign(n, Vec3u{0, 0, 0});
    depth_.assign(n, 0);
    c2_.assign(n, Vec3u{0, 0, 0});
    if (n > 0) {
      setCell(0, root_lo, static_cast<u8>(3 * k0));
      cells_.push_back({0, n});
    }
    level_ = k0;
  }

  // Decodes (or encodes) up to level `target` (bits: everything, lossless).
  Status run(int target) {
    if (n_ == 0) return Status::ok();
    coarse_ = std::make_unique<CoarseAttributes>(layout, version, n_);
    coarse_->birth(0, CoarseAttributes::kNone);
    // v5: a vertex's groups may merge, and a level that would show too many shows fewer (creases.h, Rules).
    creases_ = std::make_unique<CoarseCreases>(layout, n_, "kdtree",
                                               version >= kCreaseMerges
                                                   ? CoarseCreases::Rules{.merges = true, .fit = true}
                                                   : CoarseCreases::Rules{});
    for (int k = k0_; k < bits_ && k < target; ++k) {
      SP_RETURN_IF_ERROR(io_.begin());
      // The creases come last in each level's segment and only coarse levels show them: a decoder going to the
      // last level reads none of them (its segments end there, unread).
      if (k == k0_ && version >= kCoarseCreases && coarse_->active() && (truth_ || target < bits_)) creases_->begin();
      for (int axis = 0; axis < 3; ++axis) {
        const int d = 3 * k + axis;
        next_.clear();
        for (const auto& cell : cells_) SP_RETURN_IF_ERROR(splitCell(cell, d));
        cells_.swap(next_);
      }
      io_.meter(&CodecStats::attribute_bits);
      coarse_->endLevel(io_, u32(cells_.size()), bits_ - (k + 1), truth_, normals_, colors_, scalars_,
                        [&](u32 v) -> const std::vector<u32>& { return cx_.nb[v]; });
      if (creases_->on()) {
        if (truth_) {  // the encoder's cell of each point
          cell_of_.resize(n_);
          for (const Cell& c : cells_) std::fill(cell_of_.begin() + c.s, cell_of_.begin() + c.e, c.s);
        }
        const auto cell_of = [&](u32 point) { return cell_of_[point]; };
        SP_RETURN_IF_ERROR(creases_->endLevel(
            io_, triangleKeys(), u32(cells_.size()), cell_of, [&](u32 v) -> const Vec3u& { return c2_[v]; },
            [&](u32 v) { return coarse_->shown(v); }, normals_, colors_, scalars_, truth_ ? &truth_->cut : nullptr,
            truth_, n_));
      }
      SP_RETURN_IF_ERROR(io_.end());
      level_ = k + 1;
    }
    if (target < bits_) return Status::ok();
    level_ = bits_;
    SP_RETURN_IF_ERROR(io_.begin());
    SP_RETURN_IF_ERROR(splitCoincident());
    SP_RETURN_IF_ERROR(codeTriangles());
    codeAttributes();
    SP_RETURN_IF_ERROR(io_.end());
    complete_ = true;
    if (truth_ && split_index_ != truth_->splits.size())
      return makeError(ErrorCode::kInternal, "kdtree encoder: split sequence mismatch");
    return Status::ok();
  }

  // The mesh of the level reached: cells at their centers (lossless at the last level).
  // Moves the lossless level's arrays out (the engine is done with them): held once at the decoder's peak.
  QuantizedMesh mesh(const AttributeLayout& layout) {
    QuantizedMesh m;
    if (n_ == 0) return m;
    // The lossless level once its segment is decoded (a tile whose points share one grid position has k0 = bits:
    // its root level is the last level's cells, but not yet its points).
    if (complete_) {
      m.positions = std::move(lo_);
      m.triangles = std::move(triangles_);
      m.normals = std::move(normals_);
      m.colors = std::move(colors_);
      m.scalars = std::move(scalars_);
      return m;
    }
    const auto position = [&](u32 i) {
      Vec3u p = lo_[cells_[i].s];
      for (int a = 0; a < 3; ++a) p[a] += (1u << (bits_ - splitsAlong(depth_[cells_[i].s], a))) >> 1;
      return p;
    };
    const auto name = [&](u32 i) { return cells_[i].s; };
    // Version 4: a cell of several groups of corners (its creases and seams) shows a vertex per group, and a cell
    // may show a value chosen for it instead of its representative's (creases.h).
    if (creases_ && creases_->on() && !creases_->level().keys.empty()) {
      if (!showCreasedLevel(*creases_, *coarse_, n_, u32(cells_.size()), name, position, layout, normals_, colors_,
                            scalars_, m))
        deriveAttributes(m, layout);
      return m;
    }
    std::vector<u32> index(n_, UINT32_MAX);
    for (u32 i = 0; i < cells_.size(); ++i) {
      index[cells_[i].s] = static_cast<u32>(m.positions.size());
      m.positions.push_back(position(i));
    }
    m.triangles = orientedTriangles(triangleKeys());
    for (auto& t : m.triangles)
      for (auto& v : t) v = index[v];
    // Version 3: each cell shows its representative's attributes (attributes.h, CoarseAttributes).
    if (!coarse_ || !coarse_->show(u32(cells_.size()), name, normals_, colors_, scalars_, m))
      deriveAttributes(m, layout);
    return m;
  }

  bool creasesFailed() const { return creases_ && creases_->failed(); }

  AttributeLayout layout;            // set by the caller before run()
  uint16_t version = kCreaseMerges;  // the payload's (attribute coding)

 private:
  struct Cell {
    u32 s, e;
  };

  // Cell position and depth; c2_ holds twice the center (exact in integers), the only thing neighbours read.
  void setCell(u32 v, const Vec3u& lo, u8 depth) {
    lo_[v] = lo;
    depth_[v] = depth;
    for (int a = 0; a < 3; ++a) c2_[v][a] = 2 * lo[a] + (1u << (bits_ - splitsAlong(depth, a)));
  }
  double center(u32 v, int a) const { return 0.5 * double(c2_[v][a]); }
  Vec3d center(u32 v) const { return {center(v, 0), center(v, 1), center(v, 2)}; }
  static double dist(const Vec3d& a, const Vec3d& b) {
    return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
  }

  // Neighbours are read afresh at every split: caching the centroid per level (reused for the level's three
  // axes) cost 5% of the geometry bits on bunny and igea for no measurable time.
  int centroidBin(u32 v, int axis, double plane, double half) const {
    return hierarchy::centroidBin(cx_.nb[v], c2_, axis, plane, half);
  }

  Status splitCell(const Cell& cell, int d) {
    const u32 p = cell.e - cell.s;
    const int axis = d % 3;
    const u32 size = 1u << (bits_ - splitsAlong(d, axis));
    const u32 half = size >> 1;
    const u32 truth_c = truth_ ? lowerHalf(truth_->pos, cell.s, cell.e, axis, bits_ - 1 - splitsAlong(d, axis)) : 0;
    io_.meter(&CodecStats::geometry_bits);
    const int bin = centroidBin(cell.s, axis, double(lo_[cell.s][axis]) + half, double(half));
    u32 c;
    if (p == 1) {
      c = io_.bit(models_.single[axis][bin], truth_c == 0 ? 1 : 0) ? 0 : 1;
    } else if (p <= kSmallCounts) {
      c = io_.sym(models_.small[(p - 2) * kCentroidBins + bin], truth_c);
    } else {
      int lg = 0;
      while ((p >> (lg + 1)) != 0) ++lg;
      auto& model = models_.large[std::min(lg - 4, 23)];
      const u64 q = u64(p) + 1;
      const u32 b = io_.sym(model, static_cast<u32>(u64(truth_c) * 16 / q));
      const u32 c_lo = static_cast<u32>((u64(b) * q + 15) / 16);
      const u32 c_hi = static_cast<u32>((u64(b + 1) * q + 15) / 16);  // exclusive
      c = c_lo + io_.uniform(truth_c - c_lo, c_hi - c_lo);
    }
    Vec3u left = lo_[cell.s], right = left;
    right[axis] += half;
    const u8 nd = static_cast<u8>(d + 1);
    if (c == p || c == 0) {
      setCell(cell.s, c == p ? left : right, nd);
      next_.push_back(cell);
      return Status::ok();
    }
    const u32 v2 = cell.s + c;
    setCell(cell.s, left, nd);
    setCell(v2, right, nd);
    coarse_->birth(v2, cell.s);
    creases_->birth(v2, cell.s);
    next_.push_back({cell.s, v2});
    next_.push_back({v2, cell.e});
    return splitVertex(cell.s, v2, cell.e);
  }

  // After the last level: vertices that share a grid position (different attributes) split one by one.
  Status splitCoincident() {
    std::vector<Cell> work;
    for (const auto& c : cells_)
      if (c.e - c.s > 1) work.push_back(c);
    while (!work.empty()) {
      std::vector<Cell> rest;
      for (const auto& c : work) {
        const u32 v2 = c.s + 1;
        setCell(v2, lo_[c.s], depth_[c.s]);
        SP_RETURN_IF_ERROR(splitVertex(c.s, v2, c.e));
        if (c.e - v2 > 1) rest.push_back({v2, c.e});
      }
      work.swap(rest);
    }
    return Status::ok();
  }

  void analyseLink(const std::vector<u32>& nbrs, const std::vector<u64>& tris, std::vector<int>& tri_a,
                   std::vector<int>& tri_b, std::vector<u8>& link_degree, Link& link) {
    const size_t k = nbrs.size();
    link.kind = 2;
    link.order.clear();
    link.edge_tri.clear();
    auto indexOf = [&](u32 id) -> int {
      auto it = std::lower_bound(nbrs.begin(), nbrs.end(), id);
      return (it != nbrs.end() && *it == id) ? int(it - nbrs.begin()) : -1;
    };
    auto& adj = adj_;
    auto& adj_tri = adj_tri_;
    adj.assign(k, {-1, -1});
    adj_tri.assign(k, {-1, -1});
    link_degree.assign(k, 0);
    tri_a.resize(tris.size());
    tri_b.resize(tris.size());
    bool ok = k >= 2;
    for (size_t j = 0; j < tris.size(); ++j) {
      const int a = indexOf(pairLo(tris[j])), b = indexOf(pairHi(tris[j]));
      tri_a[j] = a;
      tri_b[j] = b;
      if (a < 0 || b < 0) {
        ok = false;
        continue;
      }
      for (int x : {a, b}) {
        if (link_degree[x] < 2) {
          adj[x][link_degree[x]] = (x == a) ? b : a;
          adj_tri[x][link_degree[x]] = int(j);
        } else {
          ok = false;
        }
        if (link_degree[x] < 255) ++link_degree[x];
      }
    }
    auto fail = [&] {
      link.kind = 2;
      link.order.clear();
      link.edge_tri.clear();
    };
    if (!ok) return;
    int ends = 0, start = -1;
    for (size_t i = 0; i < k; ++i) {
      if (link_degree[i] == 0) return;
      if (link_degree[i] == 1) {
        ++ends;
        if (start < 0) start = int(i);
      }
    }
    if (ends != 0 && ends != 2) return;
    const bool cycle = ends == 0;
    if (cycle) {
      start = 0;
      if (adj[0][1] < adj[0][0]) {  // walk first towards the smaller of the start's two link neighbours
        std::swap(adj[0][0], adj[0][1]);
        std::swap(adj_tri[0][0], adj_tri[0][1]);
      }
    }
    int prev = -1, cur = start;
    for (size_t step = 0;; ++step) {
      link.order.push_back(u32(cur));
      if (step + 1 == k) break;
      int nxt = -1, via = -1;
      for (int s = 0; s < link_degree[cur]; ++s)
        if (adj[cur][s] != prev) {
          nxt = adj[cur][s];
          via = adj_tri[cur][s];
          break;
        }
      if (nxt < 0) return fail();
      link.edge_tri.push_back(u32(via));
      prev = cur;
      cur = nxt;
    }
    if (cycle) {  // the closing link edge, back to the start
      int via = -1;
      for (int s = 0; s < 2; ++s)
        if (adj[cur][s] == start && adj[cur][s] != prev) via = adj_tri[cur][s];
      if (via < 0) return fail();
      link.edge_tri.push_back(u32(via));
    }
    // The walk must have visited every neighbour once.
    auto& seen = seen_;
    seen.assign(k, 0);
    for (u32 x : link.order) {
      if (seen[x]) return fail();
      seen[x] = 1;
    }
    link.kind = cycle ? 0 : 1;
    return;
  }

  // Codes of the edge expansion with cuts at link positions cut[0] (< cut[1] when two), `side` 0: runs of class A
  // (the first run, and the third of a path) go to V1.
  static void expansionCodes(const Link& link, const int* cut, int ncuts, int side, size_t ntris,
                             std::vector<u8>& ecode, std::vector<u8>& tcode) {
    const size_t k = link.order.size();
    const size_t nedges = link.edge_tri.size();
    tcode.assign(ntris, 0);
    const u8 code_a = side ? 2 : 1, code_b = side ? 1 : 2;
    auto runClassA = [&](size_t t) {
      if (link.kind == 0) return !(int(t) >= cut[0] && int(t) < cut[1]);
      if (ncuts == 1) return int(t) < cut[0];
      return int(t) < cut[0] || int(t) >= cut[1];
    };
    for (size_t t = 0; t < nedges; ++t) tcode[link.edge_tri[t]] = runClassA(t) ? code_a : code_b;
    for (size_t q = 0; q < k; ++q) {
      u8 code;
      if (int(q) == cut[0] || (ncuts == 2 && int(q) == cut[1])) {
        code = 4;
      } else {
        const size_t t = (q < nedges) ? q : q - 1;  // a link edge at this node (path end: the only one)
        code = runClassA(t) ? code_a : code_b;
      }
      ecode[link.order[q]] = code;
    }
  }

  u32 codeRank(SymbolModel& model, u32 r, u32 count) {
    u32 s = io_.sym(model, std::min(r, kRankEscape));
    if (s == kRankEscape)
      s += io_.uniform(r - std::min(r, kRankEscape), count > kRankEscape ? count - kRankEscape : 1);
    return s;
  }

  Status splitVertex(u32 v, u32 v2, u32 e) {
    ++splits_;
    const u8* truth_codes = nullptr;
    if (truth_) {
      if (split_index_ >= truth_->splits.size() || truth_->splits[split_index_] != std::array<u32, 3>{v, v2, e})
        return makeError(ErrorCode::kInternal, "kdtree encoder: split sequence mismatch");
      truth_codes = truth_->codes.data() + truth_->code_start[split_index_];
      const size_t len = truth_->code_start[split_index_ + 1] - truth_->code_start[split_index_];
      if (len != 1 + cx_.nb[v].size() + cx_.tr[v].size())
        return makeError(ErrorCode::kInternal, "kdtree encoder: star mismatch");
    }
    ++split_index_;
    io_.meter(&CodecStats::connectivity_bits);
    auto& nbrs = nbrs_;
    auto& tris = tris_;
    nbrs.assign(cx_.nb[v].begin(), cx_.nb[v].end());
    tris.assign(cx_.tr[v].begin(), cx_.tr[v].end());
    std::sort(nbrs.begin(), nbrs.end());
    std::sort(tris.begin(), tris.end());
    const size_t k = nbrs.size(), m = tris.size();
    auto& ecode = ecode_;
    auto& tcode = tcode_;
    ecode.assign(k, 0);
    tcode.assign(m, 0);
    auto& tri_a = tri_a_;
    auto& tri_b = tri_b_;
    auto& link_degree = link_degree_;
    auto& link = link_;
    analyseLink(nbrs, tris, tri_a, tri_b, link_degree, link);
    const Vec3d p1 = center(v), p2 = center(v2);
    auto& pn = pn_;
    pn.resize(k);
    for (size_t i = 0; i < k; ++i) pn[i] = center(nbrs[i]);

    int vcode = 3;
    bool expansion = false;
    int cut[2] = {-1, -1}, ncuts = 0, side = 0;
    if (truth_codes && link.kind != 2 && truth_codes[0] == 4) {
      // Is the true split an edge expansion? Its cuts are the code-4 neighbours.
      bool fits = true;
      for (size_t j = 0; j < m; ++j) fits &= truth_codes[1 + k + j] <= 2;
      for (size_t q = 0; q < k && fits; ++q) {
        const u8 c = truth_codes[1 + link.order[q]];
        if (c == 3) fits = false;
        if (c == 4) {
          if (ncuts == 2) fits = false;
          else cut[ncuts++] = int(q);
        }
      }
      fits &= link.kind == 0 ? ncuts == 2 : ncuts >= 1;
      for (int s = 0; s < 2 && fits && !expansion; ++s) {
        auto& ec = ec_;
        auto& tc = tc_;
        ec.assign(k, 0);
        expansionCodes(link, cut, ncuts, s, m, ec, tc);
        if (std::equal(ec.begin(), ec.end(), truth_codes + 1) && std::equal(tc.begin(), tc.end(), truth_codes + 1 + k)) {
          expansion = true;
          side = s;
        }
      }
    }
    if (link.kind != 2) expansion = io_.bit(models_.op[link.kind], expansion ? 0 : 1) == 0;
    if (expansion) {
      ++expansions_;
      vcode = 4;
      SP_RETURN_IF_ERROR(codeExpansion(link, p1, p2, pn, m, cut, ncuts, side));
      expansionCodes(link, cut, ncuts, side, m, ecode, tcode);
    } else {
      vcode = 3 + io_.bit(models_.vcode[link.kind], truth_codes ? truth_codes[0] == 4 : 0);
      for (size_t i = 0; i < k; ++i) {
        const u8 near = dist(pn[i], p1) <= dist(pn[i], p2) ? 1 : 2;
        u32 truth_sym = 0;
        if (truth_codes) {
          const u8 c = truth_codes[1 + i];
          truth_sym = c == near ? 0 : (c <= 2 ? 1 : c - 1);
          if (vcode == 3 && c == 4) return makeError(ErrorCode::kInternal, "kdtree encoder: inconsistent codes");
        }
        const int ldc = std::min<int>(link_degree[i], 3);
        const u32 s = io_.sym(models_.edge[(vcode - 3) * 4 + ldc], truth_sym);
        ecode[i] = s == 0 ? near : (s == 1 ? 3 - near : u8(s + 1));
      }
      for (size_t j = 0; j < m; ++j) {
        const u8 ca = tri_a[j] >= 0 ? ecode[tri_a[j]] : 3, cb = tri_b[j] >= 0 ? ecode[tri_b[j]] : 3;
        if (ca == 1 || cb == 1) tcode[j] = 1;
        else if (ca == 2 || cb == 2) tcode[j] = 2;
        else {
          const Vec3d pa = center(pairLo(tris[j])), pb = center(pairHi(tris[j]));
          const Vec3d mid{(pa[0] + pb[0]) / 2, (pa[1] + pb[1]) / 2, (pa[2] + pb[2]) / 2};
          const u8 near = dist(mid, p1) <= dist(mid, p2) ? 1 : 2;
          u32 truth_sym = 0;
          if (truth_codes) {
            const u8 c = truth_codes[1 + k + j];
            truth_sym = c == near ? 0 : (c == 3 ? 2 : 1);
          }
          const u32 s = io_.sym(models_.tri[(ca == 4) + (cb == 4)], truth_sym);
          tcode[j] = s == 0 ? near : (s == 1 ? 3 - near : 3);
        }
      }
    }
    if (truth_codes) {
      if (vcode != truth_codes[0] || !std::equal(ecode.begin(), ecode.end(), truth_codes + 1) ||
          !std::equal(tcode.begin(), tcode.end(), truth_codes + 1 + k))
        return makeError(ErrorCode::kInternal, "kdtree encoder: split codes do not reproduce the mesh");
    }
    applySplit(cx_, v, v2, nbrs, tris, vcode, ecode, tcode);
    return Status::ok();
  }

  Status codeExpansion(const Link& link, const Vec3d& p1, const Vec3d& p2, const std::vector<Vec3d>& pn, size_t m,
                       int* cut, int& ncuts, int& side) {
    const size_t k = link.order.size();
    // Rank the link's nodes by the paper's two predictors (lower is likelier to be a cut).
    const double len = std::max(dist(p1, p2), 1e-9);
    auto& score = score_;
    score.resize(k);
    for (size_t q = 0; q < k; ++q) {
      const Vec3d& n = pn[link.order[q]];
      const double a = dist(n, p1), b = dist(n, p2);
      const double s = (a + b + len) / 2;
      const double area2 = std::max(s * (s - a) * (s - b) * (s - len), 0.0);
      const double radius = area2 > 0 ? a * b * len / (4 * std::sqrt(area2)) : 1e9 * len;
      score[q] = {std::fabs(a - b) / len + std::min(radius / len, 1e6), u32(q)};
    }
    std::sort(score.begin(), score.end());
    auto& rank = rank_;
    rank.resize(k);
    for (size_t r = 0; r < k; ++r) rank[score[r].second] = u32(r);

    const int kind = link.kind;
    if (kind == 1) ncuts = 1 + io_.bit(models_.two_cuts, ncuts == 2);
    else ncuts = 2;
    const int model_index = kind == 0 ? 0 : (ncuts == 2 ? 1 : 2);
    if (ncuts == 2) {
      const u32 ra = truth_ ? std::min(rank[cut[0]], rank[cut[1]]) : 0;
      const u32 rb = truth_ ? std::max(rank[cut[0]], rank[cut[1]]) : 0;
      const u32 da = codeRank(models_.rank_first[model_index], ra, u32(k));
      if (da + 1 >= k) return makeError(ErrorCode::kMalformed, "kdtree payload: cut edge out of range");
      const u32 db = da + 1 + codeRank(models_.rank_second[model_index], rb - ra - 1, u32(k - da - 1));
      if (db >= k) return makeError(ErrorCode::kMalformed, "kdtree payload: cut edge out of range");
      cut[0] = int(std::min(score[da].second, score[db].second));
      cut[1] = int(std::max(score[da].second, score[db].second));
    } else {
      const u32 da = codeRank(models_.rank_first[model_index], truth_ ? rank[cut[0]] : 0, u32(k));
      if (da >= k) return makeError(ErrorCode::kMalformed, "kdtree payload: cut edge out of range");
      cut[0] = int(score[da].second);
      cut[1] = -1;
    }
    // Side: which class of runs goes to V1, predicted by the barycenters of the two classes' link edges.
    auto& ec = ec_;
    auto& tc = tc_;
    ec.assign(k, 0);
    expansionCodes(link, cut, ncuts, 0, m, ec, tc);
    Vec3d ba{0, 0, 0}, bb{0, 0, 0};
    int na = 0, nb = 0;
    const size_t nedges = link.edge_tri.size();
    for (size_t t = 0; t < nedges; ++t) {
      const Vec3d& x = pn[link.order[t]];
      const Vec3d& y = pn[link.order[(t + 1) % k]];
      Vec3d& acc = tc[link.edge_tri[t]] == 1 ? ba : bb;
      (tc[link.edge_tri[t]] == 1 ? na : nb)++;
      for (int a = 0; a < 3; ++a) acc[a] += (x[a] + y[a]) / 2;
    }
    int pred = 0, ctx = 1;
    if (na > 0 && nb > 0) {
      for (int a = 0; a < 3; ++a) ba[a] /= na, bb[a] /= nb;
      pred = dist(p1, ba) + dist(p2, bb) <= dist(p1, bb) + dist(p2, ba) ? 0 : 1;
      ctx = 0;
    }
    side = pred ^ io_.bit(models_.side_wrong[ctx], side != pred);
    return Status::ok();
  }

  // Sorted final triangles (a < b < c) of the complex.
  std::vector<std::array<u32, 3>> triangleKeys() const {
    std::vector<std::array<u32, 3>> keys;
    for (u32 v = 0; v < n_; ++v)  // cells that do not exist (yet) have empty lists
      for (u64 pr : cx_.tr[v])
        if (v < pairLo(pr)) keys.push_back({v, pairLo(pr), pairHi(pr)});
    std::sort(keys.begin(), keys.end());
    keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
    return keys;
  }

  // Orientation and multiplicity of the final triangles.
  // The complex's per-vertex lists are the largest structure (about 180 bytes per vertex of a mesh) and are not
  // needed once the keys are read from them: freed before the triangles are coded, which is the decoder's peak
  // (FORMAT.md, the payload floor).
  Status codeTriangles() {
    io_.meter(&CodecStats::connectivity_bits);
    std::vector<std::array<u32, 3>> keys = triangleKeys();
    cx_ = Complex();
    return codeFaceCopies(io_, "kdtree", models_.orient.data(), keys, truth_, max_triangles_, triangles_);
  }

  void codeAttributes() {
    io_.meter(&CodecStats::attribute_bits);
    codeTileAttributes(io_, version, layout, lo_, triangles_, truth_, normals_, colors_, scalars_, coarse_->coded());
  }

 public:
  u64 max_triangles_ = kMaxTriangles;
  u64 splits_ = 0, expansions_ = 0;

 private:
  Io& io_;
  int bits_;
  u32 n_;
  int k0_;
  const Truth* truth_;
  Models models_;
  Complex cx_;
  std::vector<Vec3u> lo_;
  std::vector<u8> depth_;
  std::vector<Vec3u> c2_;
  // Scratch of one vertex split, kept to avoid allocations.
  std::vector<u32> nbrs_, rank_;
  std::vector<u64> tris_;
  std::vector<u8> ecode_, tcode_, ec_, tc_, link_degree_, seen_;
  std::vector<int> tri_a_, tri_b_;
  std::vector<Vec3d> pn_;
  std::vector<std::pair<double, u32>> score_;
  std::vector<std::array<int, 2>> adj_, adj_tri_;
  Link link_;
  std::vector<Cell> cells_, next_;
  size_t split_index_ = 0;
  int level_ = 0;
  bool complete_ = false;
  std::vector<Triangle> triangles_;
  std::vector<OctNormal> normals_;  // by point; from version 3 filled in from the first level on
  std::vector<Rgba8> colors_;
  ScalarValues scalars_;  // by point, the layout's scalarStride() words each
  std::unique_ptr<CoarseAttributes> coarse_;
  std::unique_ptr<CoarseCreases> creases_;
  std::vector<u32> cell_of_;  // encoder, version 4: per point, its cell at the level
};

constexpr HeaderFormat kFormat{"kdtree", false};

Status encodeImpl(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<u8>& out, CodecStats* stats,
                  uint16_t* version) {
  if (version) *version = kCoarseAttributes;
  Truth truth;
  SP_RETURN_IF_ERROR(collectPoints("kdtree", ctx, mesh, {0, 1, 2}, truth));
  const u32 n = u32(truth.pos.size());
  const size_t start = out.size();
  Header h;
  h.n = n;
  h.t = mesh.triangles.size();
  if (stats) {
    *stats = CodecStats{};
    stats->points = n;
    stats->triangles = mesh.triangles.size();
  }
  if (n == 0) {
    writeHeader(kFormat, h, ctx.bits, ctx.layout, {}, out);
    if (stats) stats->payload_bytes = out.size() - start;
    return Status::ok();
  }

  // Root: the smallest grid-aligned cube holding every point.
  int k0 = ctx.bits;
  Vec3u root;
  rootCube(truth, ctx.bits, {0, 1, 2}, k0, root);

  // The decoder's split order, then the codes of every split, fine to coarse.
  {
    std::vector<std::array<u32, 2>> cells{{0, n}}, next;
    for (int d = 3 * k0; d < 3 * ctx.bits; ++d) {
      const int axis = d % 3, bit = ctx.bits - 1 - splitsAlong(d, axis);
      next.clear();
      for (const auto& [s, e] : cells) {
        const u32 c = lowerHalf(truth.pos, s, e, axis, bit);
        if (c == 0 || c == e - s) {
          next.push_back({s, e});
        } else {
          truth.splits.push_back({s, s + c, e});
          next.push_back({s, s + c});
          next.push_back({s + c, e});
        }
      }
      cells.swap(next);
    }
    std::vector<std::array<u32, 2>> work;
    for (const auto& c : cells)
      if (c[1] - c[0] > 1) work.push_back(c);
    while (!work.empty()) {
      next.clear();
      for (const auto& [s, e] : work) {
        truth.splits.push_back({s, s + 1, e});
        if (e - s > 2) next.push_back({s + 1, e});
      }
      work.swap(next);
    }
  }
  {
    Complex cx;
    cx.init(n);
    std::vector<u64> edges;
    for (const auto& q : truth.tri_keys) {
      cx.tr[q[0]].push_back(packPair(q[1], q[2]));
      cx.tr[q[1]].push_back(packPair(q[0], q[2]));
      cx.tr[q[2]].push_back(packPair(q[0], q[1]));
      edges.push_back(packPair(q[0], q[1]));
      edges.push_back(packPair(q[1], q[2]));
      edges.push_back(packPair(q[0], q[2]));
    }
    std::sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
    for (u64 e : edges) {
      cx.nb[pairLo(e)].push_back(pairHi(e));
      cx.nb[pairHi(e)].push_back(pairLo(e));
    }
    std::vector<std::vector<u8>> per_split(truth.splits.size());
    for (size_t i = truth.splits.size(); i-- > 0;)
      mergeCells(cx, truth.splits[i][0], truth.splits[i][1], per_split[i]);
    truth.code_start.reserve(per_split.size() + 1);
    for (auto& c : per_split) {
      truth.code_start.push_back(u32(truth.codes.size()));
      truth.codes.insert(truth.codes.end(), c.begin(), c.end());
      std::vector<u8>().swap(c);
    }
    truth.code_start.push_back(u32(truth.codes.size()));
  }

  // Version 5 (creases through the coarse levels) when the tile has cut edges, else version 3.
  const AttributeLayout& layout = ctx.layout;
  if (layout.hasNormals() || layout.hasColors() || layout.hasScalars()) truth.cut = cutEdges(truth);
  EncodeIo io;
  io.stats = stats;
  auto engine = std::make_unique<Engine<EncodeIo>>(io, ctx.bits, n, k0, root, &truth);
  engine->layout = layout;
  engine->version = truth.cut.empty() ? kCoarseAttributes : kCreaseMerges;
  if (Status st = engine->run(ctx.bits); !st.isOk()) {
    // A coarse level whose creases would show more vertices than the tile has, or cut edges that do not map onto
    // a level as they should (neither seen): the tile is coded without creases, as version 3.
    if (!engine->creasesFailed()) return st;
    io = EncodeIo{};
    io.stats = stats;
    if (stats) *stats = CodecStats{.points = n, .triangles = mesh.triangles.size()};
    engine = std::make_unique<Engine<EncodeIo>>(io, ctx.bits, n, k0, root, &truth);
    engine->layout = layout;
    engine->version = kCoarseAttributes;
    SP_RETURN_IF_ERROR(engine->run(ctx.bits));
  }
  if (version) *version = engine->version;
  h.k0 = k0;
  h.root = root;
  writeHeader(kFormat, h, ctx.bits, ctx.layout, io.segments, out);
  if (stats) {
    stats->splits = engine->splits_;
    stats->edge_expansions = engine->expansions_;
    stats->payload_bytes = out.size() - start;
  }
  return Status::ok();
}

Result<QuantizedMesh> decodeImpl(const TileContext& ctx, uint16_t version, std::span<const u8> payload, u32 level,
                                 const DecodeLimits& limits) {
  SP_RETURN_IF_ERROR(checkVersion("kdtree", version));
  SP_ASSIGN_OR_RETURN(Header h, readHeader(kFormat, ctx, payload, limits));
  if (h.n == 0) return QuantizedMesh{};
  const int target = int(std::min<u32>(level, u32(ctx.bits)));
  DecodeIo io;
  io.codec = "kdtree";
  SP_ASSIGN_OR_RETURN(io.segments, levelSegments("kdtree", h, ctx.bits, payload, target));
  Engine<DecodeIo> engine(io, ctx.bits, h.n, h.k0, h.root, nullptr);
  engine.layout = ctx.layout;
  engine.version = version;
  engine.max_triangles_ = h.t;
  SP_RETURN_IF_ERROR(engine.run(target));
  QuantizedMesh mesh = engine.mesh(ctx.layout);
  SP_RETURN_IF_ERROR(checkDecoded("kdtree", ctx, h, target, mesh));
  return mesh;
}

}  // namespace

Result<EncodedTile> kdtreeEncode(const TileContext& ctx, const TileView& tile, const CodecOptions&) {
  std::vector<u8> out;
  uint16_t version = 0;
  SP_RETURN_IF_ERROR(encodeImpl(ctx, tile.mesh, out, nullptr, &version));
  SP_ASSIGN_OR_RETURN(EncodedTile e, encodedTile(kFormat, ctx, tile.mesh, std::move(out)));
  e.version = version;
  return e;
}

Status kdtreeEncodeWithStats(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out,
                             CodecStats* stats, uint16_t* version) {
  return encodeImpl(ctx, mesh, out, stats, version);
}

Result<QuantizedMesh> kdtreeDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                   const DecodeLimits& limits) {
  return decodeImpl(ctx, version, payload, u32(ctx.bits), limits);
}

Result<QuantizedMesh> kdtreeDecodeLevel(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                        uint32_t level, const DecodeLimits& limits) {
  return decodeImpl(ctx, version, payload, level, limits);
}

Result<std::vector<CodecLevel>> kdtreeLevels(const TileContext& ctx, uint16_t version,
                                             std::span<const uint8_t> payload, const DecodeLimits& limits) {
  return payloadLevels(kFormat, ctx, version, payload, limits);
}

}  // namespace scanpress
