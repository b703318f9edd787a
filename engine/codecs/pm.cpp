// Codec `pm` (id 4): a simplified base mesh plus the vertex splits that undo the collapses back to the tile.
//
// Paper: S. Ahn, M. Chang, Y.-S. Ho, "Shape-preserving progressive coding of 3-D models"
// (../shared/papers/shape-preserving-progressive-qem.md): section 2 is the simplifier (engine/simplify), section 3
// the geometry coding followed here: each split codes the collapse's placement index (0: the kept vertex did not
// move, 1: it moved onto the removed vertex, 2: elsewhere), then the residuals of the positions v'_s does not give.
//
// Where this departs from the paper, and why:
//  - The index is computed from the positions, not taken from the simplifier, so any valid Simplification codes.
//  - Predictions: the paper codes Delta_r = v_r - v'_s for index 0/1, which costs about an edge length per
//    component; here the endpoint that is not at v'_s is predicted by the average of its neighbours after the split
//    (the paper's index-2 predictor, applied to every index; bunny, 16 bits, lossless, with the temporary
//    shortest-edge simplifier: 43.2 -> 40.9 bpv). For index 2, v_l is predicted by the average of its neighbours other than v_s, then v_s by v_l mirrored through v'_s (exact for a
//    midpoint placement) instead of by v'_s.
//  - Residuals are integers on the scan's grid (no m-bit requantization), coded with the range coder: per
//    component a bit-length bucket with an adaptive model (context: the local scale, the distance from v'_s to
//    the prediction, and the previous component's bucket), a sign bit and raw mantissa bits (the paper: QM coder).
//  - Connectivity (the paper refers to Hoppe's PM): per batch of independent splits, one context-coded flag per
//    current vertex in canonical order says whether it splits; vertices within two edges of a split already made
//    in the batch get no flag (the simplifier's passes have disjoint closed one-rings, so they cannot split). A
//    split vertex k codes, per incident face in canonical fan order (walks around k across shared edges), whether
//    the face goes to the new vertex (context: walk start / previous bit). The new faces (those the collapse deleted) are coded against the
//    "cut" vertices (neighbours shared by a moving and a staying face): per cut vertex a count of new faces with
//    it (0/1/2/more); any other new face's third vertex as an index into k's sorted neighbours or, escaped, any
//    vertex. Each new face's orientation is a bit predicted by the neighbouring face across its edge with k. On
//    manifold meshes a split costs the flag, about one bit per incident face, and near nothing for the new faces;
//    boundary and non-manifold neighbourhoods code exactly with the same scheme.
//  - The base mesh is coded by whichever of store, kdtree and octree codes it smallest (decoded again by the
//    encoder so that both sides start from the same vertex order); the vertices are then put in canonical order
//    (sorted by position, ties in decoded order) and every split appends its new vertex.
//  - Batches (the simplifier's passes) are grouped into levels so that a level grows the vertex count by a useful
//    step; each level is one range-coder stream (models carry over), so a payload cut after a level's end decodes it.
//  - The encoder welds vertices sharing a grid position and drops triangles that repeat a vertex after the weld:
//    the last level is the tile as triangles over positions (with multiplicity and orientation) and, from v5, the
//    wedges of their corners. Normals and colors are not kept in v1 and v2: every level derives them from its
//    triangles (deriveAttributes).
//  - Attributes (v3; ../shared/papers/attributes-selective-refinement.md §3): a vertex's normal and color are the
//    ones it has in the last level (v3, v4: a welded position takes its first input vertex's). The base codec codes
//    the base vertices' with the base mesh; a vertex a split adds shows its parent's until the last level, whose
//    stream ends with the attributes of every vertex the splits added, predicted from the finest geometry as
//    kdtree's last level predicts its (LevelAttributes). Every level thus shows the scan's own values. Where the
//    paper merges the attributes of a collapse into new values, we keep one of them (the kept vertex's): no value is
//    coded twice, and no level shows a value the scan does not have.
//  - Scalar channels (v4: confidence, intensity, lossless normals, texture coordinates) go the same way, coded
//    before the normals at the last level as kdtree's are.
//  - Wedges (v5; the paper's corner graph, §3): a crease or a texture seam is points at one position with other
//    attributes, and v4's weld kept one of them. v5 keeps each as a wedge: faces name their corners' wedges, and
//    attributes are per wedge. The paper marks edges sharp and propagates attributes through contractions; here the
//    simplifier carries each corner's wedge and moves a corner only to a wedge of its own side (simplify.h,
//    corner_wedges), so a seam's vertex leaves only along its seam. A split then names, per new face, which of k's
//    and of w's wedges its corners take (nothing where a vertex has one: about a bit per new face along seams), and
//    r's wedges follow from k's that they pair with. A wedge a split adds shows its paired wedge's values until the
//    last level, which codes the added wedges over the mesh of wedges (a wedge's predicted normal is its own side's).
//    Written for every tile with attributes, so that a decoded tile is its vertices with their attributes and
//    decoders weld tiles by position and attributes.
//
// Payload v1 to v5 (FORMAT.md, "Codec pm"):
//   u8 base codec id (1 store, 2 kdtree, 3 octree), varint base codec version, varint base payload bytes B,
//   varint base vertices V0 (v5: wedges), varint base faces F0, f32 base error (grid cells, little-endian bits),
//   varint L (levels after the base), L x { varint batches, varint vertices, [v5: varint wedges,] varint faces,
//   f32 error, varint stream bytes }, then the base payload (B bytes), then the L level streams (v3 with normals or
//   colors, v4 with scalar channels: the last one ends with the attributes of the vertices, v5 wedges, the splits
//   added).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <numeric>
#include <string>

#include "engine/codecs/attributes.h"
#include "engine/codecs/codec.h"
#include "engine/entropy/range_coder.h"
#include "engine/io/bytes.h"

namespace scanpress {
namespace {

// 2: the same layout as 1; its base payloads are kdtree's and octree's version 2 (so are its golden bytes).
// 3: normals and colors at every level (the base's in the base payload, the split vertices' at the end of the last
// level's stream); without them the bytes of v2.
// 4: scalar channels too, coded as normals and colors are.
// 5: wedges (creases and texture seams kept); written for every tile with attributes. A tile without any is written
// as version 3 (v2's bytes).
constexpr uint16_t kVersion = 5;
constexpr uint16_t kAttributesFrom = 3;
constexpr uint16_t kScalarsFrom = 4;
constexpr uint16_t kWedgesFrom = 5;
// A level closes once it has at least this many splits and grew the vertex count by this factor (or at the last
// batch): fewer, larger levels pay less per-level overhead (a 4-byte flush and the table entry).
constexpr uint64_t kMinLevelSplits = 64;
constexpr double kLevelGrowth = 1.3;
// The base mesh: simplification continues to this share of the last level's faces (or as far as it goes). Measured
// on bunny at 16 bits (with the temporary simplifier): 1/8 37.5 bpv, 1/32 38.1, 1/128 38.2 lossless; the base
// codecs code dense geometry more cheaply than vertex splits do, so a larger base is smaller but less progressive.
constexpr double kBaseFaceShare = 1.0 / 8;
constexpr uint64_t kBaseMinFaces = 16;

constexpr uint32_t kBuckets = 33;      // bit length of a residual component's magnitude (< 2^32)
constexpr uint32_t kScales = 16;       // context: bit length of the local scale (see codeResidual)
constexpr uint32_t kRelContexts = 5;   // context of y and z: their predecessor's bucket relative to the scale
constexpr uint32_t kCountEscape = 15;  // counts >= this code the rest in 32 raw bits

uint32_t bitLength(uint64_t v) {
  uint32_t b = 0;
  while (v) ++b, v >>= 1;
  return b;
}

struct Models {
  BitModel flag[2];
  BitModel wedge_same[2];  // v5: a new face's corner at k / at its third vertex takes the predicted wedge
  BitModel moved[3];
  BitModel orient[2];
  BitModel sign[3];
  SymbolModel cut_count{4};
  SymbolModel extra_count{kCountEscape + 1};
  SymbolModel big_count{kCountEscape + 1};
  SymbolModel placement{3};
  std::vector<SymbolModel> bucket;
  // Buffers reused by every split (allocation dominated the decoder's profile).
  struct Scratch {
    std::vector<uint32_t> fan, in_moved, in_stayed, nbrs, cut, extra_w, rn, kn, kw, xw;
    std::vector<uint8_t> starts, extra_o, orients, taken;
    std::vector<std::array<uint32_t, 2>> wedges;
    // Per split (stamped, so that nothing is cleared per split): per vertex the fan face that predicts a new face's
    // wedges and the vertex's wedge list (in `lists`); per wedge of k the wedge of r it pairs with.
    std::vector<uint32_t> vertex_stamp, pred_face, list_stamp, list_begin, list_size, lists, wedge_stamp, r_wedge;
    uint32_t stamp = 0;
    void next(size_t vertices, size_t wedges_now) {
      if (++stamp == 0) {
        std::fill(vertex_stamp.begin(), vertex_stamp.end(), 0);
        std::fill(list_stamp.begin(), list_stamp.end(), 0);
        std::fill(wedge_stamp.begin(), wedge_stamp.end(), 0);
        stamp = 1;
      }
      if (vertex_stamp.size() < vertices) {
        vertex_stamp.resize(vertices, 0), pred_face.resize(vertices), list_stamp.resize(vertices, 0);
        list_begin.resize(vertices), list_size.resize(vertices);
      }
      if (wedge_stamp.size() < wedges_now) wedge_stamp.resize(wedges_now, 0), r_wedge.resize(wedges_now);
      lists.clear();
    }
    std::vector<std::pair<uint32_t, uint8_t>> ordered;
  } scratch;
  Models() : bucket(3 * kScales * (1 + kRelContexts), SymbolModel(kBuckets)) {}
};

// Encoder and decoder share one coding routine: each call codes `v` (encoder) or sets it (decoder).
struct EncodeSide {
  static constexpr bool kEncode = true;
  RangeEncoder& e;
  void bit(BitModel& m, int& b) { e.encodeBit(m, b); }
  void sym(SymbolModel& m, uint32_t& s) { e.encodeSymbol(m, s); }
  void bits(uint32_t& v, int n) { e.encodeBits(v, n); }
  void uniform(uint32_t& v, uint32_t count) { e.encodeUniform(v, count); }
};
struct DecodeSide {
  static constexpr bool kEncode = false;
  RangeDecoder& d;
  void bit(BitModel& m, int& b) { b = d.decodeBit(m); }
  void sym(SymbolModel& m, uint32_t& s) { s = d.decodeSymbol(m); }
  void bits(uint32_t& v, int n) { v = d.decodeBits(n); }
  void uniform(uint32_t& v, uint32_t count) { v = d.decodeUniform(count); }
};

// The same coders with the interface of the attribute coding (attributes.h): each call returns the value.
struct AttributeEncodeIo {
  RangeEncoder& e;
  int bit(BitModel& m, int b) { return e.encodeBit(m, b), b; }
  uint32_t sym(SymbolModel& m, uint32_t s) { return e.encodeSymbol(m, s), s; }
  uint32_t uniform(uint32_t v, uint32_t n) { return e.encodeUniform(v, n), v; }
  uint32_t bits(uint32_t v, int n) { return e.encodeBits(v, n), v; }
};
struct AttributeDecodeIo {
  RangeDecoder& d;
  int bit(BitModel& m, int) { return d.decodeBit(m); }
  uint32_t sym(SymbolModel& m, uint32_t) { return d.decodeSymbol(m); }
  uint32_t uniform(uint32_t, uint32_t n) { return d.decodeUniform(n); }
  uint32_t bits(uint32_t, int n) { return d.decodeBits(n); }
};

template <class C>
void codeCount(C& c, SymbolModel& m, uint64_t& n) {
  uint32_t s = n >= kCountEscape ? kCountEscape : uint32_t(n);
  c.sym(m, s);
  if (s < kCountEscape) {
    n = s;
    return;
  }
  uint32_t rest = C::kEncode ? uint32_t(n - kCountEscape) : 0;
  c.bits(rest, 32);
  n = uint64_t(kCountEscape) + rest;
}

// The mesh both sides keep while splitting: positions, faces, and per vertex its faces; and the wedges (v5): the
// corners of a vertex on a crease or a texture seam show one set of attributes per side, a wedge each. A face names
// its corners' wedges; attributes are per wedge. Before v5 every vertex has one wedge, whose id is the vertex's.
struct PmState {
  std::vector<Vec3u> pos;
  std::vector<Triangle> faces;
  std::vector<std::vector<uint32_t>> vf;
  std::vector<Triangle> fw;  // per face: its corners' wedges (empty while `identity`)
  // Every vertex is named by one wedge, with its own id (before v5, and a v5 base without a crease or seam): a
  // split then keeps it so (r's one wedge gets r's id), corners' wedges are their vertices and `fw` is not kept.
  bool identity = false;
  const std::vector<Triangle>& cornerWedges() const { return identity ? faces : fw; }
  std::vector<uint32_t> wv;  // per wedge: its vertex
  // Per vertex: how many wedges name it, and the first. A vertex named by one wedge has it at every corner, so its
  // list (wedgesOf) needs no look at its faces: the common case, and every vertex before v5.
  std::vector<uint32_t> wedge_count, first_wedge;
  void addWedge(uint32_t v, uint32_t parent_wedge) {
    if (wedge_count[v]++ == 0) first_wedge[v] = uint32_t(wv.size());
    wv.push_back(v);
    parent.push_back(parent_wedge);
  }
  std::vector<uint32_t> parent;    // per wedge: the wedge it split from (a base wedge: itself)
  std::vector<OctNormal> normals;  // v3, with normals: per coded wedge
  std::vector<Rgba8> colors;       // v3, with colors: per coded wedge
  ScalarValues scalars;            // v4, with scalar channels: the layout's stride per coded wedge

