// Codec `octree` (id 3): embedded mesh coding (EMC) of arbitrary triangle meshes, octree levels with vertex
// merges and splits.
//
// Paper: "Embedded Mesh Coding" (M. Magnor, B. Girod, 1999), ../shared/papers/emc-embedded-octree-mesh-coding.md.
//
// The method (§3, §4): the bounding volume is refined level by level, each level as three binary splits, one per
// axis. The decoder keeps a vertex list (one vertex per occupied cell, at the cell's center) with an edge list per
// vertex. At every split step it passes once over the vertices that exist at the start of the step:
//  - a vertex not due to split gets a refinement bit (RF): which half of its cell it moves to;
//  - a vertex due to split (its cell holds points on both sides) is split (VS): it keeps the lower half, a new
//    vertex is appended for the upper half, each of its edges is classified STAY (stays with the old vertex), MOVE
//    (goes to the new one) or DUPLICATE (both), a flag says whether the two are connected, and for both vertices
//    the step of their next split is coded as a difference from the current step (or "never").
// The encoder finds those codes by merging vertices fine to coarse in the exact reverse order (§3's operation list
// read backwards). Triangles are the three-cliques of the edge graph ("reconstructed from local connectivity").
//
// Where this departs from the paper, and why:
//  - Adaptive range coding with contexts instead of fixed Huffman tables (the issue asks for it; gains measured in
//    bench/RESULTS.md): RF bits by where the centroid of the vertex's neighbours lies relative to the split plane
//    (geometry predicted from connectivity), by the split's axis and by whether the vertex still has a split
//    ahead; edge classes, coded depth-first along the split vertex's link (its neighbours that are adjacent to
//    each other) rather than in list order, by where the neighbour lies relative to the split plane (in
//    half-cells: the neighbour has or has not been refined in this step yet), by the classes of its link
//    neighbours coded before it and by the DUPLICATEs so far; the connecting-edge flag by the number of
//    DUPLICATEs; next-split differences by old/new vertex, remaining levels and degree class.
//  - The volume is the smallest cube aligned to the scan's global grid holding the tile (not the tile's bounding
//    box), so level L means cells of 2^(bits-L) grid cells in every tile and tiles decoded at one level weld. The
//    axis order is the paper's: the encoder merges along the tile's shortest extent first in every level, so the
//    decoder splits the longest first (the order is one header byte).
//  - Exact triangle sets for any input (§4 inserts extra vertices where edges close triangles that are not in the
//    surface, which changes the mesh): after the last level every three-clique of the graph codes whether it is a
//    face (nearly free where cliques and faces agree), then orientation and multiplicity are coded breadth-first
//    as in `kdtree` (EMC's graph is unoriented). Coarse levels output all cliques of their graph, oriented
//    consistently where possible without bits.
//  - Vertices at one grid position with different attributes split apart after the last level, one per round,
//    by the same VS codes with no geometry.
//  - Attributes (normals, colors) are coded per vertex in the final segment: raw in v1, predicted in v2
//    (attributes.h). In v2 coarse levels get normals from their triangles and gray colors; from v3 each coarse
//    vertex shows the attributes of a point of its cell, those of the first levels coded at the end of their
//    segments (attributes.h, CoarseAttributes); v4 (written only for a tile with creases or texture seams, else v3)
//    keeps them at every coarse level as kdtree v4 does (creases.h), with what a level of cliques needs: a flag per
//    triangle around a crease saying whether it is one of the tile's (a clique that is not, a ghost, joins no
//    corners), a merge flag per extra group of a vertex (its fan cut into pieces by a gap), and a level that would
//    show more vertices than the tile has shows fewer groups instead of failing.
//
// Payload v1 to v4 (hierarchy.h's header with the axis order byte; they differ in the attributes' coding):
//   varint N (points), varint T (triangles, with multiplicity); if N == 0 nothing follows.
//   u8 k0 (root level), u8 axis order (0..5: xyz xzy yxz yzx zxy zyx, decoder order), 3 x varint root cell index,
//   varint S (= bits - k0 + 1), S x varint segment length, then the segments, each one range-coder stream.
//   Segment i < S-1: the root's next split (i = 0 only), then the three split steps from level k0+i to k0+i+1,
//   then (v3) the attributes of the vertices they created while there are few, then (v4) the level's sharp flags,
//   projection flags, merges and chosen values.
//   Segment S-1: (the root's next split if k0 = bits) the rounds of coincident-vertex splits, face flags of the
//   cliques, orientation and multiplicity, attributes.
#include <algorithm>
#include <span>
#include <string>

#include "engine/codecs/codec.h"
#include "engine/codecs/attributes.h"
#include "engine/codecs/creases.h"
#include "engine/codecs/hierarchy.h"