  uint32_t wedgeAt(uint32_t f, uint32_t v) const {
    const Triangle& t = faces[f];
    if (identity) return v;
    return fw[f][t[0] == v ? 0 : (t[1] == v ? 1 : 2)];
  }
  // v's distinct wedges at its faces' corners, ascending.
  void wedgesOf(uint32_t v, std::vector<uint32_t>& out) const {
    out.clear();
    if (wedge_count[v] == 1) {
      out.push_back(first_wedge[v]);
      return;
    }
    bool one = true;
    for (uint32_t f : vf[v]) {
      out.push_back(wedgeAt(f, v));
      one &= out.back() == out.front();
    }
    if (one && !out.empty()) {
      out.resize(1);
      return;
    }
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
  }
  void addFace(const Triangle& t, const Triangle& w) {
    const uint32_t id = uint32_t(faces.size());
    faces.push_back(t);
    if (!identity) fw.push_back(w);
    vf[t[0]].push_back(id);
    if (t[1] != t[0]) vf[t[1]].push_back(id);
    if (t[2] != t[0] && t[2] != t[1]) vf[t[2]].push_back(id);
  }
  // Marks the vertices within two edges of a and b (after a split of a into a and b): in one batch no other
  // vertex among them splits (the pass's closed one-rings are disjoint), so their flags are not coded.
  void block(uint32_t a, uint32_t b, std::vector<uint32_t>& stamp, uint32_t mark) const {
    if (stamp.size() < pos.size()) stamp.resize(pos.size(), 0);
    if (seen_.size() < pos.size()) seen_.resize(pos.size(), 0);
    // The one-ring without duplicates, found with a second stamp (sorting it took a quarter of the decode).
    if (++seen_mark_ == 0) std::fill(seen_.begin(), seen_.end(), 0), seen_mark_ = 1;
    ring1_.clear();
    for (uint32_t c : {a, b})
      for (uint32_t f : vf[c])
        for (uint32_t w : faces[f])
          if (seen_[w] != seen_mark_) seen_[w] = seen_mark_, ring1_.push_back(w);
    stamp[a] = stamp[b] = mark;
    for (uint32_t w : ring1_)
      for (uint32_t f : vf[w]) {
        const Triangle& t = faces[f];
        stamp[t[0]] = stamp[t[1]] = stamp[t[2]] = mark;
      }
    for (uint32_t w : ring1_) stamp[w] = mark;  // (a ring vertex with no face left: none, but kept exact)
  }
  mutable std::vector<uint32_t> ring1_, seen_;
  mutable uint32_t seen_mark_ = 0;
  // The other two corners of face f after v, in f's rotation.
  std::pair<uint32_t, uint32_t> others(uint32_t f, uint32_t v) const {
    const Triangle& t = faces[f];
    const int i = t[0] == v ? 0 : (t[1] == v ? 1 : 2);
    return {t[(i + 1) % 3], t[(i + 2) % 3]};
  }
  // v's faces in canonical order: walks around v across shared edges ((v, a, b) is followed by the first unvisited
  // (v, b, c)), starting each walk at the first unvisited face in key order (the other corners (a, b) in rotation,
  // ties by face id). On a manifold fan this is the cyclic order, so the faces that move to a split's new vertex
  // form runs. `starts[i]` is set when face i begins a walk.
  void fan(uint32_t v, std::vector<uint32_t>& ids, std::vector<uint8_t>& starts) const {
    keyed_.clear();
    for (uint32_t f : vf[v]) {
      const auto [a, b] = others(f, v);
      keyed_.push_back({a, b, f});
    }
    std::sort(keyed_.begin(), keyed_.end());
    const size_t n = keyed_.size();
    visited_.assign(n, 0);
    group_next_.resize(n);
    for (size_t i = 0; i < n; ++i) group_next_[i] = uint32_t(i);  // at a group's first entry: its next candidate
    ids.clear();
    starts.clear();
    for (size_t start = 0; start < n; ++start) {
      if (visited_[start]) continue;
      size_t cur = start;
      bool first = true;
      while (true) {
        visited_[cur] = 1;
        ids.push_back(keyed_[cur][2]);
        starts.push_back(first);
        first = false;
        const uint32_t want = keyed_[cur][1];
        const size_t g = size_t(std::lower_bound(keyed_.begin(), keyed_.end(), std::array<uint32_t, 3>{want, 0, 0}) -
                                keyed_.begin());
        if (g == n || keyed_[g][0] != want) break;
        size_t j = group_next_[g];
        while (j < n && keyed_[j][0] == want && visited_[j]) ++j;
        group_next_[g] = uint32_t(j);
        if (j == n || keyed_[j][0] != want) break;
        cur = j;
      }
    }
  }
  mutable std::vector<std::array<uint32_t, 3>> keyed_;
  mutable std::vector<uint8_t> visited_;
  mutable std::vector<uint32_t> group_next_;
};

// v3's attributes through the levels (FORMAT.md, "Attributes of pm levels"): the base codec codes the base
// vertices'; a vertex a split adds shows what its parent shows (so one of the base's) until the payload's last level,
// whose stream ends with the attributes of every vertex the splits added, predicted from the finest geometry and the
// decoded neighbours as kdtree's last level predicts its (attributes.h; the angle-weighted normal sums each vertex's
// faces in its face-list order). Coding each level's new vertices at its own end, from its coarser geometry, showed
// every vertex's own at every level but cost 7-38% more attribute bytes (bench/RESULTS.md); kdtree's rule (levels
// of at most max(64, N/16) vertices code theirs) would code none here, as the base already has about N/8.
class LevelAttributes {
 public:
  // `base_wedges`: 0 when the payload codes no attributes (nothing is kept then).
  LevelAttributes(const AttributeLayout& layout, uint32_t base_wedges)
      : layout_(layout), base_(base_wedges), shows_(base_wedges) {
    std::iota(shows_.begin(), shows_.end(), 0u);
  }
  // The end of a level's stream (`last`: the payload's last level). `truth` (encoder): attributes by wedge. The
  // last level's wedges are coded as vertices of the mesh of wedges (faces over their corners' wedges), so that a
  // wedge's predicted normal is that of its own side of a crease.
  template <class Io>
  void endLevel(Io& io, PmState& st, bool last, const hierarchy::Points* truth) {
    const uint32_t n = uint32_t(st.wv.size());
    if (!last) {
      for (uint32_t w = uint32_t(shows_.size()); w < n; ++w) shows_.push_back(shows_[st.parent[w]]);
      return;
    }
    std::vector<Vec3u> wpos(n);
    for (uint32_t w = 0; w < n; ++w) wpos[w] = st.pos[st.wv[w]];
    // Per wedge its faces, in the order of its vertex's face list (before v5 that list itself), as offsets into one
    // array.
    std::vector<uint32_t> begin(size_t(n) + 1, 0), faces;
    for (uint32_t v = 0; v < st.pos.size(); ++v)
      for (uint32_t f : st.vf[v]) ++begin[st.wedgeAt(f, v) + 1];
    for (uint32_t w = 0; w < n; ++w) begin[w + 1] += begin[w];
    faces.resize(begin[n]);
    std::vector<uint32_t> next(begin.begin(), begin.end() - 1);
    for (uint32_t v = 0; v < st.pos.size(); ++v)
      for (uint32_t f : st.vf[v]) faces[next[st.wedgeAt(f, v)]++] = f;
    const auto faces_of = [&](uint32_t w) {
      return std::span<const uint32_t>(faces.data() + begin[w], begin[w + 1] - begin[w]);
    };
    hierarchy::codePredictedRange(
        io, layout_, base_, n, st.cornerWedges(), faces_of,
        [&](uint32_t w) { return hierarchy::angleWeightedNormalAt(wpos, st.cornerWedges(), faces_of(w), w); },
        [](uint32_t) { return false; }, truth, st.normals, st.colors, &st.scalars, &wpos);
    shows_.resize(n);
    std::iota(shows_.begin(), shows_.end(), 0u);
  }
  // The decoded level's attributes, by wedge.
  void show(const PmState& st, QuantizedMesh& out) const {
    const uint32_t n = uint32_t(st.wv.size());
    if (layout_.hasNormals())
      for (uint32_t v = 0; v < n; ++v) out.normals.push_back(st.normals[shows_[v]]);
    if (layout_.hasColors())
      for (uint32_t v = 0; v < n; ++v) out.colors.push_back(st.colors[shows_[v]]);
    const size_t stride = size_t(layout_.scalarStride());
    if (stride) {
      out.scalars.reserve(size_t(n) * stride);
      for (uint32_t v = 0; v < n; ++v) {
        const auto row = st.scalars.begin() + ptrdiff_t(size_t(shows_[v]) * stride);
        out.scalars.insert(out.scalars.end(), row, row + ptrdiff_t(stride));
      }
    }
  }

 private:
  AttributeLayout layout_;
  uint32_t base_;
  std::vector<uint32_t> shows_;  // per wedge: the wedge whose attributes it shows
};

// One vertex split in the state's indices: k splits into k (at vs) and a new vertex (at vr).
struct Split {
  std::vector<uint8_t> moved;                           // per fan face: goes to the new vertex
  std::vector<std::pair<uint32_t, uint8_t>> new_faces;  // (third vertex w, 0: (k, r, w) / 1: (k, w, r))
  std::vector<std::array<uint32_t, 2>> new_wedges;      // encoder, per new face: the wedges of its k and w corners
  std::vector<std::pair<uint32_t, uint32_t>> created;   // after the split: (k's wedge, r's new wedge it pairs with)
  Vec3u vs{}, vr{};
};

// Which of `list` (v's distinct wedges) a new face's corner at v names: nothing when v has one; else whether it is
// `pred` (the wedge of a face beside it), then which other.
template <class C>
Status codeWedge(C& c, BitModel& same, std::span<const uint32_t> list, uint32_t pred, uint32_t& wedge) {
  if (list.empty()) return makeError(ErrorCode::kMalformed, "pm: a new face's corner has no wedge to take");
  uint32_t idx = 0;
  if constexpr (C::kEncode) {
    auto it = std::lower_bound(list.begin(), list.end(), wedge);
    if (it == list.end() || *it != wedge)
      return makeError(ErrorCode::kInternal, "pm: a new face's wedge is not among its vertex's");
    idx = uint32_t(it - list.begin());
  }
  if (list.size() == 1) return wedge = list[0], Status::ok();
  const auto p = std::lower_bound(list.begin(), list.end(), pred);
  const bool predicted = p != list.end() && *p == pred;
  uint32_t n = uint32_t(list.size());
  if (predicted) {
    const uint32_t pi = uint32_t(p - list.begin());
    int hit = idx == pi;
    c.bit(same, hit);
    if (hit) return wedge = pred, Status::ok();
    --n;
    if (C::kEncode && idx > pi) --idx;
    if (n > 1) c.uniform(idx, n);
    else idx = 0;
    if (idx >= pi) ++idx;
  } else {
    c.uniform(idx, n);
  }
  wedge = list[idx];
  return Status::ok();
}

int predictOrientation(const PmState& st, uint32_t k, const std::vector<uint32_t>& fan,
                       const std::vector<uint8_t>& moved, uint32_t w, bool& known) {
  known = true;
  for (int pass = 0; pass < 2; ++pass)
    for (size_t i = 0; i < fan.size(); ++i) {
      if (moved[i] != pass) continue;
      const auto [a, b] = st.others(fan[i], k);
      // A staying face with k->w asks for (k, r, w); a moving face (becoming r's) with r->w asks for (k, w, r).
      if (a == w) return pass == 0 ? 0 : 1;
      if (b == w) return pass == 0 ? 1 : 0;
    }
  known = false;
  return 0;
}

// `scale`: the bit length of a distance the residual is expected to be proportional to (the distance from v'_s to
// the prediction, about an edge length): residuals shrink from coarse to fine levels, and the scale follows them.
template <class C>
void codeResidual(C& c, Models& m, int kind, uint32_t scale, std::array<int64_t, 3>& d) {
  scale = std::min(scale, kScales - 1);
  uint32_t prev = 0;
  for (int a = 0; a < 3; ++a) {
    const uint64_t mag = C::kEncode ? uint64_t(d[a] < 0 ? -d[a] : d[a]) : 0;
    uint32_t b = bitLength(mag);
    const uint32_t rel = a == 0 ? 0 : 1 + uint32_t(std::clamp<int64_t>(int64_t(prev) - scale + 2, 0, kRelContexts - 1));
    c.sym(m.bucket[(kind * kScales + scale) * (1 + kRelContexts) + rel], b);
    if (b > 0) {
      int neg = C::kEncode ? int(d[a] < 0) : 0;
      c.bit(m.sign[kind], neg);
      uint32_t low = C::kEncode ? uint32_t(mag & ((uint64_t(1) << (b - 1)) - 1)) : 0;
      if (b > 1) c.bits(low, int(b - 1));
      const uint64_t value = (uint64_t(1) << (b - 1)) | low;
      if (!C::kEncode) d[a] = neg ? -int64_t(value) : int64_t(value);
    } else if (!C::kEncode) {
      d[a] = 0;
    }
    prev = b;
  }
}

uint32_t scaleOf(const Vec3u& x, const Vec3u& y) {
  uint64_t m = 0;
  for (int a = 0; a < 3; ++a) m = std::max<uint64_t>(m, x[a] > y[a] ? x[a] - y[a] : y[a] - x[a]);
  return bitLength(m);
}

// Codes the split of k (the encoder's `s` is filled in; the decoder's is filled here), then applies it. Fails only
// on the decoder's side, on input no encoder writes.
template <class C>
Status codeSplit(C& c, Models& m, PmState& st, uint32_t k, Split& s, uint32_t max_coord, uint64_t face_budget) {
  auto& fan = m.scratch.fan;
  auto& starts = m.scratch.starts;
  st.fan(k, fan, starts);
  if (!C::kEncode) s.moved.assign(fan.size(), 0);
  int prev = 0;
  for (size_t i = 0; i < fan.size(); ++i) {
    int b = s.moved[i];
    c.bit(m.moved[starts[i] ? 0 : 1 + prev], b);
    s.moved[i] = uint8_t(b);
    prev = b;
  }
  // Cut vertices and k's neighbours.
  auto &in_moved = m.scratch.in_moved, &in_stayed = m.scratch.in_stayed, &nbrs = m.scratch.nbrs;
  in_moved.clear(), in_stayed.clear(), nbrs.clear();
  for (size_t i = 0; i < fan.size(); ++i) {
    const auto [a, b] = st.others(fan[i], k);
    auto& list = s.moved[i] ? in_moved : in_stayed;
    list.push_back(a), list.push_back(b);
    nbrs.push_back(a), nbrs.push_back(b);
  }
  for (auto* l : {&in_moved, &in_stayed, &nbrs}) {
    std::sort(l->begin(), l->end());
    l->erase(std::unique(l->begin(), l->end()), l->end());
  }
  auto& cut = m.scratch.cut;
  cut.clear();
  std::set_intersection(in_moved.begin(), in_moved.end(), in_stayed.begin(), in_stayed.end(), std::back_inserter(cut));
  cut.erase(std::remove(cut.begin(), cut.end(), k), cut.end());
  // New faces: per cut vertex a count, then the others.
  auto& ordered = m.scratch.ordered;
  ordered.clear();
  auto& extra_w = m.scratch.extra_w;
  extra_w.clear();
  auto& extra_o = m.scratch.extra_o;
  extra_o.clear();
  if constexpr (C::kEncode) {
    for (const auto& [w, o] : s.new_faces)
      if (!std::binary_search(cut.begin(), cut.end(), w)) extra_w.push_back(w), extra_o.push_back(o);
  }
  for (uint32_t w : cut) {
    uint64_t count = 0;
    auto& orients = m.scratch.orients;
    orients.clear();
    if constexpr (C::kEncode) {
      for (const auto& [x, o] : s.new_faces)
        if (x == w) ++count, orients.push_back(o);
    }
    uint32_t sym = count >= 3 ? 3 : uint32_t(count);
    c.sym(m.cut_count, sym);
    count = sym;
    if (sym == 3) {
      uint64_t more = C::kEncode ? orients.size() - 3 : 0;
      codeCount(c, m.big_count, more);
      count = 3 + more;
    }
    if (count > face_budget) return makeError(ErrorCode::kMalformed, "pm: a split adds more faces than the level");
    face_budget -= count;
    if (!C::kEncode) orients.assign(count, 0);
    bool known = false;
    const int pred = predictOrientation(st, k, fan, s.moved, w, known);
    for (uint64_t i = 0; i < count; ++i) {
      int b = orients[i] ^ pred;
      c.bit(m.orient[known ? 0 : 1], b);
      ordered.push_back({w, uint8_t(b ^ pred)});
    }
  }
  uint64_t extras = extra_w.size();
  codeCount(c, m.extra_count, extras);
  if (extras > face_budget) return makeError(ErrorCode::kMalformed, "pm: a split adds more faces than the level");
  const uint32_t n = uint32_t(st.pos.size());
  for (uint64_t i = 0; i < extras; ++i) {
    uint32_t w = C::kEncode ? extra_w[i] : 0;
    uint32_t idx = uint32_t(nbrs.size());
    if constexpr (C::kEncode) {
      auto it = std::lower_bound(nbrs.begin(), nbrs.end(), w);
      if (it != nbrs.end() && *it == w) idx = uint32_t(it - nbrs.begin());
    }
    c.uniform(idx, uint32_t(nbrs.size()) + 1);
    if (idx < nbrs.size()) {
      w = nbrs[idx];
    } else {
      c.uniform(w, n);
    }
    if (w == k) return makeError(ErrorCode::kMalformed, "pm: a new face repeats the split vertex");
    bool known = false;
    const int pred = predictOrientation(st, k, fan, s.moved, w, known);
    int b = (C::kEncode ? extra_o[i] : 0) ^ pred;
    c.bit(m.orient[known ? 0 : 1], b);
    ordered.push_back({w, uint8_t(b ^ pred)});
  }
  // Geometry (section 3, with the neighbour-average prediction for every vertex that is not at v'_s).
  const Vec3u vp = st.pos[k];
  uint32_t placement = 2;
  if constexpr (C::kEncode) placement = s.vs == vp ? 0 : (s.vr == vp ? 1 : 2);
  c.sym(m.placement, placement);
  auto add = [&](const Vec3u& base, const std::array<int64_t, 3>& d, Vec3u& out) -> Status {
    for (int a = 0; a < 3; ++a) {
      const int64_t v = int64_t(base[a]) + d[a];
      if (v < 0 || v > int64_t(max_coord)) return makeError(ErrorCode::kMalformed, "pm: a split leaves the grid");
      out[a] = uint32_t(v);
    }
    return Status::ok();
  };
  auto diff = [](const Vec3u& x, const Vec3u& y) {
    return std::array<int64_t, 3>{int64_t(x[0]) - y[0], int64_t(x[1]) - y[1], int64_t(x[2]) - y[2]};
  };
  // The neighbours of the new vertex r and of k after the split, other than k and r themselves.
  auto &rn = m.scratch.rn, &kn = m.scratch.kn;
  rn.clear(), kn.clear();
  for (size_t i = 0; i < fan.size(); ++i) {
    const auto [a, b] = st.others(fan[i], k);
    auto& list = s.moved[i] ? rn : kn;
    list.push_back(a), list.push_back(b);
  }
  for (const auto& [w, o] : ordered) rn.push_back(w), kn.push_back(w);
  for (auto* l : {&rn, &kn}) {
    std::sort(l->begin(), l->end());
    l->erase(std::unique(l->begin(), l->end()), l->end());
  }
  // The rounded average of `list`'s positions plus `extra` (when `with_extra`); `fallback` when there is none.
  auto average = [&](const std::vector<uint32_t>& list, bool with_extra, const Vec3u& extra, const Vec3u& fallback) {
    int64_t sum[3] = {0, 0, 0};
    int64_t cnt = 0;
    for (uint32_t w : list) {
      if (w == k) continue;
      for (int a = 0; a < 3; ++a) sum[a] += st.pos[w][a];
      ++cnt;
    }
    if (with_extra) {
      for (int a = 0; a < 3; ++a) sum[a] += extra[a];
      ++cnt;
    }
    if (cnt == 0) return fallback;
    Vec3u out;
    for (int a = 0; a < 3; ++a) out[a] = uint32_t((sum[a] + cnt / 2) / cnt);
    return out;
  };
  const bool joined = !ordered.empty();  // k and r share a face after the split
  if (placement == 0) {
    s.vs = vp;
    const Vec3u pred = average(rn, joined, vp, vp);
    std::array<int64_t, 3> d = diff(s.vr, pred);
    codeResidual(c, m, 0, scaleOf(pred, vp), d);
    SP_RETURN_IF_ERROR(add(pred, d, s.vr));
  } else if (placement == 1) {
    s.vr = vp;
    const Vec3u pred = average(kn, joined, vp, vp);
    std::array<int64_t, 3> d = diff(s.vs, pred);
    codeResidual(c, m, 0, scaleOf(pred, vp), d);
    SP_RETURN_IF_ERROR(add(pred, d, s.vs));
  } else {
    // Delta_l: v_l from its neighbours other than k; then Delta_s from v_l mirrored through v'_s (exact for a
    // midpoint placement, close for the quadric optimum).
    const Vec3u pred_r = average(rn, false, vp, vp);
    std::array<int64_t, 3> dl = diff(s.vr, pred_r);
    codeResidual(c, m, 1, scaleOf(pred_r, vp), dl);
    SP_RETURN_IF_ERROR(add(pred_r, dl, s.vr));
    Vec3u pred_s;
    for (int a = 0; a < 3; ++a)
      pred_s[a] = uint32_t(std::clamp<int64_t>(2 * int64_t(vp[a]) - s.vr[a], 0, int64_t(max_coord)));
    std::array<int64_t, 3> ds = diff(s.vs, pred_s);
    codeResidual(c, m, 2, scaleOf(pred_s, vp), ds);
    SP_RETURN_IF_ERROR(add(pred_s, ds, s.vs));
  }
  // Wedges (v5): each new face's corners at k and at w name one of that vertex's wedges (a vertex with one wedge
  // codes nothing: every payload before v5). The prediction is the face beside it in k's fan that holds w, a
  // staying one first.
  auto& sc = m.scratch;
  sc.next(st.pos.size(), st.wv.size());
  auto &kw = sc.kw, &xw = sc.xw;
  st.wedgesOf(k, kw);  // k's faces are its fan
  // The predicting face of each vertex of the fan, in one pass (a new face then costs O(1), not a scan of the
  // fan), made when a corner has several wedges to choose from.
  bool predicted = false;
  const auto predict = [&] {
    if (predicted) return;
    predicted = true;
    for (uint8_t pass = 0; pass < 2; ++pass)
      for (size_t f = 0; f < fan.size(); ++f) {
        if (s.moved[f] != pass) continue;
        const auto [a, b] = st.others(fan[f], k);
        for (uint32_t x : {a, b})
          if (sc.vertex_stamp[x] != sc.stamp) sc.vertex_stamp[x] = sc.stamp, sc.pred_face[x] = fan[f];
      }
  };
  auto& wedges = m.scratch.wedges;
  wedges.assign(ordered.size(), {0, 0});
  auto& taken = m.scratch.taken;
  taken.assign(C::kEncode ? s.new_faces.size() : 0, 0);
  for (size_t i = 0; i < ordered.size(); ++i) {
    const uint32_t w = ordered[i].first;
    if constexpr (C::kEncode) {
      size_t j = 0;
      while (j < s.new_faces.size() && (taken[j] || s.new_faces[j] != ordered[i])) ++j;
      if (j == s.new_faces.size() || j >= s.new_wedges.size())
        return makeError(ErrorCode::kInternal, "pm: a new face has no wedges");
      taken[j] = 1;
      wedges[i] = s.new_wedges[j];
    }
    // w's wedges, once per split (a hostile split may give one vertex many new faces).
    if (sc.list_stamp[w] != sc.stamp) {
      st.wedgesOf(w, xw);
      sc.list_stamp[w] = sc.stamp, sc.list_begin[w] = uint32_t(sc.lists.size()), sc.list_size[w] = uint32_t(xw.size());
      sc.lists.insert(sc.lists.end(), xw.begin(), xw.end());
    }
    const std::span<const uint32_t> wl(sc.lists.data() + sc.list_begin[w], sc.list_size[w]);
    uint32_t pk = UINT32_MAX, px = UINT32_MAX;
    if (kw.size() > 1 || wl.size() > 1) {
      predict();
      if (sc.vertex_stamp[w] == sc.stamp) pk = st.wedgeAt(sc.pred_face[w], k), px = st.wedgeAt(sc.pred_face[w], w);
    }
    SP_RETURN_IF_ERROR(codeWedge(c, m.wedge_same[0], kw, pk, wedges[i][0]));
    SP_RETURN_IF_ERROR(codeWedge(c, m.wedge_same[1], wl, px, wedges[i][1]));
  }
  const uint32_t r = n;
  // Apply. r gets a new wedge per wedge of k that its corners pair with, in the order they are met.
  s.created.clear();
  auto wedgeOfR = [&](uint32_t a) {  // a: one of k's wedges, below the count at the split's start
    if (sc.wedge_stamp[a] == sc.stamp) return sc.r_wedge[a];
    const uint32_t id = uint32_t(st.wv.size());
    st.addWedge(r, a);
    s.created.push_back({a, id});
    sc.wedge_stamp[a] = sc.stamp, sc.r_wedge[a] = id;
    return id;
  };
  st.pos[k] = s.vs;
  st.pos.push_back(s.vr);
  st.wedge_count.push_back(0);
  st.first_wedge.push_back(0);
  st.vf.emplace_back();
  std::vector<uint32_t> stay;
  stay.reserve(fan.size());
  for (size_t i = 0; i < fan.size(); ++i) {
    if (!s.moved[i]) {
      stay.push_back(fan[i]);
      continue;
    }
    Triangle& t = st.faces[fan[i]];
    for (int j = 0; j < 3; ++j) {
      if (t[j] != k) continue;
      t[j] = r;
      if (st.identity) wedgeOfR(k);  // r's one wedge, id r
      else st.fw[fan[i]][j] = wedgeOfR(st.fw[fan[i]][j]);
    }
    st.vf[r].push_back(fan[i]);
  }
  st.vf[k] = std::move(stay);
  for (size_t i = 0; i < ordered.size(); ++i) {
    const auto [w, o] = ordered[i];
    const uint32_t a = wedges[i][0], b = wedges[i][1], rw = wedgeOfR(a);
    if (o) st.addFace(Triangle{k, w, r}, Triangle{a, b, rw});
    else st.addFace(Triangle{k, r, w}, Triangle{a, rw, b});
  }
  // A split that gives r no face (no encoder writes one) still gives it a wedge: every vertex has one, and `identity`
  // keeps its ids.
  if (st.wedge_count[r] == 0) wedgeOfR(st.first_wedge[k]);
  return Status::ok();
}

struct LevelEntry {
  uint64_t batches = 0, vertices = 0, faces = 0, bytes = 0;
  uint64_t wedges = 0;  // v5 (before: the vertices)
  float error = 0;
};
struct Header {
  uint8_t base_codec = 0;
  uint64_t base_version = 0, base_bytes = 0, base_vertices = 0, base_faces = 0;
  float base_error = 0;
  std::vector<LevelEntry> levels;
  size_t base_offset = 0;  // where the base payload starts
  bool wedges = false;     // v5: base_vertices and the levels' wedges count wedges
  // v5: the base wedges (canonical index, group) that are not their position's first vertex's (initialState).
  std::vector<std::pair<uint64_t, uint64_t>> groups;
};

void putF32(ByteWriter& w, float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  w.u32(u);
}

Status checkVersion(uint16_t version) {
  if (version < 1 || version > kVersion)
    return makeError(ErrorCode::kUnknownVersion,
                     "pm codec version " + std::to_string(version) + " is not known to this build (knows 1 to 5)");
  return Status::ok();
}

Result<Header> parseHeader(std::span<const uint8_t> payload, const DecodeLimits& limits, uint16_t version) {
  ByteReader r(payload, "pm payload");
  Header h;
  h.wedges = version >= kWedgesFrom;
  SP_RETURN_IF_ERROR(r.u8(h.base_codec));
  if (h.base_codec < 1 || h.base_codec > 3) return r.error(ErrorCode::kMalformed, "unknown base codec");
  SP_RETURN_IF_ERROR(r.varint(h.base_version));
  if (h.base_version > UINT16_MAX) return r.error(ErrorCode::kMalformed, "base codec version out of range");
  SP_RETURN_IF_ERROR(r.varint(h.base_bytes));
  SP_RETURN_IF_ERROR(r.varint(h.base_vertices));
  SP_RETURN_IF_ERROR(r.varint(h.base_faces));
  SP_RETURN_IF_ERROR(checkLimits("pm base mesh", h.base_vertices, h.base_faces, limits));
  uint32_t u = 0;
  SP_RETURN_IF_ERROR(r.u32(u));
  std::memcpy(&h.base_error, &u, 4);
  if (h.wedges) {
    uint64_t g = 0;
    SP_RETURN_IF_ERROR(r.varint(g));
    if (g > r.remaining() / 2 || g > h.base_vertices)
      return r.error(ErrorCode::kMalformed, "more wedge groups than the base has wedges");
    h.groups.resize(g);
    uint64_t prev = 0;
    for (auto& [index, group] : h.groups) {
      uint64_t gap = 0;
      SP_RETURN_IF_ERROR(r.varint(gap));
      SP_RETURN_IF_ERROR(r.varint(group));
      if (gap == 0 || gap > h.base_vertices - prev || group == 0)
        return r.error(ErrorCode::kMalformed, "inconsistent wedge group");
      index = prev += gap;
    }
  }
  uint64_t count = 0;
  SP_RETURN_IF_ERROR(r.varint(count));
  // Every level entry takes at least 8 bytes: the count is bounded by the bytes left before anything is allocated.
  if (count > r.remaining() / 8) return r.error(ErrorCode::kMalformed, "more levels than the payload could hold");
  h.levels.resize(count);
  // v5: the base's vertices are wedges, and its positions are known only once it is decoded.
  uint64_t prev_v = h.wedges ? 0 : h.base_vertices, prev_f = h.base_faces, prev_w = h.base_vertices;
  for (auto& l : h.levels) {
    SP_RETURN_IF_ERROR(r.varint(l.batches));
    SP_RETURN_IF_ERROR(r.varint(l.vertices));
    l.wedges = l.vertices;
    if (h.wedges) SP_RETURN_IF_ERROR(r.varint(l.wedges));
    SP_RETURN_IF_ERROR(r.varint(l.faces));
    SP_RETURN_IF_ERROR(r.u32(u));
    std::memcpy(&l.error, &u, 4);
    SP_RETURN_IF_ERROR(r.varint(l.bytes));
    SP_RETURN_IF_ERROR(checkLimits("pm level", l.wedges, l.faces, limits));
    // Every batch adds a vertex (and a wedge); v5's first level is checked against the decoded base (decodeImpl).
    if (l.vertices < prev_v || l.wedges < l.vertices || l.wedges < prev_w || l.faces < prev_f || l.batches == 0 ||
        l.batches > l.wedges - prev_w + 1 || (prev_v > 0 && l.batches > l.vertices - prev_v + 1) ||
        l.bytes > (uint64_t(1) << 40))
      return r.error(ErrorCode::kMalformed, "inconsistent level entry");
    prev_v = l.vertices, prev_f = l.faces, prev_w = l.wedges;
  }
  h.base_offset = r.position();
  return h;
}

std::vector<CodecLevel> levelsOf(const Header& h) {
  std::vector<CodecLevel> out;
  uint64_t end = h.base_offset + h.base_bytes;
  CodecLevel base;
  base.level = 0;
  base.end_bytes = end;
  base.kind = LevelKind::kSimplified;
  base.vertices = h.base_vertices;
  base.max_error = h.base_error;
  base.complete = h.levels.empty();
  out.push_back(base);
  for (size_t i = 0; i < h.levels.size(); ++i) {
    end += h.levels[i].bytes;
    CodecLevel l = base;
    l.level = uint32_t(i + 1);
    l.end_bytes = end;
    l.vertices = h.levels[i].wedges;
    l.max_error = h.levels[i].error;
    l.complete = i + 1 == h.levels.size();
    out.push_back(l);
  }
  return out;
}

// Stable sort of vertex indices by position: the canonical order both sides give the base mesh.
std::vector<uint32_t> canonicalOrder(const std::vector<Vec3u>& pos) {
  std::vector<uint32_t> order(pos.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return pos[a] < pos[b]; });
  return order;
}

// The base mesh in canonical order as the state to split from: its vertices are the wedges. Before v5 (`groups`
// null) each is a state vertex of its own (the same ids). In v5 the wedges at one position are one vertex's, its
// position's first (group 0), unless `groups` (ascending canonical indices) names another: group g < the groups met
// at that position so far is the g-th vertex there, g equal to it a new one (two points the simplifier moved into
// one cell). nullopt on a group no vertex has.
std::optional<PmState> initialState(const QuantizedMesh& base, const std::vector<std::pair<uint64_t, uint64_t>>* groups,
                                    std::vector<uint32_t>* order_out) {
  const std::vector<uint32_t> order = canonicalOrder(base.positions);
  std::vector<uint32_t> rank(order.size());
  for (uint32_t i = 0; i < order.size(); ++i) rank[order[i]] = i;
  PmState st;
  st.pos.reserve(order.size());
  st.wv.reserve(order.size());
  std::vector<uint32_t> here;  // the state vertices at the current position, by group
  size_t next = 0;
  for (uint32_t i = 0; i < order.size(); ++i) {
    const Vec3u& p = base.positions[order[i]];
    uint64_t g = 0;
    if (groups && next < groups->size() && (*groups)[next].first == i) g = (*groups)[next++].second;
    if (!groups || i == 0 || p != base.positions[order[i - 1]]) {
      if (g != 0) return std::nullopt;
      here.clear();
    }
    if (g > here.size()) return std::nullopt;
    if (g == here.size()) here.push_back(uint32_t(st.pos.size())), st.pos.push_back(p);
    st.wv.push_back(here[g]);
  }
  if (groups && next != groups->size()) return std::nullopt;
  if (!base.normals.empty())
    for (uint32_t v : order) st.normals.push_back(base.normals[v]);
  if (!base.colors.empty())
    for (uint32_t v : order) st.colors.push_back(base.colors[v]);
  if (!base.scalars.empty() && !base.positions.empty()) {
    const size_t stride = base.scalars.size() / base.positions.size();
    st.scalars.reserve(base.scalars.size());
    for (uint32_t v : order)
      st.scalars.insert(st.scalars.end(), base.scalars.begin() + ptrdiff_t(v * stride),
                        base.scalars.begin() + ptrdiff_t((v + 1) * stride));
  }
  st.vf.resize(st.pos.size());
  st.parent.resize(order.size());
  std::iota(st.parent.begin(), st.parent.end(), 0u);
  st.wedge_count.assign(st.pos.size(), 0);
  st.first_wedge.assign(st.pos.size(), 0);
  for (uint32_t w = 0; w < st.wv.size(); ++w)
    if (st.wedge_count[st.wv[w]]++ == 0) st.first_wedge[st.wv[w]] = w;
  st.identity = st.wv.size() == st.pos.size();  // one wedge per vertex, in vertex order (initialState's numbering)
  for (const auto& t : base.triangles) {
    const Triangle w{rank[t[0]], rank[t[1]], rank[t[2]]};
    st.addFace({st.wv[w[0]], st.wv[w[1]], st.wv[w[2]]}, w);
  }
  if (order_out) *order_out = order;
  return st;
}

Result<QuantizedMesh> decodeImpl(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                 uint32_t level, const DecodeLimits& limits) {
  SP_RETURN_IF_ERROR(checkVersion(version));
  if (ctx.layout.hasScalars() && version < kScalarsFrom)
    return makeError(ErrorCode::kMalformed, "pm payload of version " + std::to_string(version) +
                                                " in a container with scalar channels (those carry none)");
  if (version >= kWedgesFrom && !ctx.layout.hasNormals() && !ctx.layout.hasColors() && !ctx.layout.hasScalars())
    return makeError(ErrorCode::kMalformed, "pm payload of version " + std::to_string(version) +
                                                " in a container without attributes (its wedges would have none)");
  SP_ASSIGN_OR_RETURN(Header h, parseHeader(payload, limits, version));
  const uint32_t target = std::min<uint32_t>(level, uint32_t(h.levels.size()));
  if (h.base_bytes > payload.size() - h.base_offset)
    return makeError(ErrorCode::kTruncated, "pm payload ends inside its base mesh");
  const CodecInfo* base_codec = findCodec(CodecId(h.base_codec));
  if (!base_codec) return makeError(ErrorCode::kMalformed, "pm: unknown base codec");
  const bool attributes = version >= kAttributesFrom &&
                          (ctx.layout.hasNormals() || ctx.layout.hasColors() || ctx.layout.hasScalars());
  const TileContext base_ctx{ctx.bits, attributes ? ctx.layout : AttributeLayout{}};
  SP_ASSIGN_OR_RETURN(QuantizedMesh base,
                      base_codec->decode(base_ctx, uint16_t(h.base_version),
                                         payload.subspan(h.base_offset, h.base_bytes),
                                         DecodeLimits{uint32_t(h.base_vertices), uint32_t(h.base_faces)}));
  if (base.positions.size() != h.base_vertices || base.triangles.size() != h.base_faces)
    return makeError(ErrorCode::kMalformed, "pm: the base mesh does not have the counts the header gives");
  if (attributes && ((ctx.layout.hasNormals() && base.normals.size() != base.positions.size()) ||
                     (ctx.layout.hasColors() && base.colors.size() != base.positions.size()) ||
                     base.scalars.size() != base.positions.size() * size_t(ctx.layout.scalarStride())))
    return makeError(ErrorCode::kMalformed, "pm: the base mesh lacks the layout's attributes");
  const uint64_t final_v = target == 0 ? h.base_vertices : h.levels[target - 1].vertices;
  const uint64_t final_f = target == 0 ? h.base_faces : h.levels[target - 1].faces;
  std::optional<PmState> initial = initialState(base, h.wedges ? &h.groups : nullptr, nullptr);
  if (!initial) return makeError(ErrorCode::kMalformed, "pm: a wedge group of the base names no vertex");
  PmState st = std::move(*initial);
  for (const auto& t : st.faces)
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2])
      return makeError(ErrorCode::kMalformed, "pm: a base triangle repeats a vertex");
  if (!h.levels.empty() &&
      (h.levels[0].vertices < st.pos.size() || h.levels[0].batches > h.levels[0].vertices - st.pos.size() + 1))
    return makeError(ErrorCode::kMalformed, "pm: level 1 does not follow the base");
  st.pos.reserve(final_v);
  st.vf.reserve(final_v);
  st.faces.reserve(final_f);
  const uint32_t max_coord = uint32_t((uint64_t(1) << ctx.bits) - 1);
  Models m;
  LevelAttributes level_attributes(ctx.layout, attributes ? uint32_t(h.base_vertices) : 0);
  std::vector<uint32_t> blocked;  // == mark: within two edges of a split of the current batch
  uint32_t mark = 0;
  size_t offset = h.base_offset + h.base_bytes;
  for (uint32_t li = 0; li < target; ++li) {
    const LevelEntry& le = h.levels[li];
    if (le.bytes > payload.size() - offset)
      return makeError(ErrorCode::kTruncated, "pm payload ends inside level " + std::to_string(li + 1));
    RangeDecoder rd(payload.subspan(offset, le.bytes));
    DecodeSide c{rd};
    Split s;
    for (uint64_t b = 0; b < le.batches; ++b) {
      const uint32_t n_start = uint32_t(st.pos.size());
      ++mark;
      int prev = 0;
      for (uint32_t v = 0; v < n_start; ++v) {
        if (v < blocked.size() && blocked[v] == mark) continue;
        int flag = 0;
        c.bit(m.flag[prev], flag);
        prev = flag;
        if (!flag) continue;
        if (st.pos.size() >= le.vertices)
          return makeError(ErrorCode::kMalformed, "pm: level " + std::to_string(li + 1) + " splits too many vertices");
        SP_RETURN_IF_ERROR(codeSplit(c, m, st, v, s, max_coord, le.faces - st.faces.size()));
        if (st.wv.size() > le.wedges)
          return makeError(ErrorCode::kMalformed, "pm: level " + std::to_string(li + 1) + " adds too many wedges");
        st.block(v, uint32_t(st.pos.size() - 1), blocked, mark);
        if (rd.overrun()) return makeError(ErrorCode::kTruncated, "pm: level stream ends early");
      }
      // Checked per batch too: a stream that runs dry must not make the decoder walk every vertex per batch.
      if (rd.overrun()) return makeError(ErrorCode::kTruncated, "pm: level stream ends early");
    }
    if (attributes) {
      AttributeDecodeIo io{rd};
      level_attributes.endLevel(io, st, li + 1 == h.levels.size(), nullptr);
    }
    if (rd.overrun()) return makeError(ErrorCode::kTruncated, "pm: level stream ends early");
    if (st.pos.size() != le.vertices || st.wv.size() != le.wedges || st.faces.size() != le.faces)
      return makeError(ErrorCode::kMalformed,
                       "pm: level " + std::to_string(li + 1) + " does not have the counts its entry gives");
    offset += le.bytes;
  }
  QuantizedMesh out;
  if (attributes) level_attributes.show(st, out);
  out.positions.reserve(st.wv.size());
  for (uint32_t v : st.wv) out.positions.push_back(st.pos[v]);
  out.triangles = st.identity ? std::move(st.faces) : std::move(st.fw);
  if (!attributes) {
    deriveAttributes(out, ctx.layout);
  }
  SP_RETURN_IF_ERROR(validateTile(ctx, out));
  return out;
}