namespace scanpress {
namespace {

using namespace hierarchy;
using i64 = int64_t;

constexpr u32 kNone = UINT32_MAX;  // no further split
constexpr int kLevelClasses = 12;
// A coarse level shows every three-clique of its vertex graph, which the index's counts bound only loosely: at most
// this many per vertex and face of the tile (FORMAT.md). The scans of ../shared/data stay at or below 0.67 (the
// complete level's share) at every level: tests/test_data_roundtrip.cpp.
constexpr u64 kCoarseTrianglesPerElement = 4;
u64 coarseTriangleLimit(const DecodeLimits& limits) {
  return kCoarseTrianglesPerElement * (u64(limits.vertices) + limits.faces) + 64;
}  // levels remaining after the step (0..10), coincident rounds (11)
constexpr int kDegreeClasses = 3;
constexpr int kPlaneBins = 10;  // a neighbour's offset from the split plane (9 bins), coincident splits (1)
enum : u8 { kStay = 0, kMove = 1, kDuplicate = 2, kUncoded = 3 };
constexpr std::string_view kCodec = "octree";
constexpr HeaderFormat kFormat{kCodec, true};

// The encoder's plan: every vertex split in decoder order (old vertex, new vertex) and its codes: the old vertex's
// neighbours just before the split, sorted, each with its class, and the connecting-edge flag.
struct Plan {
  std::vector<std::array<u32, 2>> events;
  std::vector<std::pair<u32, u8>> codes;
  std::vector<u32> code_start;  // per event, one extra entry at the end
  std::vector<u8> connect;
};

// What only the encoder knows.
struct Truth {
  const Points* pts = nullptr;  // Morton order (decoder axis order)
  std::vector<Key> keys;        // Morton key per point
  const Plan* plan = nullptr;   // null while planning
  Points by_id;                 // triangles and attributes over the decoder's vertex ids
  std::vector<u32> first;       // per vertex id, its point (Morton order)
  std::vector<u64> cut;         // version 4: the cut edges over vertex ids (creases.h, cutEdges)
};

// The planning pass codes nothing: it only follows the truth.
struct NullIo {
  Status begin() { return Status::ok(); }
  Status end() { return Status::ok(); }
  void meter(double CodecStats::*) {}
  int bit(BitModel&, int v) { return v; }
  u32 sym(SymbolModel&, u32 v) { return v; }
  u32 uniform(u32 v, u32) { return v; }
  u32 bits(u32 v, int) { return v; }
};

struct Models {
  BitModel rf[2][3][kCentroidBins];  // [split ahead][axis in level][centroid bin]
  std::vector<SymbolModel> next;     // [role 3][level class][degree class], symbols 0 (never), 1..3*bits+1
  std::vector<SymbolModel> cls;      // [link neighbours' classes seen][plane bin][DUPLICATEs so far, 0..2]
  BitModel connect[4];
  BitModel face[3];  // by faces already on the clique's first edge
  std::vector<SymbolModel> orient;
  explicit Models(int bits) {
    for (int i = 0; i < 3 * kLevelClasses * kDegreeClasses; ++i) next.emplace_back(u32(3 * bits + 2));
    for (int i = 0; i < 8 * kPlaneBins * 3; ++i) cls.emplace_back(3);
    for (int i = 0; i < 2; ++i) orient.emplace_back(3);
  }
};

int highestBit(Key k) {
  const u64 hi = u64(k >> 64), lo = u64(k);
  return hi ? 127 - __builtin_clzll(hi) : 63 - __builtin_clzll(lo);
}

template <class Io>
class Engine {
 public:
  Engine(Io& io, int bits, const Header& h, const Truth* truth)
      : io_(io), bits_(bits), n_(h.n), k0_(h.k0), axes_(h.axes), truth_(truth), models_(bits) {
    steps_ = 3 * (bits - h.k0);
    max_triangles_ = h.t;
    max_edges_ = 3 * h.t;
    level_ = h.k0;
    if (n_ == 0) return;
    const u32 size = 1u << (bits - h.k0);
    addVertex(h.root, {2 * h.root[0] + size, 2 * h.root[1] + size, 2 * h.root[2] + size});
    if (truth_) range_.push_back({0, n_});
  }