// What the encoder records per collapse while it replays the simplification forwards (last-level indices).
struct CollapseRecord {
  uint32_t kept = 0, removed = 0;
  Vec3u vs{}, vr{}, vp{};
  std::vector<std::pair<uint32_t, uint32_t>> moved;  // faces (kept, a, b) after the collapse, as (a, b)
  std::vector<std::pair<uint32_t, uint8_t>> new_faces;  // deleted faces: (w, 0: (kept, removed, w) / 1: (kept, w, removed))
  std::vector<std::array<uint32_t, 2>> new_wedges;   // per deleted face: the wedges of its kept and w corners
  std::vector<std::pair<uint32_t, uint32_t>> pairs;  // (kept's wedge, removed's wedge) the deleted faces pair
};

std::array<uint32_t, 3> rotateMin(const Triangle& t) {
  int i = 0;
  if (t[1] < t[i]) i = 1;
  if (t[2] < t[i]) i = 2;
  return {t[i], t[(i + 1) % 3], t[(i + 2) % 3]};
}

std::vector<std::array<uint32_t, 3>> faceKeys(const std::vector<Triangle>& faces) {
  std::vector<std::array<uint32_t, 3>> keys;
  keys.reserve(faces.size());
  for (const auto& t : faces) keys.push_back(rotateMin(t));
  std::sort(keys.begin(), keys.end());
  return keys;
}