  // Decodes (or encodes) up to level `target` (bits: everything, lossless).
  Status run(int target) {
    if (n_ == 0) return Status::ok();
    coarse_ = std::make_unique<CoarseAttributes>(layout, version, n_);
    coarse_->birth(0, CoarseAttributes::kNone);
    creases_ = std::make_unique<CoarseCreases>(layout, n_, kCodec,
                                               CoarseCreases::Rules{.cliques = true, .merges = true, .fit = true});
    for (int k = k0_; k < bits_ && k < target; ++k) {
      SP_RETURN_IF_ERROR(io_.begin());
      if (k == k0_) SP_RETURN_IF_ERROR(codeNext(0, -1, 2));
      // The creases come last in each level's segment and only coarse levels show them: a decoder going to the
      // last level reads none of them (its segments end there, unread).
      if (k == k0_ && version >= kCoarseCreases && coarse_->active() && !planning() && (truth_ || target < bits_))
        creases_->begin();
      for (int j = 0; j < 3; ++j) SP_RETURN_IF_ERROR(step(3 * (k - k0_) + j));
      io_.meter(&CodecStats::attribute_bits);
      coarse_->endLevel(io_, u32(lo_.size()), bits_ - (k + 1), truth_ ? &truth_->by_id : nullptr, normals_, colors_,
                        scalars_, [&](u32 v) -> const std::vector<u32>& { return nb_[v]; });
      if (creases_->on()) SP_RETURN_IF_ERROR(endCreasedLevel(k + 1));
      SP_RETURN_IF_ERROR(io_.end());
      level_ = k + 1;
    }
    if (target < bits_) return Status::ok();
    SP_RETURN_IF_ERROR(io_.begin());
    if (k0_ == bits_) SP_RETURN_IF_ERROR(codeNext(0, -1, 2));
    SP_RETURN_IF_ERROR(splitCoincident());
    if (lo_.size() != n_)
      return makeError(ErrorCode::kMalformed, "octree payload: " + std::to_string(lo_.size()) +
                                                  " vertices after the last split, header says " + std::to_string(n_));
    if (planning()) return Status::ok();
    if (truth_ && split_index_ != truth_->plan->events.size())
      return makeError(ErrorCode::kInternal, "octree encoder: split sequence mismatch");
    SP_RETURN_IF_ERROR(codeFaces());
    io_.meter(&CodecStats::attribute_bits);
    codeTileAttributes(io_, version, layout, lo_, triangles_, truth_ ? &truth_->by_id : nullptr, normals_, colors_,
                       scalars_, coarse_->coded());
    SP_RETURN_IF_ERROR(io_.end());
    level_ = bits_;
    complete_ = true;
    return Status::ok();
  }

  // The mesh of the level reached: vertices at their cells' centers, the cliques as triangles (lossless once
  // complete).
  // Moves the lossless level's arrays out (the engine is done with them): held once at the decoder's peak.
  Result<QuantizedMesh> mesh(const AttributeLayout& layout) {
    QuantizedMesh m;
    if (n_ == 0) return m;
    if (complete_) {
      m.positions = std::move(lo_);
      m.triangles = std::move(triangles_);
      m.normals = std::move(normals_);
      m.colors = std::move(colors_);
      m.scalars = std::move(scalars_);
      return m;
    }
    const u32 half = (1u << (bits_ - level_)) >> 1;
    // Version 4: a vertex of several groups of corners (its creases and seams) shows a vertex per group, and a
    // vertex may show a value chosen for it instead of its representative's (creases.h).
    if (creases_ && creases_->on() && !creases_->level().keys.empty()) {
      const auto position = [&](u32 v) { return Vec3u{lo_[v][0] + half, lo_[v][1] + half, lo_[v][2] + half}; };
      if (!showCreasedLevel(
              *creases_, *coarse_, n_, u32(lo_.size()), [](u32 v) { return v; }, position, layout, normals_, colors_,
              scalars_, m))
        deriveAttributes(m, layout);
      return m;
    }
    m.positions = lo_;
    for (auto& p : m.positions)
      for (auto& c : p) c += half;
    std::vector<TriKey> keys;
    SP_RETURN_IF_ERROR(levelCliques(keys));
    m.triangles = orientedTriangles(keys);
    // Version 3: each vertex shows its representative's attributes (attributes.h, CoarseAttributes).
    if (!coarse_ || !coarse_->show(
                        u32(m.positions.size()), [](u32 i) { return i; }, normals_, colors_, scalars_, m))
      deriveAttributes(m, layout);
    return m;
  }

  bool creasesFailed() const { return creases_ && creases_->failed(); }

  AttributeLayout layout;             // set by the caller before run()
  uint16_t version = kCoarseCreases;  // the payload's (attribute coding)
  u64 max_cliques_ = kMaxTriangles;   // coarse levels' triangles (set by the decoder from the index)
  bool flat_ = false;                 // one model per symbol kind (measuring the contexts' gain)
  u64 splits_ = 0;
  std::vector<std::array<u32, 2>> range_;   // encoder: the points [s, e) of each vertex
  std::vector<std::array<u32, 2>> events_;  // planning: the splits in order

 private:
  bool planning() const { return truth_ && !truth_->plan; }

  // The coarse level's triangles: every three-clique of its vertex graph (sorted keys), at most max_cliques_.
  Status levelCliques(std::vector<TriKey>& keys) const {
    SortedLists lists;  // the lists sorted, in one array (a copy per vertex cost more than the cliques)
    lists.start.reserve(nb_.size() + 1);
    for (const auto& l : nb_) {
      lists.start.push_back(u32(lists.items.size()));
      lists.items.insert(lists.items.end(), l.begin(), l.end());
      std::sort(lists.items.end() - ptrdiff_t(l.size()), lists.items.end());
    }
    lists.start.push_back(u32(lists.items.size()));
    Status status = Status::ok();
    forEachClique(lists, [&](u32 a, u32 b, u32 c, int) {
      if (keys.size() >= max_cliques_) {
        status = makeError(ErrorCode::kMalformed, "octree payload: more than " + std::to_string(max_cliques_) +
                                                      " triangles at level " + std::to_string(level_) +
                                                      " (the tile index bounds a coarse level)");
        return -1;
      }
      keys.push_back({a, b, c});
      return 1;
    });
    return status;
  }

  // Version 4: the end of level `level`'s segment codes its sharp edges and its groups' values (creases.h).
  Status endCreasedLevel(int level) {
    level_ = level;
    std::vector<TriKey> keys;
    if (Status st = levelCliques(keys); !st.isOk()) {
      if (truth_) creases_->fail();  // (a level the decoder would refuse: the tile is coded as v3)
      return st;
    }
    if (truth_) {  // each vertex id's vertex at the level: the one whose points hold its point
      morton_vertex_.resize(n_);
      for (u32 v = 0; v < lo_.size(); ++v)
        std::fill(morton_vertex_.begin() + range_[v][0], morton_vertex_.begin() + range_[v][1], v);
    }
    const auto cell_of = [&](u32 id) { return morton_vertex_[truth_->first[id]]; };
    return creases_->endLevel(
        io_, std::move(keys), u32(lo_.size()), cell_of, [&](u32 v) -> const Vec3u& { return c2_[v]; },
        [&](u32 v) { return coarse_->shown(v); }, normals_, colors_, scalars_, truth_ ? &truth_->cut : nullptr,
        truth_ ? &truth_->by_id : nullptr, n_);
  }

  void addVertex(Vec3u lo, Vec3u c2) {
    lo_.push_back(lo);
    c2_.push_back(c2);
    next_.push_back(kNone);
    nb_.emplace_back();
  }

  // One split step: every vertex that exists at its start is refined (RF) or split (VS).
  Status step(int t) {
    const int j = t % 3, axis = axes_[j];
    const int bit = bits_ - 1 - (k0_ + t / 3);
    const u32 half = 1u << bit;
    const u32 count = u32(lo_.size());
    for (u32 v = 0; v < count; ++v) {
      if (next_[v] == u32(t)) {
        SP_RETURN_IF_ERROR(splitVertex(v, t, axis, bit));
        continue;
      }
      io_.meter(&CodecStats::geometry_bits);
      const int truth_bit = truth_ ? int((truth_->pts->pos[range_[v][0]][axis] >> bit) & 1) : 0;
      const int bin = flat_ ? 0 : centroidBin(nb_[v], c2_, axis, double(lo_[v][axis]) + half, double(half));
      const int ahead = flat_ ? 0 : (next_[v] != kNone);
      if (io_.bit(models_.rf[ahead][flat_ ? 0 : j][bin], truth_bit)) lo_[v][axis] += half;
      c2_[v][axis] = 2 * lo_[v][axis] + half;
    }
    return Status::ok();
  }

  // After the last level: vertices holding points at one grid position split one point off per round.
  Status splitCoincident() {
    for (int t = steps_;; ++t) {
      bool any = false;
      const u32 count = u32(lo_.size());
      for (u32 v = 0; v < count; ++v)
        if (next_[v] == u32(t)) {
          any = true;
          SP_RETURN_IF_ERROR(splitVertex(v, t, -1, 0));
        }
      if (!any) return Status::ok();
    }
  }

  // The step of v's next split after step t (encoder), kNone if it holds one point.
  u32 nextSplit(u32 v, int t) const {
    const auto [s, e] = range_[v];
    if (e - s == 1) return kNone;
    const Key diff = truth_->keys[s] ^ truth_->keys[e - 1];
    if (diff == 0) return u32(std::max(steps_, t + 1));  // coincident points: the rounds after the last level
    return u32(3 * bits_ - 1 - highestBit(diff) - 3 * k0_);
  }

  // Codes when v splits next, as the difference from step t (t = -1 for the root); role 0 old, 1 new, 2 root.
  Status codeNext(u32 v, int t, int role) {
    io_.meter(&CodecStats::geometry_bits);
    u32 truth_sym = 0;
    if (truth_) {
      const u32 nx = nextSplit(v, t);
      if (nx != kNone && i64(nx) <= t) return makeError(ErrorCode::kInternal, "octree encoder: split order");
      truth_sym = nx == kNone ? 0 : u32(i64(nx) - t);
    }
    int ctx = 0;
    if (!flat_) {
      const int lc = t < 0         ? 0
                     : t >= steps_ ? kLevelClasses - 1
                                   : std::min(bits_ - 1 - (k0_ + t / 3), kLevelClasses - 2);
      const size_t deg = nb_[v].size();
      const int dc = deg == 0 ? 0 : deg <= 5 ? 1 : 2;
      ctx = (role * kLevelClasses + lc) * kDegreeClasses + dc;
    }
    const u32 s = io_.sym(models_.next[ctx], truth_sym);
    if (s == 0) {
      next_[v] = kNone;
      return Status::ok();
    }
    const i64 nx = i64(t) + s;
    if (t < steps_ ? nx > steps_ : s != 1)
      return makeError(ErrorCode::kMalformed, "octree payload: vertex split scheduled past the last level");
    next_[v] = u32(nx);
    return Status::ok();
  }