// Faces over positions with their corners' wedges, each rotated to start at its least position, sorted: two meshes
// over the same positions and wedges have the same faces exactly when these are equal.
std::vector<std::array<uint32_t, 6>> wedgeFaceKeys(const std::vector<Triangle>& faces,
                                                   const std::vector<Triangle>& wedges) {
  std::vector<std::array<uint32_t, 6>> keys;
  keys.reserve(faces.size());
  for (size_t f = 0; f < faces.size(); ++f) {
    const Triangle& t = faces[f];
    const int i = t[1] < t[0] ? (t[2] < t[1] ? 2 : 1) : (t[2] < t[0] ? 2 : 0);
    std::array<uint32_t, 6> k;
    for (int j = 0; j < 3; ++j) k[j] = t[(i + j) % 3], k[3 + j] = wedges[f][(i + j) % 3];
    keys.push_back(k);
  }
  std::sort(keys.begin(), keys.end());
  return keys;
}

// The tile as pm codes it: triangles over positions, and the wedges of their corners (v5). A wedge is a position's
// set of attributes; wedges of one position are consecutive and in position order.
struct WedgedMesh {
  QuantizedMesh mesh;                  // positions and the triangles over them (no attributes)
  std::vector<uint8_t> locked;         // per position
  std::vector<Triangle> corners;       // per triangle: its corners' wedges
  std::vector<uint32_t> wedge_vertex;  // per wedge: its position
  QuantizedMesh attrs;                 // per wedge: normals, colors, scalar rows (no positions)
  bool wedged() const { return wedge_vertex.size() > mesh.positions.size(); }
};