  // VS at step t along `axis` (axis < 0: a coincident split, no geometry).
  Status splitVertex(u32 v, int t, int axis, int bit) {
    if (lo_.size() >= n_)
      return makeError(ErrorCode::kMalformed,
                       "octree payload: more vertex splits than the header's " + std::to_string(n_) + " vertices");
    ++splits_;
    const u32 w = u32(lo_.size());
    addVertex(lo_[v], c2_[v]);
    i64 plane2 = 0;
    const u32 half = axis >= 0 ? 1u << bit : 1;
    if (axis >= 0) {
      plane2 = 2 * (i64(lo_[v][axis]) + half);
      lo_[w][axis] += half;
      c2_[v][axis] = 2 * lo_[v][axis] + half;
      c2_[w][axis] = 2 * lo_[w][axis] + half;
    }
    if (truth_) {
      const auto [s, e] = range_[v];
      const u32 m = axis >= 0 ? s + lowerHalf(truth_->pts->pos, s, e, axis, bit) : s + 1;
      if (m <= s || m >= e) return makeError(ErrorCode::kInternal, "octree encoder: split of a one-sided cell");
      range_[v] = {s, m};
      range_.push_back({m, e});
    }
    if (axis >= 0) coarse_->birth(w, v), creases_->birth(w, v);
    if (planning()) events_.push_back({v, w});
    else SP_RETURN_IF_ERROR(splitEdges(v, w, axis, plane2, half));
    SP_RETURN_IF_ERROR(codeNext(v, t, 0));
    return codeNext(w, t, 1);
  }

  // The edge classes and the connecting edge of the split of v into v and w.
  Status splitEdges(u32 v, u32 w, int axis, i64 plane2, u32 half) {
    io_.meter(&CodecStats::connectivity_bits);
    nbrs_ = nb_[v];
    std::sort(nbrs_.begin(), nbrs_.end());
    const std::pair<u32, u8>* codes = nullptr;
    size_t ev = 0;
    if (truth_) {
      const Plan& plan = *truth_->plan;
      ev = split_index_++;
      if (ev >= plan.events.size() || plan.events[ev] != std::array<u32, 2>{v, w} ||
          plan.code_start[ev + 1] - plan.code_start[ev] != nbrs_.size())
        return makeError(ErrorCode::kInternal, "octree encoder: split sequence mismatch");
      codes = plan.codes.data() + plan.code_start[ev];
    }
    linkOrder();
    nb_[v].clear();
    int dups = 0;
    for (u32 i : order_) {
      const u32 x = nbrs_[i];
      if (codes && codes[i].first != x) return makeError(ErrorCode::kInternal, "octree encoder: star mismatch");
      int bin = kPlaneBins - 1;
      if (axis >= 0) bin = int(std::clamp<i64>((i64(c2_[x][axis]) - plane2) / half, -4, 4)) + 4;
      int seen = 0;  // the classes of x's link neighbours coded so far
      for (u32 a = link_start_[i]; a < link_start_[i + 1]; ++a)
        if (cls_[link_[a]] != kUncoded) seen |= 1 << cls_[link_[a]];
      const int ctx = flat_ ? 0 : (seen * kPlaneBins + bin) * 3 + std::min(dups, 2);
      const u8 c = u8(io_.sym(models_.cls[ctx], codes ? codes[i].second : 0));
      cls_[i] = c;
      switch (c) {
        case kStay: nb_[v].push_back(x); break;
        case kMove:
          replaceOne(nb_[x], v, w);
          nb_[w].push_back(x);
          break;
        default:
          nb_[v].push_back(x);
          nb_[x].push_back(w);
          nb_[w].push_back(x);
          ++edges_;
          ++dups;
      }
    }
    if (io_.bit(models_.connect[flat_ ? 0 : std::min(dups, 3)], codes ? truth_->plan->connect[ev] : 0)) {
      nb_[v].push_back(w);
      nb_[w].push_back(v);
      ++edges_;
    }
    if (edges_ > max_edges_)
      return makeError(ErrorCode::kMalformed, "octree payload: more edges than three per triangle");
    return Status::ok();
  }

  // The order in which the split vertex's neighbours (nbrs_, sorted) are coded: depth-first along its link (the
  // neighbours adjacent to each other), so that a neighbour's class is coded after those of its link neighbours;
  // link_ / link_start_ hold the link's adjacency by index. Unsplit manifold stars are walked around their cycle.
  void linkOrder() {
    const u32 k = u32(nbrs_.size());
    if (mark_.size() < lo_.size()) mark_.resize(lo_.size(), 0);
    for (u32 i = 0; i < k; ++i) mark_[nbrs_[i]] = i + 1;
    link_start_.resize(k + 1);
    link_.clear();
    for (u32 i = 0; i < k; ++i) {
      link_start_[i] = u32(link_.size());
      for (u32 y : nb_[nbrs_[i]])
        if (mark_[y]) link_.push_back(mark_[y] - 1);
    }
    link_start_[k] = u32(link_.size());
    for (u32 i = 0; i < k; ++i) mark_[nbrs_[i]] = 0;
    cls_.assign(k, kUncoded);
    order_.clear();
    stack_.clear();
    std::vector<u8>& pushed = pushed_;
    pushed.assign(k, 0);
    for (u32 root = 0; root < k; ++root) {
      if (pushed[root]) continue;
      pushed[root] = 1;
      stack_.push_back(root);
      while (!stack_.empty()) {
        const u32 i = stack_.back();
        stack_.pop_back();
        order_.push_back(i);
        for (u32 a = link_start_[i + 1]; a-- > link_start_[i];)
          if (!pushed[link_[a]]) {
            pushed[link_[a]] = 1;
            stack_.push_back(link_[a]);
          }
      }
    }
  }