// The part of `from` that is left: the positions `keep` marks (at `positions`), the triangles `tris` over from's
// positions and their corners' wedges `corners`. A kept position keeps the wedges these use, or its first when they
// use none (a point without triangles); both are renumbered in order. `wedge_map` gets from's wedge -> the result's.
WedgedMesh compact(const WedgedMesh& from, const std::vector<Vec3u>& positions, std::span<const uint8_t> keep,
                   const std::vector<Triangle>& tris, const std::vector<Triangle>& corners,
                   std::vector<uint32_t>* wedge_map, size_t stride) {
  const size_t np = from.mesh.positions.size(), nw = from.wedge_vertex.size();
  std::vector<uint8_t> used(nw, 0), pos_used(np, 0);
  for (const Triangle& c : corners)
    for (uint32_t w : c) used[w] = 1, pos_used[from.wedge_vertex[w]] = 1;
  WedgedMesh out;
  std::vector<uint32_t> pmap(np, UINT32_MAX), wmap(nw, UINT32_MAX);
  for (uint32_t p = 0; p < np; ++p)
    if (keep[p]) {
      pmap[p] = uint32_t(out.mesh.positions.size());
      out.mesh.positions.push_back(positions[p]);
      out.locked.push_back(from.locked[p]);
    }
  for (uint32_t w = 0; w < nw; ++w) {
    const uint32_t p = from.wedge_vertex[w];
    const bool first = w == 0 || from.wedge_vertex[w - 1] != p;
    if (!keep[p] || !(used[w] || (!pos_used[p] && first))) continue;
    wmap[w] = uint32_t(out.wedge_vertex.size());
    out.wedge_vertex.push_back(pmap[p]);
    if (!from.attrs.normals.empty()) out.attrs.normals.push_back(from.attrs.normals[w]);
    if (!from.attrs.colors.empty()) out.attrs.colors.push_back(from.attrs.colors[w]);
    if (stride)
      out.attrs.scalars.insert(out.attrs.scalars.end(), from.attrs.scalars.begin() + ptrdiff_t(w * stride),
                               from.attrs.scalars.begin() + ptrdiff_t((w + 1) * stride));
  }
  for (size_t f = 0; f < tris.size(); ++f) {
    const Triangle& t = tris[f];
    out.mesh.triangles.push_back({pmap[t[0]], pmap[t[1]], pmap[t[2]]});
    out.corners.push_back({wmap[corners[f][0]], wmap[corners[f][1]], wmap[corners[f][2]]});
  }
  if (wedge_map) *wedge_map = std::move(wmap);
  return out;
}

// Orders two vertices (of meshes with one layout) by position, then normal, color (the layout's channels: decoders
// give RGB alpha 255) and scalar row.
int compareVertices(const QuantizedMesh& a, uint32_t i, const QuantizedMesh& b, uint32_t j,
                    const AttributeLayout& layout) {
  // Element by element: std::array's comparisons call memcmp, and the weld sorts every point of the tile with this.
  for (int k = 0; k < 3; ++k)
    if (a.positions[i][k] != b.positions[j][k]) return a.positions[i][k] < b.positions[j][k] ? -1 : 1;
  if (layout.hasNormals())
    for (int k = 0; k < 2; ++k)
      if (a.normals[i][k] != b.normals[j][k]) return a.normals[i][k] < b.normals[j][k] ? -1 : 1;
  for (int c = 0; c < layout.color_channels; ++c)
    if (a.colors[i][c] != b.colors[j][c]) return a.colors[i][c] < b.colors[j][c] ? -1 : 1;
  const size_t stride = size_t(layout.scalarStride());
  for (size_t k = 0; k < stride; ++k) {
    const uint32_t x = a.scalars[i * stride + k], y = b.scalars[j * stride + k];
    if (x != y) return x < y ? -1 : 1;
  }
  return 0;
}

std::vector<uint32_t> flatten(const std::vector<Triangle>& corners) {
  std::vector<uint32_t> out;
  out.reserve(3 * corners.size());
  for (const Triangle& c : corners) out.insert(out.end(), c.begin(), c.end());
  return out;
}

Result<EncodedTile> pmEncodeImpl(const TileContext& ctx, const TileView& tile, const CodecOptions& options) {
  const QuantizedMesh& in = tile.mesh;
  if (in.positions.size() >= UINT32_MAX || in.triangles.size() >= UINT32_MAX)
    return makeError(ErrorCode::kLimitExceeded, "tile has more than 2^32-2 vertices or triangles");
  const AttributeLayout& layout = ctx.layout;
  const bool with_normals = layout.hasNormals(), with_colors = layout.hasColors();
  const size_t stride = size_t(layout.scalarStride());
  const bool attributes = with_normals || with_colors || stride > 0;
  if ((with_normals && in.normals.size() != in.positions.size()) ||
      (with_colors && in.colors.size() != in.positions.size()) || in.scalars.size() != in.positions.size() * stride)
    return makeError(ErrorCode::kInvalidArgument, "pm: the tile lacks the layout's attributes");
  const auto scalarRow = [stride](const ScalarValues& values, uint32_t v) {
    return std::span<const uint32_t>(values.data() + size_t(v) * stride, stride);
  };
  const auto appendRow = [](ScalarValues& to, std::span<const uint32_t> row) {
    to.insert(to.end(), row.begin(), row.end());
  };
  // Weld by position (lock flags are OR-ed). The input vertices at one position with the same attributes are one
  // wedge; a position keeps the wedges its triangles' corners use (two at a crease or a texture seam: v5), or its
  // first when none does. Points at a position whose wedge nothing uses are merged into the others (counted).
  WedgedMesh welded;
  uint64_t merged = 0;
  {
    std::vector<uint32_t> order(in.positions.size());
    std::iota(order.begin(), order.end(), 0u);
    std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
      const int c = compareVertices(in, a, in, b, layout);
      return c != 0 ? c < 0 : a < b;
    });
    std::vector<uint32_t> pos_of(in.positions.size()), wedge_of(in.positions.size()), first_of;
    for (uint32_t i = 0; i < order.size(); ++i) {
      const uint32_t v = order[i];
      if (i == 0 || in.positions[v] != welded.mesh.positions.back()) {
        welded.mesh.positions.push_back(in.positions[v]);
        welded.locked.push_back(0);
      }
      if (i == 0 || compareVertices(in, order[i - 1], in, v, layout) != 0) {
        first_of.push_back(v);
        welded.wedge_vertex.push_back(uint32_t(welded.mesh.positions.size() - 1));
      }
      pos_of[v] = uint32_t(welded.mesh.positions.size() - 1);
      wedge_of[v] = uint32_t(first_of.size() - 1);
      if (!tile.locked.empty() && tile.locked[v]) welded.locked.back() = 1;
    }
    for (uint32_t v : first_of) {
      if (with_normals) welded.attrs.normals.push_back(in.normals[v]);
      if (with_colors) welded.attrs.colors.push_back(in.colors[v]);
      if (stride) appendRow(welded.attrs.scalars, scalarRow(in.scalars, v));
    }
    for (const auto& t : in.triangles) {
      for (uint32_t v : t)
        if (v >= in.positions.size()) return makeError(ErrorCode::kInvalidArgument, "triangle index out of range");
      const Triangle w{pos_of[t[0]], pos_of[t[1]], pos_of[t[2]]};
      if (w[0] != w[1] && w[1] != w[2] && w[0] != w[2]) {
        welded.mesh.triangles.push_back(w);
        welded.corners.push_back({wedge_of[t[0]], wedge_of[t[1]], wedge_of[t[2]]});
      }
    }
    std::vector<uint32_t> wmap;
    const std::vector<uint8_t> all(welded.mesh.positions.size(), 1);
    WedgedMesh kept = compact(welded, welded.mesh.positions, all, welded.mesh.triangles, welded.corners, &wmap, stride);
    for (uint32_t v = 0; v < in.positions.size(); ++v) merged += wmap[wedge_of[v]] == UINT32_MAX;
    welded = std::move(kept);
  }
  const bool wedged = welded.wedged();
  const PmOptions& opt = options.pm;
  // The last level.
  WedgedMesh last;
  float last_error = 0;
  if (opt.max_error < 0 && opt.ratio >= 1) {
    last = std::move(welded);
  } else {
    SimplifyOptions so;
    so.weights = opt.weights;
    so.max_error = opt.max_error < 0 ? std::numeric_limits<double>::infinity() : opt.max_error;
    so.target_faces =
        opt.ratio < 1 ? uint64_t(std::ceil(std::max(0.0, opt.ratio) * double(welded.mesh.triangles.size()))) : 0;
    const std::vector<uint32_t> corners = wedged ? flatten(welded.corners) : std::vector<uint32_t>{};
    SP_ASSIGN_OR_RETURN(Simplification s1, simplify(welded.mesh, welded.locked, so, corners));
    if (!s1.pass_errors.empty()) last_error = s1.pass_errors.back();
    std::vector<uint8_t> keep(welded.mesh.positions.size(), 1);
    for (const auto& c : s1.collapses) {
      if (c.removed >= keep.size()) return makeError(ErrorCode::kInternal, "pm: simplifier removed an unknown vertex");
      keep[c.removed] = 0;
    }
    for (const auto& t : s1.mesh.triangles)
      if (!keep[t[0]] || !keep[t[1]] || !keep[t[2]])
        return makeError(ErrorCode::kInternal, "pm: simplified mesh uses a removed vertex");
    std::vector<Triangle> s1_corners;
    if (wedged) {
      for (size_t f = 0; f < s1.mesh.triangles.size(); ++f)
        s1_corners.push_back({s1.corner_wedges[3 * f], s1.corner_wedges[3 * f + 1], s1.corner_wedges[3 * f + 2]});
    } else {
      s1_corners = s1.mesh.triangles;  // one wedge per position, with its id
    }
    last = compact(welded, s1.mesh.positions, keep, s1.mesh.triangles, s1_corners, nullptr, stride);
  }
  // Simplify further to the base.
  SimplifyOptions so2;
  so2.weights = opt.weights;
  // The splits from the base back to the last level code one position each when their collapses keep an endpoint
  // (bench/RESULTS.md: igea, 16 bits, lossless, 58.3 bpv with optimal placements); the last level itself keeps the
  // simplifier's best placements.
  so2.endpoints_only = true;
  so2.target_faces = std::max<uint64_t>(kBaseMinFaces, uint64_t(double(last.mesh.triangles.size()) * kBaseFaceShare));
  Simplification s2;
  if (last.mesh.triangles.size() > so2.target_faces) {
    const std::vector<uint32_t> corners = wedged ? flatten(last.corners) : std::vector<uint32_t>{};
    SP_ASSIGN_OR_RETURN(s2, simplify(last.mesh, last.locked, so2, corners));
  }
  // Replay forwards, recording each collapse.
  const uint32_t nl = uint32_t(last.mesh.positions.size());
  const uint32_t nw = uint32_t(last.wedge_vertex.size());
  std::vector<CollapseRecord> records(s2.collapses.size());
  PmState fw;
  fw.pos = last.mesh.positions;
  fw.vf.resize(nl);
  for (size_t f = 0; f < last.mesh.triangles.size(); ++f) fw.addFace(last.mesh.triangles[f], last.corners[f]);
  std::vector<uint8_t> alive_face(fw.faces.size(), 1), alive_v(nl, 1);
  for (size_t ci = 0; ci < s2.collapses.size(); ++ci) {
    const EdgeCollapse& c = s2.collapses[ci];
    if (c.kept >= nl || c.removed >= nl || c.kept == c.removed || !alive_v[c.kept] || !alive_v[c.removed])
      return makeError(ErrorCode::kInternal, "pm: invalid collapse from the simplifier");
    CollapseRecord& rec = records[ci];
    rec.kept = c.kept, rec.removed = c.removed;
    rec.vs = fw.pos[c.kept], rec.vr = fw.pos[c.removed], rec.vp = c.position;
    for (uint32_t f : fw.vf[c.removed]) {
      const Triangle& t = fw.faces[f];
      if (alive_face[f] && (t[0] == c.kept || t[1] == c.kept || t[2] == c.kept))
        rec.pairs.push_back({fw.wedgeAt(f, c.kept), fw.wedgeAt(f, c.removed)});
    }
    for (uint32_t f : fw.vf[c.removed]) {
      if (!alive_face[f]) continue;
      Triangle& t = fw.faces[f];
      const bool has_k = t[0] == c.kept || t[1] == c.kept || t[2] == c.kept;
      if (has_k) {
        alive_face[f] = 0;
        const auto [a, b] = fw.others(f, c.kept);
        const uint32_t w = a == c.removed ? b : a;
        rec.new_faces.push_back({w, a == c.removed ? 0 : 1});
        rec.new_wedges.push_back({fw.wedgeAt(f, c.kept), fw.wedgeAt(f, w)});
        continue;
      }
      for (int j = 0; j < 3; ++j) {
        if (t[j] != c.removed) continue;
        t[j] = c.kept;
        uint32_t& wedge = fw.fw[f][j];
        auto it = std::find_if(rec.pairs.begin(), rec.pairs.end(), [&](const auto& p) { return p.second == wedge; });
        if (it == rec.pairs.end()) return makeError(ErrorCode::kInternal, "pm: a collapse leaves a wedge unpaired");
        wedge = it->first;
      }
      fw.vf[c.kept].push_back(f);
      rec.moved.push_back(fw.others(f, c.kept));
    }
    std::sort(rec.moved.begin(), rec.moved.end());
    fw.vf[c.removed].clear();
    alive_v[c.removed] = 0;
    fw.pos[c.kept] = c.position;
  }
  // The base mesh (a vertex per wedge), and each base codec's encoding of it decoded back.
  std::vector<Triangle> base_tris, base_corners;
  for (uint32_t f = 0; f < fw.faces.size(); ++f)
    if (alive_face[f]) base_tris.push_back(fw.faces[f]), base_corners.push_back(fw.fw[f]);
  std::vector<uint32_t> last_to_base;
  const WedgedMesh bw = compact(last, fw.pos, alive_v, base_tris, base_corners, &last_to_base, stride);
  std::vector<uint32_t> base_to_last(bw.wedge_vertex.size());
  for (uint32_t w = 0; w < nw; ++w)
    if (last_to_base[w] != UINT32_MAX) base_to_last[last_to_base[w]] = w;
  QuantizedMesh base = bw.attrs;
  for (uint32_t p : bw.wedge_vertex) base.positions.push_back(bw.mesh.positions[p]);
  base.triangles = bw.corners;
  const TileContext base_ctx{ctx.bits, attributes ? layout : AttributeLayout{}};
  // Decoded vertices are found by position and attributes (unique unless the simplifier moved two points of the
  // base onto one position with the same ones; then only an order-keeping decode is used).
  std::vector<uint32_t> sorted_base(base.positions.size());
  std::iota(sorted_base.begin(), sorted_base.end(), 0u);
  std::stable_sort(sorted_base.begin(), sorted_base.end(),
                   [&](uint32_t a, uint32_t b) { return compareVertices(base, a, base, b, layout) < 0; });
  bool unique_keys = true;
  for (size_t i = 1; i < sorted_base.size(); ++i)
    if (compareVertices(base, sorted_base[i], base, sorted_base[i - 1], layout) == 0) unique_keys = false;
  const auto base_keys = faceKeys(base.triangles);
  const CodecInfo* best = nullptr;
  uint16_t best_version = 0;
  std::vector<uint8_t> best_payload;
  QuantizedMesh best_decoded;
  std::vector<uint32_t> best_map;  // decoded base vertex -> last-level wedge
  for (const CodecInfo& codec : allCodecs()) {
    if (codec.id != CodecId::kStore && codec.id != CodecId::kKdtree && codec.id != CodecId::kOctree) continue;
    auto enc = codec.encode(base_ctx, TileView{base, {}}, options);
    if (!enc.isOk()) continue;
    if (best && enc->payload.size() >= best_payload.size()) continue;
    auto dec = codec.decode(base_ctx, payloadVersion(codec, *enc), enc->payload, limitsOf(enc->decoded));
    if (!dec.isOk() || dec->positions.size() != base.positions.size()) continue;
    if ((with_normals && dec->normals.size() != dec->positions.size()) ||
        (with_colors && dec->colors.size() != dec->positions.size()) ||
        dec->scalars.size() != dec->positions.size() * stride)
      continue;
    std::vector<uint32_t> map(dec->positions.size());
    bool ok = true;
    for (uint32_t i = 0; i < map.size() && ok; ++i) {
      if (unique_keys) {
        auto it = std::lower_bound(sorted_base.begin(), sorted_base.end(), i, [&](uint32_t v, uint32_t d) {
          return compareVertices(base, v, *dec, d, layout) < 0;
        });
        ok = it != sorted_base.end() && compareVertices(base, *it, *dec, i, layout) == 0;
        if (ok) map[i] = *it;
      } else {
        ok = compareVertices(base, i, *dec, i, layout) == 0;
        map[i] = i;
      }
    }
    if (!ok) continue;
    std::vector<Triangle> mapped;
    for (const auto& t : dec->triangles) mapped.push_back({map[t[0]], map[t[1]], map[t[2]]});
    if (faceKeys(mapped) != base_keys) continue;
    for (uint32_t& v : map) v = base_to_last[v];
    best = &codec;
    best_version = payloadVersion(codec, *enc);
    best_payload = std::move(enc->payload);
    best_decoded = std::move(dec).value();
    best_map = std::move(map);
  }
  if (!best) return makeError(ErrorCode::kInternal, "pm: no codec reproduces the base mesh");
  // Backward: split from the decoded base, as the decoder will. v5: the base wedges at one position that are not
  // its first vertex's (the simplifier may move a point into the cell of one it does not share a triangle with).
  Header h;
  h.wedges = attributes;  // v5 whenever attributes are coded (CodecInfo::keeps_attributes_from)
  if (h.wedges) {         // (before v5 every base vertex is a state vertex of its own)
    const std::vector<uint32_t> sorted = canonicalOrder(best_decoded.positions);
    std::vector<uint32_t> here;  // last-level vertices at the current position, by group
    for (uint32_t i = 0; i < sorted.size(); ++i) {
      const uint32_t vertex = last.wedge_vertex[best_map[sorted[i]]];
      if (i == 0 || best_decoded.positions[sorted[i]] != best_decoded.positions[sorted[i - 1]]) here.clear();
      const uint64_t g = uint64_t(std::find(here.begin(), here.end(), vertex) - here.begin());
      if (g == here.size()) here.push_back(vertex);
      if (g != 0) h.groups.push_back({i, g});
    }
  }
  std::vector<uint32_t> order;
  std::optional<PmState> initial = initialState(best_decoded, h.wedges ? &h.groups : nullptr, &order);
  if (!initial) return makeError(ErrorCode::kInternal, "pm: the base's wedge groups are inconsistent");
  PmState st = std::move(*initial);
  std::vector<uint32_t> wedge_truth;  // state wedge -> last-level wedge
  for (uint32_t v : order) wedge_truth.push_back(best_map[v]);
  std::vector<uint32_t> wedge_state(nw, UINT32_MAX);
  for (uint32_t i = 0; i < wedge_truth.size(); ++i) wedge_state[wedge_truth[i]] = i;
  std::vector<uint32_t> last_of(st.pos.size());  // state vertex -> last-level vertex
  for (uint32_t w = 0; w < wedge_truth.size(); ++w) last_of[st.wv[w]] = last.wedge_vertex[wedge_truth[w]];
  std::vector<uint32_t> state_of(nl, UINT32_MAX);
  for (uint32_t i = 0; i < last_of.size(); ++i) state_of[last_of[i]] = i;
  const size_t passes = s2.pass_ends.size();
  std::vector<uint8_t> streams;
  h.base_codec = uint8_t(best->id);
  // Without attributes kdtree's and octree's version 3 payloads are their version 2 bytes: such a base keeps naming
  // 2, as pm v2 always has (the same bytes as v2, golden ones included).
  h.base_version = attributes ? best_version : std::min<uint16_t>(best_version, 2);
  h.base_bytes = best_payload.size();
  h.base_vertices = best_decoded.positions.size();
  h.base_faces = best_decoded.triangles.size();
  h.base_error = last_error + (s2.pass_errors.empty() ? 0.f : s2.pass_errors.back());
  const uint32_t max_coord = uint32_t((uint64_t(1) << ctx.bits) - 1);
  Models m;
  LevelAttributes level_attributes(layout, attributes ? uint32_t(st.wv.size()) : 0);
  std::vector<uint32_t> blocked;
  uint32_t mark = 0;
  std::vector<uint8_t> level_bytes;
  std::unique_ptr<RangeEncoder> re;
  LevelEntry cur;
  uint64_t level_start_v = st.pos.size();
  for (size_t p = passes; p-- > 0;) {
    if (!re) re = std::make_unique<RangeEncoder>(level_bytes), level_start_v = st.pos.size();
    EncodeSide c{*re};
    const uint32_t begin = p == 0 ? 0 : s2.pass_ends[p - 1], end = s2.pass_ends[p];
    if (begin > end || end > records.size()) return makeError(ErrorCode::kInternal, "pm: invalid pass ends");
    std::vector<std::pair<uint32_t, uint32_t>> splits;  // (state index of kept, record)
    for (uint32_t ci = begin; ci < end; ++ci) {
      const uint32_t k = state_of[records[ci].kept];
      if (k == UINT32_MAX) return makeError(ErrorCode::kInternal, "pm: a pass's kept vertex is not present");
      splits.push_back({k, ci});
    }
    std::sort(splits.begin(), splits.end());
    // An empty pass codes no batch (the last one still closes its level; the simplifier records none, but a batch
    // of zero flags outside the level's count would put bits where the decoder reads the attributes).
    if (splits.empty() && p != 0) continue;
    const uint32_t n_start = splits.empty() ? 0 : uint32_t(st.pos.size());
    size_t next = 0;
    int prev = 0;
    std::vector<uint32_t> fan;
    std::vector<uint8_t> starts;
    ++mark;
    for (uint32_t v = 0; v < n_start; ++v) {
      int flag = next < splits.size() && splits[next].first == v;
      if (next + 1 < splits.size() && flag && splits[next + 1].first == v)
        return makeError(ErrorCode::kInternal, "pm: a vertex collapses twice in one pass");
      if (v < blocked.size() && blocked[v] == mark) {
        if (flag) return makeError(ErrorCode::kInternal, "pm: a pass's collapses are not independent");
        continue;
      }
      c.bit(m.flag[prev], flag);
      prev = flag;
      if (!flag) continue;
      const CollapseRecord& rec = records[splits[next++].second];
      if (st.pos[v] != rec.vp) return makeError(ErrorCode::kInternal, "pm: a pass's collapses are not independent");
      Split s;
      s.vs = rec.vs, s.vr = rec.vr;
      st.fan(v, fan, starts);
      std::vector<std::pair<uint32_t, uint32_t>> to_move = rec.moved;  // sorted
      for (uint32_t f : fan) {
        const auto [a, b] = st.others(f, v);
        const std::pair<uint32_t, uint32_t> key{last_of[a], last_of[b]};
        auto it = std::lower_bound(to_move.begin(), to_move.end(), key);
        const bool moved = it != to_move.end() && *it == key;
        if (moved) to_move.erase(it);
        s.moved.push_back(moved);
      }
      if (!to_move.empty()) return makeError(ErrorCode::kInternal, "pm: a pass's collapses are not independent");
      for (size_t j = 0; j < rec.new_faces.size(); ++j) {
        const auto [w, o] = rec.new_faces[j];
        const uint32_t ws = state_of[w], a = wedge_state[rec.new_wedges[j][0]], b = wedge_state[rec.new_wedges[j][1]];
        if (ws == UINT32_MAX || a == UINT32_MAX || b == UINT32_MAX)
          return makeError(ErrorCode::kInternal, "pm: a new face's vertex or wedge is not present");
        s.new_faces.push_back({ws, o});
        s.new_wedges.push_back({a, b});
      }
      SP_RETURN_IF_ERROR(codeSplit(c, m, st, v, s, max_coord, UINT64_MAX));
      st.block(v, uint32_t(st.pos.size() - 1), blocked, mark);
      state_of[rec.removed] = uint32_t(st.pos.size() - 1);
      last_of.push_back(rec.removed);
      // r's new wedges are the removed vertex's that the deleted faces pair with k's.
      for (const auto& [a, id] : s.created) {
        const uint32_t kept_wedge = wedge_truth[a];  // (clang 14 captures no structured binding)
        auto it =
            std::find_if(rec.pairs.begin(), rec.pairs.end(), [&](const auto& q) { return q.first == kept_wedge; });
        if (it == rec.pairs.end() || id != wedge_truth.size())
          return makeError(ErrorCode::kInternal, "pm: a split's new wedge pairs with none of the collapse's");
        wedge_truth.push_back(it->second);
        wedge_state[it->second] = id;
      }
    }
    if (next != splits.size()) return makeError(ErrorCode::kInternal, "pm: a split was not coded");
    if (!splits.empty()) ++cur.batches;
    const uint64_t grown = st.pos.size() - level_start_v;
    if (p == 0 || (grown >= kMinLevelSplits && double(st.pos.size()) >= kLevelGrowth * double(level_start_v))) {
      // The last level (the last with splits) ends with the attributes of every wedge the splits added.
      if (attributes && cur.batches > 0 && st.pos.size() == nl) {
        if (st.wv.size() != nw) return makeError(ErrorCode::kInternal, "pm: splits do not restore the wedges");
        hierarchy::Points truth;  // by state wedge
        for (uint32_t i = 0; i < nw; ++i) {
          if (with_normals) truth.normals.push_back(last.attrs.normals[wedge_truth[i]]);
          if (with_colors) truth.colors.push_back(last.attrs.colors[wedge_truth[i]]);
          if (stride) appendRow(truth.scalars, scalarRow(last.attrs.scalars, wedge_truth[i]));
        }
        AttributeEncodeIo io{*re};
        level_attributes.endLevel(io, st, true, &truth);
      }
      re->finish();
      re.reset();
      if (cur.batches == 0) {
        level_bytes.clear();
        continue;
      }
      cur.vertices = st.pos.size();
      cur.wedges = st.wv.size();
      cur.faces = st.faces.size();
      cur.error = last_error + (p == 0 || p > s2.pass_errors.size() ? 0.f : s2.pass_errors[p - 1]);
      cur.bytes = level_bytes.size();
      streams.insert(streams.end(), level_bytes.begin(), level_bytes.end());
      level_bytes.clear();
      h.levels.push_back(cur);
      cur = LevelEntry{};
    }
  }
  // The last state must be the last level: same positions per vertex, same wedges, same faces.
  if (st.pos.size() != nl || st.wv.size() != nw)
    return makeError(ErrorCode::kInternal, "pm: splits do not restore the last level");
  for (uint32_t i = 0; i < nl; ++i)
    if (st.pos[i] != last.mesh.positions[last_of[i]])
      return makeError(ErrorCode::kInternal, "pm: split positions differ");
  for (uint32_t w = 0; w < nw; ++w)
    if (last.wedge_vertex[wedge_truth[w]] != last_of[st.wv[w]])
      return makeError(ErrorCode::kInternal, "pm: a wedge is at another vertex");
  std::vector<Triangle> mapped, mapped_wedges;
  for (size_t f = 0; f < st.faces.size(); ++f) {
    const Triangle &t = st.faces[f], &w = st.cornerWedges()[f];
    mapped.push_back({last_of[t[0]], last_of[t[1]], last_of[t[2]]});
    mapped_wedges.push_back({wedge_truth[w[0]], wedge_truth[w[1]], wedge_truth[w[2]]});
  }
  if (wedgeFaceKeys(mapped, mapped_wedges) != wedgeFaceKeys(last.mesh.triangles, last.corners))
    return makeError(ErrorCode::kInternal, "pm: splits do not restore the last level's faces");
  // Assemble.
  EncodedTile result;
  ByteWriter w(result.payload);
  w.u8(h.base_codec);
  w.varint(h.base_version);
  w.varint(h.base_bytes);
  w.varint(h.base_vertices);
  w.varint(h.base_faces);
  putF32(w, h.base_error);
  if (h.wedges) {
    w.varint(h.groups.size());
    uint64_t prev = 0;
    for (const auto& [index, group] : h.groups) {
      w.varint(index - prev);
      w.varint(group);
      prev = index;
    }
  }
  w.varint(h.levels.size());
  for (const auto& l : h.levels) {
    w.varint(l.batches);
    w.varint(l.vertices);
    if (h.wedges) w.varint(l.wedges);
    w.varint(l.faces);
    putF32(w, l.error);
    w.varint(l.bytes);
  }
  h.base_offset = result.payload.size();
  w.bytes(best_payload);
  w.bytes(streams);
  QuantizedMesh final_mesh;
  for (uint32_t v : st.wv) final_mesh.positions.push_back(st.pos[v]);
  final_mesh.triangles = st.identity ? std::move(st.faces) : std::move(st.fw);
  result.decoded = summarize(final_mesh);
  result.levels = levelsOf(h);
  // With attributes, v5 (wedges) even when every position has one: a v5 tile gives back the tile's vertices, so
  // the decoders weld it to its neighbours by position and attributes, which a tile of v3 or v4 (welded by position,
  // the first point's attributes kept) does not allow; without, v3 (v2's bytes).
  result.version = attributes ? kWedgesFrom : kAttributesFrom;
  // Reported where the last level is the tile (lossless): a simplified one drops vertices and their attributes
  // anyway, and the weld is its first step.
  result.merged_points = opt.max_error < 0 && opt.ratio >= 1 ? merged : 0;
  return result;
}

}  // namespace

Result<EncodedTile> pmEncode(const TileContext& ctx, const TileView& tile, const CodecOptions& options) {
  return pmEncodeImpl(ctx, tile, options);
}

Result<QuantizedMesh> pmDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                               const DecodeLimits& limits) {
  return decodeImpl(ctx, version, payload, UINT32_MAX, limits);
}

Result<std::vector<CodecLevel>> pmLevels(const TileContext&, uint16_t version, std::span<const uint8_t> payload,
                                         const DecodeLimits& limits) {
  SP_RETURN_IF_ERROR(checkVersion(version));
  SP_ASSIGN_OR_RETURN(Header h, parseHeader(payload, limits, version));
  auto levels = levelsOf(h);
  if (levels.back().end_bytes > payload.size())
    return makeError(ErrorCode::kTruncated, "pm payload is shorter than its levels");
  return levels;
}

Result<QuantizedMesh> pmDecodeLevel(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                    uint32_t level, const DecodeLimits& limits) {
  return decodeImpl(ctx, version, payload, level, limits);
}

}  // namespace scanpress