  // Sorted neighbour lists in one array: vertex v's are items[start[v], start[v + 1]).
  struct SortedLists {
    std::vector<u32> start, items;
    size_t size() const { return start.size() - 1; }
    std::span<const u32> operator[](size_t v) const {
      return std::span<const u32>(items).subspan(start[v], start[v + 1] - start[v]);
    }
  };

  // Calls f(a, b, c, faces so far on edge ab) for every three-clique a < b < c of the sorted lists, in order;
  // f returns -1 to stop, 1 when (a, b, c) counts as a face, 0 otherwise.
  template <class Lists, class F>
  static void forEachClique(const Lists& lists, F f) {
    for (u32 a = 0; a < lists.size(); ++a) {
      const std::span<const u32> la = lists[a];
      for (u32 b : la) {
        if (b <= a) continue;
        const std::span<const u32> lb = lists[b];
        auto ia = std::upper_bound(la.begin(), la.end(), b);
        auto ib = std::upper_bound(lb.begin(), lb.end(), b);
        int faces = 0;
        while (ia != la.end() && ib != lb.end()) {
          if (*ia < *ib) ++ia;
          else if (*ib < *ia) ++ib;
          else {
            const int r = f(a, b, *ia, faces);
            if (r < 0) return;
            faces += r;
            ++ia, ++ib;
          }
        }
      }
    }
  }

  // After the last split: which cliques are faces, then their orientation and multiplicity.
  Status codeFaces() {
    io_.meter(&CodecStats::connectivity_bits);
    for (auto& l : nb_) std::sort(l.begin(), l.end());
    std::vector<TriKey> faces;
    u64 cliques = 0;
    Status status = Status::ok();
    forEachClique(nb_, [&](u32 a, u32 b, u32 c, int on_edge) -> int {
      if (++cliques > kMaxTriangles) {
        status = makeError(ErrorCode::kLimitExceeded, "octree payload: more than 2^28 cliques");
        return -1;
      }
      const TriKey key{a, b, c};
      int truth_face = 0;
      if (truth_) truth_face = std::binary_search(truth_->by_id.tri_keys.begin(), truth_->by_id.tri_keys.end(), key);
      if (!io_.bit(models_.face[flat_ ? 0 : std::min(on_edge, 2)], truth_face)) return 0;
      if (faces.size() >= max_triangles_) {
        status = makeError(ErrorCode::kMalformed, "octree payload: more faces than the header's triangles");
        return -1;
      }
      faces.push_back(key);
      return 1;
    });
    SP_RETURN_IF_ERROR(status);
    return codeFaceCopies(io_, kCodec, models_.orient.data(), faces, truth_ ? &truth_->by_id : nullptr, max_triangles_,
                          triangles_);
  }

  Io& io_;
  int bits_;
  u32 n_;
  int k0_;
  Axes axes_;
  const Truth* truth_;
  Models models_;
  int steps_ = 0;
  u64 max_triangles_ = 0, max_edges_ = 0, edges_ = 0;
  int level_ = 0;
  bool complete_ = false;
  size_t split_index_ = 0;
  std::vector<Vec3u> lo_;  // cell corner
  std::vector<Vec3u> c2_;  // twice the cell center (exact in integers)
  std::vector<u32> next_;  // step of the next split, kNone
  std::vector<std::vector<u32>> nb_;
  std::vector<u32> nbrs_, link_, link_start_, order_, stack_;
  std::vector<u32> mark_;  // per vertex: 1 + its index among the split vertex's neighbours, 0 otherwise
  std::vector<u8> cls_, pushed_;
  std::vector<Triangle> triangles_;
  std::vector<OctNormal> normals_;  // by vertex id; from version 3 filled in from the first level on
  std::vector<Rgba8> colors_;
  ScalarValues scalars_;  // by vertex id
  std::unique_ptr<CoarseAttributes> coarse_;
  std::unique_ptr<CoarseCreases> creases_;
  std::vector<u32> morton_vertex_;  // encoder, version 4: per point (Morton order), its vertex at the level
};

// Decoder axis order: the tile's longest extent first (the encoder merges along the shortest first).
Axes axisOrder(const QuantizedMesh& mesh) {
  Axes axes{0, 1, 2};
  if (mesh.positions.empty()) return axes;
  Vec3u lo = mesh.positions[0], hi = lo;
  for (const auto& p : mesh.positions)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
  std::stable_sort(axes.begin(), axes.end(), [&](int a, int b) { return hi[a] - lo[a] > hi[b] - lo[b]; });
  return axes;
}

// Triangles and attributes renamed from points to the decoder's vertex ids (point of vertex v: range[v][0]).
void renameToIds(const Points& pts, const std::vector<std::array<u32, 2>>& range, Points& out) {
  const u32 n = u32(range.size());
  std::vector<u32> id(n);
  for (u32 v = 0; v < n; ++v) id[range[v][0]] = v;
  const size_t stride = pts.stride();
  for (u32 v = 0; v < n; ++v) {
    out.pos.push_back(pts.pos[range[v][0]]);
    if (!pts.normals.empty()) out.normals.push_back(pts.normals[range[v][0]]);
    if (!pts.colors.empty()) out.colors.push_back(pts.colors[range[v][0]]);
    const auto row = pts.scalars.begin() + ptrdiff_t(range[v][0] * stride);
    out.scalars.insert(out.scalars.end(), row, row + ptrdiff_t(stride));
  }
  std::vector<std::pair<TriKey, std::array<u32, 2>>> tris;
  for (size_t i = 0; i < pts.tri_keys.size(); ++i) {
    TriKey q{id[pts.tri_keys[i][0]], id[pts.tri_keys[i][1]], id[pts.tri_keys[i][2]]};  // copy 0's orientation
    auto copies = pts.tri_copies[i];
    const int r = int(std::min_element(q.begin(), q.end()) - q.begin());
    std::rotate(q.begin(), q.begin() + r, q.end());
    if (q[1] > q[2]) std::swap(q[1], q[2]), std::swap(copies[0], copies[1]);
    tris.push_back({q, copies});
  }
  std::sort(tris.begin(), tris.end());
  for (const auto& [q, c] : tris) {
    out.tri_keys.push_back(q);
    out.tri_copies.push_back(c);
  }
}

// The codes of every split, fine to coarse: merges the new vertex back into the old one in reverse order.
Plan planCodes(const Points& by_id, const std::vector<std::array<u32, 2>>& events) {
  const size_t n = by_id.pos.size();
  std::vector<std::vector<u32>> nb(n);
  std::vector<std::array<u32, 2>> edges;
  for (const auto& q : by_id.tri_keys)
    edges.push_back({q[0], q[1]}), edges.push_back({q[1], q[2]}), edges.push_back({q[0], q[2]});
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  for (const auto& [a, b] : edges) nb[a].push_back(b), nb[b].push_back(a);
  std::vector<std::vector<std::pair<u32, u8>>> per_event(events.size());
  Plan plan;
  plan.events = events;
  plan.connect.resize(events.size());
  for (size_t i = events.size(); i-- > 0;) {
    const auto [v, w] = events[i];
    auto& e = per_event[i];
    for (u32 x : nb[v])
      if (x == w) plan.connect[i] = 1;
      else e.push_back({x, 1});
    for (u32 x : nb[w])
      if (x != v) e.push_back({x, 2});
    sortAndMergeFlags(e);
    nb[v].clear();
    for (auto& [x, flags] : e) {
      nb[v].push_back(x);
      if (flags == 2) replaceOne(nb[x], w, v);
      else if (flags == 3) eraseOne(nb[x], w);
      flags = flags == 1 ? kStay : flags == 2 ? kMove : kDuplicate;
    }
    std::vector<u32>().swap(nb[w]);
  }
  plan.code_start.reserve(events.size() + 1);
  for (auto& e : per_event) {
    plan.code_start.push_back(u32(plan.codes.size()));
    plan.codes.insert(plan.codes.end(), e.begin(), e.end());
    std::vector<std::pair<u32, u8>>().swap(e);
  }
  plan.code_start.push_back(u32(plan.codes.size()));
  return plan;
}

Status encodeImpl(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<u8>& out, CodecStats* stats,
                  bool contexts, uint16_t* version) {
  if (version) *version = kCoarseAttributes;
  const Axes axes = axisOrder(mesh);
  Points pts;
  SP_RETURN_IF_ERROR(collectPoints(kCodec, ctx, mesh, axes, pts));
  const size_t start = out.size();
  Header h;
  h.n = u32(pts.pos.size());
  h.t = mesh.triangles.size();
  h.axes = axes;
  if (stats) {
    *stats = CodecStats{};
    stats->points = h.n;
    stats->triangles = h.t;
  }
  if (h.n == 0) {
    writeHeader(kFormat, h, ctx.bits, ctx.layout, {}, out);
    if (stats) stats->payload_bytes = out.size() - start;
    return Status::ok();
  }
  rootCube(pts, ctx.bits, axes, h.k0, h.root);
  Truth truth;
  truth.pts = &pts;
  truth.keys.reserve(h.n);
  for (const auto& p : pts.pos) truth.keys.push_back(mortonKey(p, ctx.bits, axes));

  std::vector<std::array<u32, 2>> events;
  {
    NullIo nio;
    Engine<NullIo> planner(nio, ctx.bits, h, &truth);
    SP_RETURN_IF_ERROR(planner.run(ctx.bits));
    renameToIds(pts, planner.range_, truth.by_id);
    truth.first.resize(h.n);
    for (u32 v = 0; v < h.n; ++v) truth.first[v] = planner.range_[v][0];
    events = std::move(planner.events_);
  }
  const Plan plan = planCodes(truth.by_id, events);
  truth.plan = &plan;

  // Version 4 (creases through the coarse levels) when the tile has cut edges, else version 3.
  const AttributeLayout& layout = ctx.layout;
  if (layout.hasNormals() || layout.hasColors() || layout.hasScalars()) {
    std::vector<u32> id(h.n);
    for (u32 v = 0; v < h.n; ++v) id[truth.first[v]] = v;
    for (u64 e : cutEdges(pts)) truth.cut.push_back(edgeKey(id[u32(e >> 32)], id[u32(e)]));
    std::sort(truth.cut.begin(), truth.cut.end());
  }
  const auto encode = [&](EncodeIo& io, uint16_t v) {
    io.stats = stats;
    auto engine = std::make_unique<Engine<EncodeIo>>(io, ctx.bits, h, &truth);
    engine->layout = layout;
    // Version 4 lists every coarse level's cliques, within the decoder's bound (the tile's own counts).
    engine->max_cliques_ =
        std::min<u64>(kMaxTriangles, coarseTriangleLimit(DecodeLimits{h.n, u32(std::min<u64>(h.t, UINT32_MAX))}));
    engine->flat_ = !contexts;
    engine->version = v;
    return engine;
  };
  EncodeIo io;
  auto engine = encode(io, truth.cut.empty() ? kCoarseAttributes : kCoarseCreases);
  if (Status st = engine->run(ctx.bits); !st.isOk()) {
    // A coarse level whose creases would show more vertices than the tile has, or cut edges that do not map onto
    // a level as they should (neither seen): the tile is coded without creases, as version 3.
    if (!engine->creasesFailed()) return st;
    io = EncodeIo{};
    if (stats) *stats = CodecStats{.points = h.n, .triangles = h.t};
    engine = encode(io, kCoarseAttributes);
    SP_RETURN_IF_ERROR(engine->run(ctx.bits));
  }
  if (version) *version = engine->version;
  writeHeader(kFormat, h, ctx.bits, ctx.layout, io.segments, out);
  if (stats) {
    stats->splits = engine->splits_;
    stats->payload_bytes = out.size() - start;
  }
  return Status::ok();
}

Result<QuantizedMesh> decodeImpl(const TileContext& ctx, uint16_t version, std::span<const u8> payload, u32 level,
                                 const DecodeLimits& limits) {
  SP_RETURN_IF_ERROR(checkVersion(kCodec, version));
  SP_ASSIGN_OR_RETURN(Header h, readHeader(kFormat, ctx, payload, limits));
  if (h.n == 0) return QuantizedMesh{};
  const int target = int(std::min<u32>(level, u32(ctx.bits)));
  DecodeIo io;
  io.codec = kCodec;
  SP_ASSIGN_OR_RETURN(io.segments, levelSegments(kCodec, h, ctx.bits, payload, target));
  Engine<DecodeIo> engine(io, ctx.bits, h, nullptr);
  engine.layout = ctx.layout;
  engine.version = version;
  engine.max_cliques_ = std::min<u64>(kMaxTriangles, coarseTriangleLimit(limits));
  SP_RETURN_IF_ERROR(engine.run(target));
  SP_ASSIGN_OR_RETURN(QuantizedMesh mesh, engine.mesh(ctx.layout));
  SP_RETURN_IF_ERROR(checkDecoded(kCodec, ctx, h, target, mesh));
  return mesh;
}

}  // namespace

Result<EncodedTile> octreeEncode(const TileContext& ctx, const TileView& tile, const CodecOptions& options) {
  std::vector<u8> out;
  uint16_t version = 0;
  SP_RETURN_IF_ERROR(encodeImpl(ctx, tile.mesh, out, nullptr, options.octree.contexts, &version));
  SP_ASSIGN_OR_RETURN(EncodedTile e, encodedTile(kFormat, ctx, tile.mesh, std::move(out)));
  e.version = version;
  return e;
}

Status octreeEncodeWithStats(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out,
                             CodecStats* stats, const OctreeOptions& options, uint16_t* version) {
  return encodeImpl(ctx, mesh, out, stats, options.contexts, version);
}

Result<QuantizedMesh> octreeDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                   const DecodeLimits& limits) {
  return decodeImpl(ctx, version, payload, u32(ctx.bits), limits);
}

Result<QuantizedMesh> octreeDecodeLevel(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                        uint32_t level, const DecodeLimits& limits) {
  return decodeImpl(ctx, version, payload, level, limits);
}

Result<std::vector<CodecLevel>> octreeLevels(const TileContext& ctx, uint16_t version,
                                             std::span<const uint8_t> payload, const DecodeLimits& limits) {
  return payloadLevels(kFormat, ctx, version, payload, limits);
}

}  // namespace scanpress
