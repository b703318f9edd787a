// Codec `edgebreaker` (id 5): single-rate lossless coding of arbitrary triangle meshes.
//
// Papers: J. Rossignac, "Edgebreaker: Connectivity compression for triangle meshes", IEEE TVCG 1999 (the CLERS
// traversal); S. Gumhold, W. Strasser, "Real time compression of triangle mesh connectivity", SIGGRAPH 1998 (the
// cut-border machine, which decodes Edgebreaker's traversal in one forward pass by coding where a split lands);
// C. Touma, C. Gotsman, "Triangle mesh compression", GI 1998 (parallelogram prediction); the PRM paper's §3.1
// (../shared/papers/prm-piecewise-regular-meshes.md: CLERS symbols context-coded by the previous symbol and the
// valence at the gate).
//
// Connectivity: the decoder keeps the cut border, loops of border half-edges of the decoded faces, and a stack of
// the loops still open. At the gate (a border half-edge x->y) the face beyond it has a third vertex c that is new
// (C), the start of the previous border half-edge (L), the end of the next one (R), both (E), elsewhere on the
// current loop (S: the loop splits, one part is pushed) or on a stacked loop (M: the loops merge; needed only on
// handles). Gate after C and R: x->c, so the traversal spirals around x as Edgebreaker does; after L: c->y.
// Symbols are coded with adaptive models by the previous symbol and the number of faces already decoded around x.
//
// Where this departs from the papers, and why:
//  - S and M code where c lies on the border (direction and distance along the loop; the stack entry for M)
//    instead of Edgebreaker's offset-free S with a second pass or a reversed decode: one forward pass, and every
//    symbol is coded with the decoder's state at hand (which the valence contexts need).
//  - Input is any triangle set. The distinct (position, attribute) points and the distinct unoriented triangles
//    are taken as kdtree takes them (hierarchy.h). Triangles are oriented breadth-first across edges with two
//    triangles; an edge with more, or whose two triangles cannot agree, is cut. Around each point the triangles
//    that share glued edges form fans; every fan becomes its own cut vertex, so the cut mesh is an oriented
//    manifold. Each boundary loop of the cut mesh is closed by a fan around a dummy vertex (as Isenburg &
//    Snoeyink and Draco's hole handling do). Every vertex the traversal meets first is coded as a new point, a
//    dummy, or a copy of an earlier point (its index): how the cut pieces glue back. A cut edge whose ends stay
//    joined around other triangles leaves two edges between one pair of cut vertices, so border loops of two
//    half-edges are legal (the papers' manifolds have none).
//  - Orientation and multiplicity of the input triangles are then coded exactly as kdtree codes them (hierarchy.h
//    codeFaceCopies over the sorted keys), so the decoded triangle set equals the input's.
//  - Geometry: after connectivity, the points in decode order; each is predicted by the mean of every
//    parallelogram around its first fan whose three corners are known, else the mean of its known neighbours, else
//    the previous point. Residuals (zigzag) are coded as a bit-length class with adaptive models by prediction kind,
//    axis, the mean class of the known neighbours' residuals and the largest class on the point's earlier axes;
//    then the bit below the leading one with a model per class, the rest raw. Measured at 12 bits (bunny, igea,
//    rs1, fandisk): the point's earlier axes and the modelled second bit gain 1-3% on the large scans; coding
//    residuals below 32 as symbols of their own lost 1-8% (models too many to learn on small meshes).
//  - Attributes: per point in decode order, as kdtree codes them (v1 raw, v2 predicted: attributes.h).
//
// Payload v1 and v2: varint N (points), varint T (triangles, with multiplicity), varint F (faces of the cut mesh with the
// dummy faces); if N == 0 nothing follows. Then one range-coder stream to the end of the payload: connectivity,
// geometry, orientation and multiplicity, attributes.
#include <algorithm>
#include <bit>
#include <array>
#include <cstring>
#include <string>

#include "engine/codecs/codec.h"
#include "engine/codecs/attributes.h"
#include "engine/geometry.h"
#include "engine/codecs/hierarchy.h"
#include "engine/entropy/range_coder.h"
#include "engine/io/bytes.h"
#include "engine/remesh/resample.h"

namespace scanpress {
namespace {

using namespace hierarchy;
using i64 = int64_t;

constexpr u32 kNone = UINT32_MAX;
constexpr std::string_view kName = "edgebreaker";
enum Op : u32 { kC = 0, kL = 1, kR = 2, kE = 3, kS = 4, kM = 5, kNumOps = 6 };
enum Kind : u32 { kNewPoint = 0, kDummy = 1, kCopy = 2 };
constexpr int kStartOp = kNumOps;  // context of a component's first symbol
constexpr int kValenceContexts = 12;
constexpr int kClasses = 34;  // bit lengths of zigzag residuals up to 2^33
constexpr int kPredKinds = 4;
constexpr int kMagContexts = 8;
constexpr int kDirectBits = 0;  // zigzag residuals below 2^kDirectBits are coded as symbols of their own
constexpr u32 kDirect = 1u << kDirectBits;
constexpr int kAxisContexts = 3;  // by the largest bit length of the point's residuals on earlier axes

inline u32 nextIn(u32 h) { return h % 3 == 2 ? h - 2 : h + 1; }
inline u32 prevIn(u32 h) { return h % 3 == 0 ? h + 2 : h - 1; }
inline int bitLength(u64 v) {
  int n = 0;
  while (v >> n) ++n;
  return n;
}

// prm's lattice (FORMAT.md, "prm"): relief r (0..5: +x, -x, +y, -y, +z, -z) has height axis r / 2 and base
// coordinates the other two axes (swapped for odd r, so that a triangle facing r is counterclockwise in its base);
// lattice point (i, j) is base (i * G + j * G / 2, j * H), G even, H = round(G * sqrt(3) / 2) (engine/remesh/resample.h).
constexpr int kLatticeKinds = 6;
constexpr u8 kNoRelief = 0xFF;
// rot60 turns a lattice step into the next one counterclockwise: (1, 0) -> (0, 1) -> (-1, 1) -> ...
// The lattice offsets within two steps: the six steps (0-5), twice each step (6-11), each step plus the next one
// (12-17, the far corner of the parallelogram on steps k and k + 1).
constexpr int kRing2[18][2] = {{1, 0},  {0, 1},  {-1, 1}, {-1, 0}, {0, -1}, {1, -1}, {2, 0},   {0, 2},  {-2, 2},
                               {-2, 0}, {0, -2}, {2, -2}, {1, 1},  {-1, 2}, {-2, 1}, {-1, -1}, {1, -2}, {2, -1}};
inline std::array<i64, 2> rot60(std::array<i64, 2> v, int times) {
  for (int k = 0; k < times; ++k) v = {-v[1], v[0] + v[1]};
  return v;
}
inline int baseAxis(int relief, int which) {
  const int a = relief / 2;
  return (a + 1 + ((relief % 2) ^ which)) % 3;
}
// The lattice coordinates of a grid point in relief r's plane, if it is a lattice point.
inline bool latticeOf(const Vec3u& p, int relief, i64 G, i64 H, std::array<i64, 2>& ij) {
  const i64 b0 = p[size_t(baseAxis(relief, 0))], b1 = p[size_t(baseAxis(relief, 1))];
  if (b1 % H != 0) return false;
  const i64 j = b1 / H, x = b0 - j * (G / 2);
  if (((x % G) + G) % G != 0) return false;
  ij = {x >= 0 ? x / G : -((-x) / G), j};
  return true;
}
// The relief codes in which triangle (a, b, c) (cut-face order) is a unit triangle of the lattice, as a mask: bit r
// if it is counterclockwise in relief r's base, bit r + 6 if clockwise (the cut mesh orients each component as its
// traversal needs, which may be against the input's orientation).
u32 latticeReliefs(const Vec3u& a, const Vec3u& b, const Vec3u& c, i64 G, i64 H) {
  u32 mask = 0;
  for (int r = 0; r < 6; ++r) {
    std::array<i64, 2> la, lb, lc;
    if (!latticeOf(a, r, G, H, la) || !latticeOf(b, r, G, H, lb) || !latticeOf(c, r, G, H, lc)) continue;
    const i64 d1[2] = {lb[0] - la[0], lb[1] - la[1]}, d2[2] = {lc[0] - la[0], lc[1] - la[1]};
    const auto unit = [](i64 i, i64 j) { return std::abs(i) + std::abs(j) + std::abs(i + j) == 2; };
    if (!unit(d1[0], d1[1]) || !unit(d2[0], d2[1]) || !unit(d2[0] - d1[0], d2[1] - d1[1])) continue;
    const i64 cross = d1[0] * d2[1] - d1[1] * d2[0];
    if (cross == 1) mask |= 1u << r;
    if (cross == -1) mask |= 1u << (r + 6);
  }
  return mask;
}
// A point's place in a patch's lattice (relative coordinates), ordered by place.
struct LatticeEntry {
  u32 point, patch;
  int32_t i, j;
  bool operator<(const LatticeEntry& o) const {
    return patch != o.patch ? patch < o.patch : i != o.i ? i < o.i : j < o.j;
  }
};
constexpr u8 kMaxPatchesPerPoint = 2;
constexpr int kWeightSlotBits = 10, kWeightSlots = 1 << kWeightSlotBits;
// A regular patch, and a point's place in one.
struct Patch {
  u8 relief, anchored, rotation, clockwise;  // clockwise: the first face's relief code is >= 6
  u32 first_face;
  i64 oi, oj;  // lattice coordinates of relative (0, 0), once anchored
};
struct PointPatch {
  u32 patch;
  int32_t i, j;
};

// Sorts sorted-corner keys lexicographically; when the points fit 21 bits a key packs into one u64 whose order is
// the same, and sorting those is about twice as fast as comparing arrays.
void sortKeys(std::vector<TriKey>& keys, u32 max_point) {
  if (max_point >= (1u << 21)) {
    std::sort(keys.begin(), keys.end());
    return;
  }
  std::vector<u64> packed(keys.size());
  for (size_t i = 0; i < keys.size(); ++i) packed[i] = (u64(keys[i][0]) << 42) | (u64(keys[i][1]) << 21) | keys[i][2];
  if (packed.size() < 4096) {
    std::sort(packed.begin(), packed.end());
  } else {  // LSD radix sort, 16 bits a pass over the bits the points use: linear, where std::sort was 17% of decode
    const int used = 42 + std::max(1, 32 - std::countl_zero(std::max<u32>(max_point, 1)));
    std::vector<u64> tmp(packed.size());
    std::vector<u32> count(1u << 16);
    for (int shift = 0; shift < used; shift += 16) {
      std::fill(count.begin(), count.end(), 0);
      for (u64 k : packed) ++count[(k >> shift) & 0xFFFF];
      u32 sum = 0;
      for (u32& c : count) {
        const u32 n = c;
        c = sum;
        sum += n;
      }
      for (u64 k : packed) tmp[count[(k >> shift) & 0xFFFF]++] = k;
      packed.swap(tmp);
    }
  }
  constexpr u64 kMask = (1u << 21) - 1;
  for (size_t i = 0; i < keys.size(); ++i)
    keys[i] = {u32(packed[i] >> 42), u32((packed[i] >> 21) & kMask), u32(packed[i] & kMask)};
}

// The cut mesh (encoder only): an oriented closed manifold over cut vertices, half-edge h = 3f + i from hv[h] to
// hv[nextIn(h)]. The input's faces come first, then the dummy faces.
struct CutMesh {
  u32 faces = 0;
  std::vector<u32> hv;
  std::vector<u32> twin;
  std::vector<u32> point;  // per cut vertex: its point, kNone for a dummy
};

u32 findRoot(std::vector<u32>& parent, u32 x) {
  while (parent[x] != x) x = parent[x] = parent[parent[x]];
  return x;
}

Status buildCutMesh(const std::vector<TriKey>& keys, CutMesh& cm) {
  const u32 nk = u32(keys.size());
  // Unoriented side s of key f: k[s] - k[s+1]. Sides on an edge with exactly two triangles are glue candidates.
  std::vector<std::pair<u64, u32>> sides;
  sides.reserve(size_t(nk) * 3);
  for (u32 f = 0; f < nk; ++f)
    for (u32 s = 0; s < 3; ++s) {
      const u32 a = keys[f][s], b = keys[f][(s + 1) % 3];
      sides.push_back({a < b ? (u64(a) << 32) | b : (u64(b) << 32) | a, 3 * f + s});
    }
  std::sort(sides.begin(), sides.end());
  std::vector<u32> partner(size_t(nk) * 3, kNone);
  for (size_t i = 0; i < sides.size();) {
    size_t j = i;
    while (j < sides.size() && sides[j].first == sides[i].first) ++j;
    if (j - i == 2) partner[sides[i].second] = sides[i + 1].second, partner[sides[i + 1].second] = sides[i].second;
    i = j;
  }
  // Orientation breadth-first; a glue whose triangles disagree is cut.
  std::vector<u8> orient(nk, 2);
  std::vector<u32> queue;
  for (u32 root = 0; root < nk; ++root) {
    if (orient[root] != 2) continue;
    orient[root] = 0;
    queue.assign(1, root);
    for (size_t head = 0; head < queue.size(); ++head) {
      const u32 f = queue[head];
      for (u32 s = 0; s < 3; ++s) {
        const u32 ps = partner[3 * f + s];
        if (ps == kNone) continue;
        const u32 g = ps / 3, t = ps % 3;
        const u8 same = keys[f][s] == keys[g][t];
        const u8 want = orient[f] ^ same;
        if (orient[g] == 2) {
          orient[g] = want;
          queue.push_back(g);
        } else if (orient[g] != want) {
          partner[3 * f + s] = kNone;
          partner[ps] = kNone;
        }
      }
    }
  }
  // Oriented faces: orientation 0 is (k0, k1, k2), 1 is (k0, k2, k1); side s is half-edge s, or 2 - s.
  const u64 max_faces = u64(nk) * 4;
  cm.hv.clear();
  cm.hv.reserve(max_faces * 3);
  cm.twin.assign(size_t(nk) * 3, kNone);
  std::vector<u32> vert(size_t(nk) * 3);  // point at the start of each half-edge
  for (u32 f = 0; f < nk; ++f) {
    const auto& k = keys[f];
    const std::array<u32, 3> o = orient[f] == 0 ? std::array<u32, 3>{k[0], k[1], k[2]}
                                                : std::array<u32, 3>{k[0], k[2], k[1]};
    for (int i = 0; i < 3; ++i) vert[3 * f + i] = o[i];
  }
  for (u32 f = 0; f < nk; ++f)
    for (u32 s = 0; s < 3; ++s) {
      const u32 ps = partner[3 * f + s];
      if (ps == kNone) continue;
      const u32 g = ps / 3, t = ps % 3;
      cm.twin[3 * f + (orient[f] ? 2 - s : s)] = 3 * g + (orient[g] ? 2 - t : t);
    }
  // Cut vertices: corners (named by the half-edge leaving them) joined across glued edges.
  std::vector<u32> parent(size_t(nk) * 3);
  for (u32 h = 0; h < parent.size(); ++h) parent[h] = h;
  for (u32 h = 0; h < parent.size(); ++h) {
    const u32 g = cm.twin[h];
    if (g == kNone || g < h) continue;
    if (vert[h] != vert[nextIn(g)] || vert[nextIn(h)] != vert[g])
      return makeError(ErrorCode::kInternal, "edgebreaker encoder: glued edge with mismatched corners");
    parent[findRoot(parent, h)] = findRoot(parent, nextIn(g));
    parent[findRoot(parent, nextIn(h))] = findRoot(parent, g);
  }
  std::vector<u32> id(parent.size(), kNone);
  cm.point.clear();
  cm.hv.resize(parent.size());
  for (u32 h = 0; h < parent.size(); ++h) {
    const u32 r = findRoot(parent, h);
    if (id[r] == kNone) {
      id[r] = u32(cm.point.size());
      cm.point.push_back(vert[r]);
    }
    cm.hv[h] = id[r];
  }
  std::vector<u32>().swap(parent);
  std::vector<u32>().swap(id);
  std::vector<u32>().swap(vert);
  // Boundary loops: the boundary half-edge leaving each cut vertex (one at most: every fan is a path or a cycle).
  std::vector<u32> out_boundary(cm.point.size(), kNone);
  for (u32 h = 0; h < 3 * nk; ++h)
    if (cm.twin[h] == kNone) {
      if (out_boundary[cm.hv[h]] != kNone)
        return makeError(ErrorCode::kInternal, "edgebreaker encoder: cut vertex with two boundary fans");
      out_boundary[cm.hv[h]] = h;
    }
  cm.faces = nk;
  std::vector<u8> closed(size_t(nk) * 3, 0);
  for (u32 h0 = 0; h0 < 3 * nk; ++h0) {
    if (cm.twin[h0] != kNone || closed[h0]) continue;
    const u32 d = u32(cm.point.size());
    cm.point.push_back(kNone);
    // Dummy face on boundary half-edge h (x->y): (y, x, d); consecutive dummy faces share d->y / y->d.
    const u32 first_face = cm.faces;
    u32 h = h0;
    do {
      closed[h] = 1;
      const u32 f = cm.faces++;
      const u32 x = cm.hv[h], y = cm.hv[nextIn(h)];
      cm.hv.insert(cm.hv.end(), {y, x, d});
      cm.twin.insert(cm.twin.end(), {h, kNone, kNone});
      cm.twin[h] = 3 * f;
      if (f > first_face) {
        cm.twin[3 * (f - 1) + 2] = 3 * f + 1;
        cm.twin[3 * f + 1] = 3 * (f - 1) + 2;
      }
      h = out_boundary[y];
      if (h == kNone) return makeError(ErrorCode::kInternal, "edgebreaker encoder: open boundary loop");
    } while (h != h0);
    const u32 last = cm.faces - 1;
    cm.twin[3 * last + 2] = 3 * first_face + 1;
    cm.twin[3 * first_face + 1] = 3 * last + 2;
  }
  return Status::ok();
}

struct Models {
  std::vector<SymbolModel> op;
  SymbolModel kind{3};
  SymbolModel distance{34};
  BitModel direction;
  std::vector<SymbolModel> residual;
  BitModel second_bit[kClasses];
  std::vector<SymbolModel> orient;
  // prm
  // By the face across the gate (none, irregular, regular), corners next to an irregular face (0..3), corners next
  // to a regular face (0..3), and whether the face made a new vertex (C).
  BitModel regular[96];
  BitModel same_relief[2];  // as the face across the gate's, as the last regular face's
  SymbolModel relief{12};
  SymbolModel rotation{6};
  std::vector<SymbolModel> height;
  Models() {
    for (int i = 0; i < kLatticeKinds * kMagContexts; ++i) height.emplace_back(kDirect + kClasses - kDirectBits - 1);
    for (int i = 0; i < (int(kNumOps) + 1) * kValenceContexts; ++i) op.emplace_back(kNumOps);
    for (int i = 0; i < kPredKinds * kMagContexts * 3 * kAxisContexts; ++i)
      residual.emplace_back(kDirect + kClasses - kDirectBits - 1);
    for (int i = 0; i < 2; ++i) orient.emplace_back(3);
  }
};

// What only the encoder knows.
struct Truth {
  const CutMesh* cm = nullptr;
  const Points* pts = nullptr;  // positions and attributes by point
  Points ordered;               // points renumbered in decode order, keys over those numbers
  std::vector<u32> out_of_point;
};

template <class Io>
class Engine {
 public:
  Engine(Io& io, int bits, u32 n, u64 t, u32 faces, Truth* truth)
      : io_(io), n_(n), t_(t), faces_(faces), truth_(truth) {
    max_coord_ = (u64(1) << bits) - 1;
  }

  AttributeLayout layout;
  uint16_t version = kPredictedAttributes;  // the payload's (attribute coding)
  // prm: the lattice spacing G in grid cells (even, >= 2); 0 is plain edgebreaker.
  u32 spacing = 0;
  u64 ops[kNumOps] = {};
  u64 regular_faces = 0, patch_count = 0, lattice_points = 0;

  Status run() {
    hv_.assign(size_t(faces_) * 3, kNone);
    twin_.assign(size_t(faces_) * 3, kNone);
    nxt_.assign(size_t(faces_) * 3, kNone);
    prv_.assign(size_t(faces_) * 3, kNone);
    if (truth_) {
      enc_of_dec_.assign(size_t(faces_) * 3, kNone);
      dec_of_enc_.assign(size_t(faces_) * 3, kNone);
      dec_vertex_.assign(truth_->cm->point.size(), kNone);
      truth_->out_of_point.assign(truth_->pts->pos.size(), kNone);
    }
    io_.meter(&CodecStats::connectivity_bits);
    SP_RETURN_IF_ERROR(connectivity());
    SP_RETURN_IF_ERROR(mapPoints());
    if (spacing > 0) {
      io_.meter(&CodecStats::regularity_bits);
      SP_RETURN_IF_ERROR(regularity());
      std::vector<u8>().swap(face_op_);
      SP_RETURN_IF_ERROR(buildPatches());
    }
    io_.meter(&CodecStats::geometry_bits);
    SP_RETURN_IF_ERROR(geometry());
    io_.meter(&CodecStats::connectivity_bits);
    SP_RETURN_IF_ERROR(triangles());
    io_.meter(&CodecStats::attribute_bits);
    codeTileAttributes(io_, version, layout, pos_, tris_, truth_ ? &truth_->ordered : nullptr, normals_, colors_,
                       scalars_);
    return Status::ok();
  }

  QuantizedMesh mesh() {
    QuantizedMesh m;
    m.positions = std::move(pos_);
    m.triangles = std::move(tris_);
    m.normals = std::move(normals_);
    m.colors = std::move(colors_);
    m.scalars = std::move(scalars_);
    return m;
  }

 private:
  Status malformed(const std::string& what) const {
    return makeError(truth_ ? ErrorCode::kInternal : ErrorCode::kMalformed,
                     std::string(spacing ? "prm" : kName) + (truth_ ? " encoder: " : " payload: ") + what);
  }

  // A cut vertex met for the first time: a new point, a dummy, or a copy of an earlier point.
  Status newVertex(u32 enc_vertex, u32& v) {
    u32 kind = 0, copy_of = 0;
    if (truth_) {
      const u32 p = truth_->cm->point[enc_vertex];
      if (p == kNone) kind = kDummy;
      else if (truth_->out_of_point[p] != kNone) kind = kCopy, copy_of = truth_->out_of_point[p];
      else kind = kNewPoint;
    }
    kind = io_.sym(models_.kind, kind);
    u32 point = kNone;
    if (kind == kNewPoint) {
      if (points_ >= n_) return malformed("more points than the header says");
      point = points_++;
      if (truth_) truth_->out_of_point[truth_->cm->point[enc_vertex]] = point;
    } else if (kind == kCopy) {
      if (points_ == 0) return malformed("copy of a point before any");
      point = io_.uniform(copy_of, points_);
    }
    v = u32(cut_point_.size());
    cut_point_.push_back(point);
    is_first_.push_back(kind == kNewPoint);
    count_.push_back(0);
    first_he_.push_back(kNone);
    if (truth_) dec_vertex_[enc_vertex] = v;
    return Status::ok();
  }

  u32 codeDistance(u32 d) {
    const int cls = int(io_.sym(models_.distance, u32(bitLength(d))));
    if (cls <= 1) return u32(cls);
    // A hostile stream can name a class past 32 bits: the shifts are 64-bit, and the value (cut to 32 bits) is then
    // checked by the caller like any other distance.
    const uint64_t top = uint64_t(1) << (cls - 1);
    return u32(top | io_.bits(u32(d & (top - 1)), std::min(cls - 1, 32)));
  }

  // Walks `steps` border elements from `from`, forward or backward.
  u32 walk(u32 from, u32 steps, bool forward) const {
    for (u32 i = 0; i < steps; ++i) from = forward ? nxt_[from] : prv_[from];
    return from;
  }

  void link(u32 a, u32 b) {
    nxt_[a] = b;
    prv_[b] = a;
  }
  void setTwin(u32 a, u32 b) {
    twin_[a] = b;
    twin_[b] = a;
  }

  Status connectivity() {
    u32 done = 0;
    u32 enc_scan = 0;
    std::vector<u8> enc_done;
    if (truth_) enc_done.assign(faces_, 0);
    struct Loop {
      u32 rep, len;
    };
    std::vector<Loop> stack;
    while (done < faces_) {
      // A new component: its first face, three new vertices, a loop of three.
      const u32 k = done++;
      if (spacing > 0) face_op_.push_back(u8(kNumOps));
      u32 f0 = 0;
      if (truth_) {
        while (enc_done[enc_scan]) ++enc_scan;
        f0 = enc_scan;
        enc_done[f0] = 1;
      }
      for (u32 i = 0; i < 3; ++i) {
        u32 v;
        SP_RETURN_IF_ERROR(newVertex(truth_ ? truth_->cm->hv[3 * f0 + i] : 0, v));
        hv_[3 * k + i] = v;
        first_he_[v] = 3 * k + i;
        count_[v]++;
        if (truth_) enc_of_dec_[3 * k + i] = 3 * f0 + i, dec_of_enc_[3 * f0 + i] = 3 * k + i;
      }
      link(3 * k, 3 * k + 1);
      link(3 * k + 1, 3 * k + 2);
      link(3 * k + 2, 3 * k);
      u32 gate = 3 * k, len = 3;
      int prev_op = kStartOp;
      stack.clear();
      while (true) {
        const u32 e = gate, p = prv_[e], nx = nxt_[e];
        const u32 x = hv_[e], y = hv_[nx];
        u32 op = 0, g_h = 0, n1 = 0, n2 = 0, q = kNone, enc_c = 0;
        if (truth_) {
          const CutMesh& cm = *truth_->cm;
          g_h = cm.twin[enc_of_dec_[e]];
          if (g_h == kNone || enc_done[g_h / 3]) return malformed("traversal met a decoded face");
          n1 = nextIn(g_h);
          n2 = nextIn(n1);
          enc_c = cm.hv[n2];
          const bool left = enc_of_dec_[p] == cm.twin[n1], right = enc_of_dec_[nx] == cm.twin[n2];
          if (left && right) op = kE;
          else if (left) op = kL;
          else if (right) op = kR;
          else if (dec_vertex_[enc_c] == kNone) op = kC;
          else {
            // Rotate around c from the new face to the first decoded face: its half-edge into c is on the border.
            u32 hh = cm.twin[n2];
            for (u32 steps = 0; !enc_done[hh / 3]; ++steps) {
              if (steps > 3 * faces_) return malformed("fan without a decoded face");
              hh = cm.twin[nextIn(hh)];
            }
            q = dec_of_enc_[hh];
            // Search both ways at once: the walk costs the shorter distance, as the decoder's does.
            op = kM;
            u32 fwd = nx, bwd = p;
            for (u32 d = 1; 2 * d <= len + 1; ++d, fwd = nxt_[fwd], bwd = prv_[bwd]) {
              if (fwd == q) {
                op = kS, stack_distance_ = d;
                break;
              }
              if (bwd == q) {
                op = kS, stack_distance_ = len - d;
                break;
              }
            }
          }
        }
        const int ctx = prev_op * kValenceContexts + int(std::min<u32>(count_[x], kValenceContexts - 1));
        op = io_.sym(models_.op[ctx], op);
        prev_op = int(op);
        ops[op]++;
        if (spacing > 0) face_op_.push_back(u8(op));
        if (done >= faces_) return malformed("more faces than the header says");
        const u32 k2 = done++;
        const u32 t0 = 3 * k2, t1 = t0 + 1, t2 = t0 + 2;
        setTwin(t0, e);
        u32 c = kNone;
        switch (op) {
          case kC: {
            SP_RETURN_IF_ERROR(newVertex(enc_c, c));
            first_he_[c] = t2;
            link(p, t1);
            link(t1, t2);
            link(t2, nx);
            ++len;
            gate = t1;
            break;
          }
          case kL: {
            if (len < 3) return malformed("L on a loop of two");
            c = hv_[p];
            setTwin(t1, p);
            link(prv_[p], t2);
            link(t2, nx);
            --len;
            gate = t2;
            break;
          }
          case kR: {
            if (len < 3) return malformed("R on a loop of two");
            c = hv_[nxt_[nx]];
            setTwin(t2, nx);
            link(p, t1);
            link(t1, nxt_[nx]);
            --len;
            gate = t1;
            break;
          }
          case kE: {
            if (len != 3 && len < 5) return malformed("E on a short loop");
            c = hv_[p];
            if (hv_[nxt_[nx]] != c) return malformed("E does not close");
            setTwin(t1, p);
            setTwin(t2, nx);
            if (len == 3) {
              len = 0;
            } else {
              const u32 pp = prv_[p], nn = nxt_[nx];
              link(pp, nn);
              len -= 3;
              gate = nn;
            }
            break;
          }
          case kS: {
            if (len < 3) return malformed("S on a short loop");
            u32 dist = 0;
            int forward = 1;
            if (truth_) {
              const u32 d = stack_distance_;
              forward = d <= len - d;
              dist = forward ? d : len - d;
            }
            forward = io_.bit(models_.direction, forward);
            dist = codeDistance(dist);
            const u32 d = forward ? dist : len - std::min(dist, len);
            if (d < 1 || d > len - 2) return malformed("S lands outside its loop");
            q = walk(e, std::min(dist, len), forward);
            const u32 s = nxt_[q];
            c = hv_[s];
            link(t2, nx);
            link(q, t2);
            link(p, t1);
            link(t1, s);
            stack.push_back({t2, d + 1});
            len = len - d;
            gate = t1;
            break;
          }
          case kM: {
            u32 si = 0, dist = 0;
            int forward = 1;
            if (truth_) {
              bool found = false;
              for (size_t j = stack.size(); j-- > 0 && !found;) {
                u32 at = stack[j].rep;
                for (u32 d = 0; d < stack[j].len; ++d, at = nxt_[at])
                  if (at == q) {
                    si = u32(stack.size() - 1 - j);
                    forward = d <= stack[j].len - d;
                    dist = forward ? d : stack[j].len - d;
                    found = true;
                    break;
                  }
              }
              if (!found) return malformed("M target on no loop");
            }
            if (stack.empty()) return malformed("M without a stacked loop");
            si = io_.uniform(si, u32(stack.size()));
            forward = io_.bit(models_.direction, forward);
            dist = codeDistance(dist);
            const size_t j = stack.size() - 1 - si;
            const Loop other = stack[j];
            if (dist >= other.len) return malformed("M lands outside its loop");
            q = walk(other.rep, dist, forward);
            const u32 s = nxt_[q];
            c = hv_[s];
            link(p, t1);
            link(t1, s);
            link(q, t2);
            link(t2, nx);
            len += other.len + 1;
            stack.erase(stack.begin() + j);
            gate = t1;
            break;
          }
          default: return malformed("unknown symbol");
        }
        if (c == x || c == y) return malformed("degenerate face");
        hv_[t0] = y;
        hv_[t1] = x;
        hv_[t2] = c;
        count_[x]++;
        count_[y]++;
        count_[c]++;
        if (truth_) {
          const u32 hs[3] = {g_h, n1, n2};
          for (int i = 0; i < 3; ++i) enc_of_dec_[t0 + i] = hs[i], dec_of_enc_[hs[i]] = t0 + i;
          enc_done[g_h / 3] = 1;
          if (dec_vertex_[enc_c] != c) return malformed("traversal lost a vertex");
        }
        if (len == 0) {
          if (stack.empty()) break;
          gate = stack.back().rep;
          len = stack.back().len;
          stack.pop_back();
        }
      }
    }
    return Status::ok();
  }

  // Positions of the points in decode order, then of the isolated points.
  // Numbers the isolated points (after those the traversal met), and the encoder's maps between its points and the
  // decode order.
  Status mapPoints() {
    u32 isolated = 0;
    if (truth_) {
      for (u32 p = 0; p < truth_->pts->pos.size(); ++p)
        if (truth_->out_of_point[p] == kNone) truth_->out_of_point[p] = points_ + isolated++;
      if (points_ + isolated != n_) return malformed("point count mismatch");
      point_of_out_.assign(n_, kNone);
      for (u32 p = 0; p < n_; ++p) point_of_out_[truth_->out_of_point[p]] = p;
    }
    return Status::ok();
  }

  // The prediction of a point from its first fan (around cut vertex v): the mean of every parallelogram whose three
  // corners are known, else the mean of the known neighbours, else `last`.
  void fanPrediction(u32 v, const Vec3u& last, i64* pred, int& kind, int& mctx) const {
    i64 par[3] = {0, 0, 0}, nb[3] = {0, 0, 0};
    u32 npar = 0, nnb = 0, mag_sum = 0;
    const u32 limit = 3 * faces_ + 3;
    const u32 start = first_he_[v];
    u32 h = start;
    for (u32 steps = 0; steps < limit; ++steps) {
      const u32 ab = nextIn(h);
      const u32 a = cut_point_[hv_[ab]], b = cut_point_[hv_[prevIn(h)]];
      if (a != kNone && known_[a]) {
        ++nnb;
        mag_sum += mag_[a];
        for (int i = 0; i < 3; ++i) nb[i] += pos_[a][i];
        const u32 o_he = twin_[ab];
        const u32 o = o_he == kNone ? kNone : cut_point_[hv_[prevIn(o_he)]];
        if (b != kNone && known_[b] && o != kNone && known_[o]) {
          ++npar;
          for (int i = 0; i < 3; ++i) par[i] += i64(pos_[a][i]) + pos_[b][i] - pos_[o][i];
        }
      }
      const u32 back = twin_[prevIn(h)];
      if (back == kNone) break;
      h = back;
      if (h == start) break;
    }
    if (npar > 0) {
      kind = npar > 1 ? 0 : 1;
      for (int i = 0; i < 3; ++i) pred[i] = floorDiv(2 * par[i] + npar, 2 * i64(npar));
    } else if (nnb > 0) {
      kind = 2;
      for (int i = 0; i < 3; ++i) pred[i] = floorDiv(2 * nb[i] + nnb, 2 * i64(nnb));
    } else {
      kind = 3;
      for (int i = 0; i < 3; ++i) pred[i] = last[i];
    }
    mctx = nnb ? int(std::min<u32>((mag_sum + nnb / 2) / nnb, kMagContexts - 1)) : 0;
  }

  Status geometry() {
    pos_.assign(n_, Vec3u{0, 0, 0});
    known_.assign(n_, 0);
    mag_.assign(n_, 0);
    Vec3u last{0, 0, 0};
    for (u32 v = 0; v < cut_point_.size(); ++v) {
      if (!is_first_[v]) continue;
      const u32 point = cut_point_[v];
      if (spacing > 0) {
        bool done = false;
        SP_RETURN_IF_ERROR(latticePoint(v, point, last, done));
        if (done) {
          last = pos_[point];
          continue;
        }
      }
      int kind, mctx;
      i64 pred[3];
      fanPrediction(v, last, pred, kind, mctx);
      SP_RETURN_IF_ERROR(codePosition(point, pred, kind, mctx));
      if (spacing > 0) SP_RETURN_IF_ERROR(anchorPatches(point));
      last = pos_[point];
    }
    for (u32 point = points_; point < n_; ++point) {
      const i64 pred[3] = {last[0], last[1], last[2]};
      SP_RETURN_IF_ERROR(codePosition(point, pred, 3, 0));
      last = pos_[point];
    }
    return Status::ok();
  }

  // prm, §3.2: which faces are regular (a counterclockwise unit triangle of one relief's lattice, in cut-face order)
  // and their relief, per face in decode order; faces with a dummy corner or a repeated point never are.
  Status regularity() {
    row = HexLattice::withSpacing(spacing).row;
    face_relief_.assign(faces_, kNoRelief);
    u8 last_relief = kNoRelief;
    // Per cut vertex: on an irregular face decoded so far (bit 0), on a regular one (bit 1).
    std::vector<u8> near_irregular(cut_point_.size(), 0);
    for (u32 k = 0; k < faces_; ++k) {
      u32 pt[3];
      bool eligible = true;
      for (int i = 0; i < 3; ++i) {
        pt[i] = cut_point_[hv_[3 * k + i]];
        eligible &= pt[i] != kNone;
      }
      if (!eligible || pt[0] == pt[1] || pt[1] == pt[2] || pt[0] == pt[2]) continue;
      const u32 across = twin_[3 * k];
      const u8 parent = across != kNone && across / 3 < k ? face_relief_[across / 3] : kNoRelief;
      u8 truth_relief = kNoRelief;
      if (truth_) {
        // A face may be a unit triangle in several reliefs: the parent's code first (one patch, not two), then the
        // last code sent, then the lowest.
        const auto& tp = truth_->pts->pos;
        const u32 mask =
            latticeReliefs(tp[truthPoint(pt[0])], tp[truthPoint(pt[1])], tp[truthPoint(pt[2])], spacing, row);
        if (mask != 0)
          truth_relief = parent != kNoRelief && (mask >> parent & 1)             ? parent
                         : last_relief != kNoRelief && (mask >> last_relief & 1) ? last_relief
                                                                                 : u8(std::countr_zero(mask));
      }
      int irregular_corners = 0, regular_corners = 0;
      for (int i = 0; i < 3; ++i) {
        irregular_corners += near_irregular[hv_[3 * k + i]] & 1;
        regular_corners += near_irregular[hv_[3 * k + i]] >> 1;
      }
      const int ctx = (((across == kNone || across / 3 >= k ? 0
                         : parent == kNoRelief              ? 1
                                                            : 2) *
                            4 +
                        irregular_corners) *
                           4 +
                       regular_corners) *
                          2 +
                      (face_op_[k] == kC);
      if (!io_.bit(models_.regular[ctx], truth_relief != kNoRelief)) {
        for (int i = 0; i < 3; ++i) near_irregular[hv_[3 * k + i]] |= 1;
        continue;
      }
      for (int i = 0; i < 3; ++i) near_irregular[hv_[3 * k + i]] |= 2;
      ++regular_faces;
      if (parent != kNoRelief && io_.bit(models_.same_relief[0], truth_relief == parent)) {
        face_relief_[k] = parent;
        continue;
      }
      if (parent == kNoRelief && last_relief != kNoRelief &&
          io_.bit(models_.same_relief[1], truth_relief == last_relief)) {
        face_relief_[k] = last_relief;
        continue;
      }
      const u32 r = io_.sym(models_.relief, truth_relief == kNoRelief ? 0 : truth_relief);
      if (r >= 12) return malformed("relief id out of range");
      face_relief_[k] = last_relief = u8(r);
    }
    return Status::ok();
  }

  // prm, §3.3: regular patches (regular faces of one relief joined across edges), each point's coordinates in its
  // patches' lattices relative to the patch's first face (corners (0, 0), (1, 0), (0, 1)).
  Status buildPatches() {
    std::vector<u32> face_patch(faces_, kNone);
    std::vector<u32> stamp(n_, kNone);
    std::vector<std::array<i64, 2>> rel(n_);
    std::vector<u8> registered(n_, 0);
    std::vector<LatticeEntry> entries;
    std::vector<u32> queue;
    constexpr i64 kMaxRel = i64(1) << 30;
    for (u32 f0 = 0; f0 < faces_; ++f0) {
      if (face_relief_[f0] == kNoRelief || face_patch[f0] != kNone) continue;
      const u32 patch = u32(patches_.size());
      patches_.push_back(Patch{u8(face_relief_[f0] % 6), 0, 0, u8(face_relief_[f0] >= 6), f0, 0, 0});
      const auto place = [&](u32 point, std::array<i64, 2> ij) -> Status {
        if (std::abs(ij[0]) > kMaxRel || std::abs(ij[1]) > kMaxRel) return malformed("regular patch too large");
        if (stamp[point] == patch) {
          if (rel[point] != ij) return malformed("regular patch does not fit its lattice");
          return Status::ok();
        }
        stamp[point] = patch;
        rel[point] = ij;
        // A point is registered in its first kMaxPatchesPerPoint patches only (memory: at most that many entries
        // per point, whatever relief codes a payload gives); in later ones it is not a neighbour for predictions.
        if (registered[point] < kMaxPatchesPerPoint) {
          ++registered[point];
          entries.push_back({point, patch, int32_t(ij[0]), int32_t(ij[1])});
        }
        return Status::ok();
      };
      // A clockwise face (relief code >= 6) starts a mirrored frame: its corners' lattice steps are then still a
      // rotation of the relative ones.
      const bool cw = face_relief_[f0] >= 6;
      SP_RETURN_IF_ERROR(place(cut_point_[hv_[3 * f0]], {0, 0}));
      SP_RETURN_IF_ERROR(place(cut_point_[hv_[3 * f0 + 1]], cw ? std::array<i64, 2>{0, 1} : std::array<i64, 2>{1, 0}));
      SP_RETURN_IF_ERROR(place(cut_point_[hv_[3 * f0 + 2]], cw ? std::array<i64, 2>{1, 0} : std::array<i64, 2>{0, 1}));
      face_patch[f0] = patch;
      queue.assign(1, f0);
      for (size_t head = 0; head < queue.size(); ++head) {
        const u32 f = queue[head];
        for (u32 h = 3 * f; h < 3 * f + 3; ++h) {
          const u32 g = twin_[h];
          if (g == kNone) continue;
          const u32 fg = g / 3;
          if (face_patch[fg] != kNone || face_relief_[fg] != face_relief_[f]) continue;
          // Across edge x->y of f (third corner c), the face's third corner is x + y - c.
          const u32 x = cut_point_[hv_[h]], y = cut_point_[hv_[nextIn(h)]], c = cut_point_[hv_[prevIn(h)]];
          if (cut_point_[hv_[g]] != y || cut_point_[hv_[nextIn(g)]] != x)
            return malformed("regular faces glued inconsistently");
          const u32 c2 = cut_point_[hv_[prevIn(g)]];
          SP_RETURN_IF_ERROR(place(c2, {rel[x][0] + rel[y][0] - rel[c][0], rel[x][1] + rel[y][1] - rel[c][1]}));
          face_patch[fg] = patch;
          queue.push_back(fg);
        }
      }
    }
    patch_count = patches_.size();
    std::vector<u32>().swap(face_patch);
    std::vector<u32>().swap(stamp);
    std::vector<std::array<i64, 2>>().swap(rel);
    std::vector<u8>().swap(registered);
    std::vector<u32>().swap(queue);
    std::vector<u8>().swap(face_relief_);
    // Per point, its patches in patch order (entries are made patch by patch).
    point_begin_.assign(size_t(n_) + 1, 0);
    for (const LatticeEntry& e : entries) ++point_begin_[e.point + 1];
    for (u32 p = 0; p < n_; ++p) point_begin_[p + 1] += point_begin_[p];
    point_patches_.resize(entries.size());
    {
      std::vector<u32> fill(point_begin_.begin(), point_begin_.end() - 1);
      for (const LatticeEntry& e : entries) point_patches_[fill[e.point]++] = PointPatch{e.patch, e.i, e.j};
    }
    // The points by (patch, i, j), the first registered at a place kept (a patch may overlap itself).
    std::stable_sort(entries.begin(), entries.end());
    entries.erase(std::unique(entries.begin(), entries.end(),
                              [](const LatticeEntry& a, const LatticeEntry& b) { return !(a < b) && !(b < a); }),
                  entries.end());
    at_ = std::move(entries);
    // An open-addressing table over at_ for pointAt: the predictions look up 18 places per lattice point.
    size_t capacity = 16;
    while (capacity < 2 * at_.size()) capacity *= 2;
    place_slots_.assign(capacity, kNone);
    for (u32 k = 0; k < at_.size(); ++k) {
      size_t s = placeHash(at_[k].patch, at_[k].i, at_[k].j) & (capacity - 1);
      while (place_slots_[s] != kNone) s = (s + 1) & (capacity - 1);
      place_slots_[s] = k;
    }
    return Status::ok();
  }

  static size_t placeHash(u32 patch, int32_t i, int32_t j) {
    u64 h = u64(patch) * 0x9E3779B97F4A7C15ull ^ u64(u32(i)) * 0xC2B2AE3D27D4EB4Full ^
            u64(u32(j)) * 0x165667B19E3779F9ull;
    return size_t(h ^ (h >> 31));
  }

  // The point registered at relative coordinates (i, j) of a patch, or kNone.
  u32 pointAt(u32 patch, i64 i, i64 j) const {
    if (i < INT32_MIN || i > INT32_MAX || j < INT32_MIN || j > INT32_MAX) return kNone;
    const size_t mask = place_slots_.size() - 1;
    for (size_t s = placeHash(patch, int32_t(i), int32_t(j)) & mask;; s = (s + 1) & mask) {
      const u32 k = place_slots_[s];
      if (k == kNone) return kNone;
      const LatticeEntry& e = at_[k];
      if (e.patch == patch && e.i == int32_t(i) && e.j == int32_t(j)) return e.point;
    }
  }

  // The lattice coordinates of relative coordinates in an anchored patch.
  std::array<i64, 2> latticeCoords(const Patch& pa, i64 ri, i64 rj) const {
    const auto r = rot60({ri, rj}, pa.rotation);
    return {pa.oi + r[0], pa.oj + r[1]};
  }

  // A point of an anchored patch: its base coordinates follow from the lattice, its height is predicted from the
  // lattice neighbours within two steps already decoded: the least-squares quadratic through them (fitQuadratic)
  // when seven or more are known and one parallelogram around the point is, else the mean of the parallelograms,
  // else of the lines through the point, else of the neighbours, else the fan's prediction. `done` is false when
  // none of the point's patches is anchored.
  Status latticePoint(u32 v, u32 point, const Vec3u& last, bool& done) {
    done = false;
    const PointPatch* pp = nullptr;
    for (u32 e = point_begin_[point]; e < point_begin_[point + 1]; ++e)
      if (patches_[point_patches_[e].patch].anchored) {
        pp = &point_patches_[e];
        break;
      }
    if (!pp) return Status::ok();
    const Patch& pa = patches_[pp->patch];
    const int relief = pa.relief, axis = relief / 2;
    const auto ij = latticeCoords(pa, pp->i, pp->j);
    const i64 base[2] = {ij[0] * i64(spacing) + ij[1] * i64(spacing / 2), ij[1] * i64(row)};
    for (int w = 0; w < 2; ++w) {
      if (base[w] < 0 || base[w] > i64(max_coord_)) return malformed("lattice point outside the grid");
      pos_[point][size_t(baseAxis(relief, w))] = u32(base[w]);
      if (truth_ && truth_->pts->pos[truthPoint(point)][size_t(baseAxis(relief, w))] != u32(base[w]))
        return malformed("lattice point off its lattice");
    }
    // Heights of the known neighbours within two steps (kRing2 order), -1 for unknown.
    i64 h[18];
    u32 mask = 0, mag_sum = 0, nnb = 0;
    for (int k = 0; k < 18; ++k) {
      h[k] = -1;
      const u32 q = pointAt(pp->patch, pp->i + kRing2[k][0], pp->j + kRing2[k][1]);
      if (q == kNone || !known_[q]) continue;
      h[k] = pos_[q][size_t(axis)];
      mask |= 1u << k;
      if (k < 6) ++nnb, mag_sum += mag_[q];
    }
    i64 par = 0, lin = 0, nb = 0;
    u32 npar = 0, nlin = 0;
    for (int k = 0; k < 6; ++k) {
      if (h[k] < 0) continue;
      nb += h[k];
      const int next = (k + 1) % 6;
      if (h[next] >= 0 && h[12 + k] >= 0) ++npar, par += h[k] + h[next] - h[12 + k];
      if (h[6 + k] >= 0) ++nlin, lin += 2 * h[k] - h[6 + k];
    }
    int kind, mctx = nnb ? int(std::min<u32>((mag_sum + nnb / 2) / nnb, kMagContexts - 1)) : 0;
    i64 pred;
    const double* weights = npar > 0 && std::popcount(mask) >= 7 ? quadraticWeights(mask) : nullptr;
    if (weights) {
      kind = npar >= 3 ? 0 : npar == 2 ? 1 : 2;
      double fit = 0;
      for (int k = 0; k < 18; ++k)
        if (mask >> k & 1) fit += weights[k] * double(h[k]);
      pred = i64(std::floor(fit + 0.5));
    } else if (npar > 0) {
      kind = 3;
      pred = floorDiv(2 * par + npar, 2 * i64(npar));
    } else if (nlin > 0) {
      kind = 4;
      pred = floorDiv(2 * lin + nlin, 2 * i64(nlin));
    } else if (nnb > 0) {
      kind = 4;
      pred = floorDiv(2 * nb + nnb, 2 * i64(nnb));
    } else {
      kind = 5;
      i64 p3[3];
      int fan_kind;
      fanPrediction(v, last, p3, fan_kind, mctx);
      pred = p3[axis];
    }
    int cls = 0;
    SP_RETURN_IF_ERROR(codeCoordinate(point, axis, pred, models_.height[kind * kMagContexts + mctx], cls));
    known_[point] = 1;
    mag_[point] = u8(cls);
    ++lattice_points;
    done = true;
    return Status::ok();
  }

  // The weights that give, from the heights at the offsets of `mask` (kRing2), the value at the centre of the
  // least-squares quadratic through them (with a small ridge on the quadratic terms); nullptr when the fit is
  // singular. Computed once per mask, in IEEE double without contraction (the file is built with
  // -ffp-contract=off): encoder and decoder get the same bits.
  const double* quadraticWeights(u32 mask) {
    // A direct-mapped cache of kWeightSlots masks (a payload can reach about 130,000 masks; memory stays fixed).
    if (weights_.empty()) weights_.resize(kWeightSlots);
    Weights& wt = weights_[(mask * 0x9E3779B1u) >> (32 - kWeightSlotBits)];
    if (wt.mask == mask) return wt.ok ? wt.w.data() : nullptr;
    wt.mask = mask;
    wt.ok = false;
    constexpr double kRidge = 0.5, kHalfSqrt3 = 0.8660254037844386;
    double A[6][6] = {}, F[18][6];
    for (int k = 0; k < 18; ++k) {
      const double x = kRing2[k][0] + 0.5 * kRing2[k][1], y = kHalfSqrt3 * kRing2[k][1];
      const double f[6] = {1, x, y, x * x, x * y, y * y};
      for (int c = 0; c < 6; ++c) F[k][c] = f[c];
      if (!(mask >> k & 1)) continue;
      for (int r = 0; r < 6; ++r)
        for (int c = 0; c < 6; ++c) A[r][c] += f[r] * f[c];
    }
    for (int r = 3; r < 6; ++r) A[r][r] += kRidge;
    // The first row of A^-1 (Gauss-Jordan on [A | e0]): the value at the centre is row0 . (F^T h).
    double inv[6][6] = {};
    for (int r = 0; r < 6; ++r) inv[r][r] = 1;
    for (int c = 0; c < 6; ++c) {
      int piv = c;
      for (int r = c + 1; r < 6; ++r)
        if (std::abs(A[r][c]) > std::abs(A[piv][c])) piv = r;
      if (std::abs(A[piv][c]) < 1e-9) return nullptr;
      std::swap(A[c], A[piv]);
      std::swap(inv[c], inv[piv]);
      const double d = A[c][c];
      for (int k = 0; k < 6; ++k) A[c][k] /= d, inv[c][k] /= d;
      for (int r = 0; r < 6; ++r) {
        if (r == c) continue;
        const double m = A[r][c];
        for (int k = 0; k < 6; ++k) A[r][k] -= m * A[c][k], inv[r][k] -= m * inv[c][k];
      }
    }
    for (int k = 0; k < 18; ++k) {
      double w = 0;
      if (mask >> k & 1)
        for (int c = 0; c < 6; ++c) w += inv[0][c] * F[k][c];
      wt.w[size_t(k)] = w;
    }
    wt.ok = true;
    return wt.w.data();
  }

  // After a point is decoded in full: every patch of it not yet anchored is anchored at it (its lattice coordinates,
  // from its position, and the rotation of the patch's relative coordinates, coded).
  Status anchorPatches(u32 point) {
    for (u32 e = point_begin_[point]; e < point_begin_[point + 1]; ++e) {
      const PointPatch& pp = point_patches_[e];
      Patch& pa = patches_[pp.patch];
      if (pa.anchored) continue;
      std::array<i64, 2> ij;
      if (!latticeOf(pos_[point], pa.relief, spacing, row, ij))
        return malformed("regular patch anchored off its lattice");
      u32 rotation = 0;
      if (truth_) {
        // The patch's first face has relative corners (0, 0) and (1, 0) (counterclockwise) or (0, 1) (clockwise): the
        // rotation turns that step into their lattice step.
        const std::array<i64, 2> rel_step = pa.clockwise ? std::array<i64, 2>{0, 1} : std::array<i64, 2>{1, 0};
        const auto& tp = truth_->pts->pos;
        std::array<i64, 2> l0, l1;
        const bool ok0 = latticeOf(tp[truthPoint(cut_point_[hv_[3 * pa.first_face]])], pa.relief, spacing, row, l0);
        const bool ok1 = latticeOf(tp[truthPoint(cut_point_[hv_[3 * pa.first_face + 1]])], pa.relief, spacing, row, l1);
        if (!ok0 || !ok1) return malformed("regular face off its lattice");
        const std::array<i64, 2> step = {l1[0] - l0[0], l1[1] - l0[1]};
        while (rotation < 6 && rot60(rel_step, int(rotation)) != step) ++rotation;
        if (rotation == 6) return malformed("regular face is not a unit triangle");
      }
      rotation = io_.sym(models_.rotation, rotation);
      if (rotation >= 6) return malformed("patch rotation out of range");
      pa.rotation = u8(rotation);
      const auto r = rot60({pp.i, pp.j}, pa.rotation);
      pa.oi = ij[0] - r[0];
      pa.oj = ij[1] - r[1];
      pa.anchored = 1;
    }
    return Status::ok();
  }

  static i64 floorDiv(i64 a, i64 b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

  Status codePosition(u32 point, const i64* pred, int kind, int mctx) {
    int max_cls = 0;
    for (int i = 0; i < 3; ++i) {
      SymbolModel& model =
          models_.residual[((kind * kMagContexts + mctx) * 3 + i) * kAxisContexts + (max_cls <= 2   ? 0
                                                                                     : max_cls <= 4 ? 1
                                                                                                    : 2)];
      int cls = 0;
      SP_RETURN_IF_ERROR(codeCoordinate(point, i, pred[i], model, cls));
      max_cls = std::max(max_cls, cls);
    }
    known_[point] = 1;
    mag_[point] = u8(max_cls);
    return Status::ok();
  }

  // Codes coordinate `axis` of `point` against its prediction; `cls` is the residual's bit-length class.
  Status codeCoordinate(u32 point, int axis, i64 pred, SymbolModel& model, int& cls) {
    {
      const int i = axis;
      const i64 pr = std::clamp<i64>(pred, 0, i64(max_coord_));
      u64 zig = 0;
      if (truth_) {
        const Vec3u& actual = truth_->pts->pos[truthPoint(point)];
        const i64 r = i64(actual[i]) - pr;
        zig = r >= 0 ? u64(r) << 1 : (u64(-r) << 1) - 1;
      }
      // Small residuals are symbols of their own; larger ones an escape by bit length, then the bits below the
      // leading one raw.
      const int true_cls = bitLength(zig);
      const u32 sym = io_.sym(model, true_cls < kDirectBits + 1 ? u32(zig) : u32(kDirect + true_cls - kDirectBits - 1));
      u64 z = 0;
      if (sym < kDirect) {
        z = sym;
        cls = bitLength(z);
      } else {
        cls = int(sym - kDirect) + kDirectBits + 1;
        // The bit below the leading one is modelled (residuals are peaked within a length class), the rest raw.
        const int top =
            cls >= 2 ? io_.bit(models_.second_bit[std::min(cls, kClasses - 1)], int((zig >> (cls - 2)) & 1)) : 0;
        const int low = cls >= 2 ? cls - 2 : 0;
        const u64 mask = (u64(1) << low) - 1;
        u64 rest;
        if (low > 16) {
          const u64 hi = io_.bits(u32((zig & mask) >> 16), low - 16);
          rest = (hi << 16) | io_.bits(u32(zig & 0xFFFF), 16);
        } else {
          rest = io_.bits(u32(zig & mask), low);
        }
        z = cls >= 2 ? (u64(1) << (cls - 1)) | (u64(top) << low) | rest : 1;
      }
      const i64 r = (z & 1) ? -i64((z + 1) >> 1) : i64(z >> 1);
      const i64 value = pr + r;
      if (value < 0 || value > i64(max_coord_)) return malformed("position outside the grid");
      pos_[point][i] = u32(value);
    }
    return Status::ok();
  }

  // The encoder's point index of decoded point `point`.
  u32 truthPoint(u32 point) const { return point_of_out_[point]; }

  // The input's triangles: the cut mesh's faces without a dummy corner, over points; then orientation and copies.
  Status triangles() {
    std::vector<TriKey> keys;
    keys.reserve(faces_);
    u32 max_point = 0;
    for (u32 k = 0; k < faces_; ++k) {
      TriKey key;
      bool dummy = false;
      for (int i = 0; i < 3; ++i) {
        key[i] = cut_point_[hv_[3 * k + i]];
        dummy |= key[i] == kNone;
      }
      if (dummy) continue;
      std::sort(key.begin(), key.end());
      if (key[0] == key[1] || key[1] == key[2]) return malformed("triangle with a repeated point");
      max_point = std::max(max_point, key[2]);
      keys.push_back(key);
    }
    sortKeys(keys, max_point);
    if (std::adjacent_find(keys.begin(), keys.end()) != keys.end()) return malformed("triangle coded twice");
    if (keys.size() > t_) return malformed("more triangles than the header says");
    // The decode-order structures are no longer needed: free them before the triangles are built.
    std::vector<u32>().swap(nxt_);
    std::vector<u32>().swap(prv_);
    if (truth_) {
      Points& o = truth_->ordered;
      const Points& pts = *truth_->pts;
      o.pos.assign(n_, Vec3u{0, 0, 0});
      if (!pts.normals.empty()) o.normals.resize(n_);
      if (!pts.colors.empty()) o.colors.resize(n_);
      const size_t stride = pts.stride();
      o.scalars.resize(size_t(n_) * stride);
      for (u32 p = 0; p < pts.pos.size(); ++p) {
        const u32 q = truth_->out_of_point[p];
        o.pos[q] = pts.pos[p];
        if (!pts.normals.empty()) o.normals[q] = pts.normals[p];
        if (!pts.colors.empty()) o.colors[q] = pts.colors[p];
        std::copy_n(pts.scalars.begin() + ptrdiff_t(p * stride), stride, o.scalars.begin() + ptrdiff_t(q * stride));
      }
      std::vector<std::pair<TriKey, std::array<u32, 2>>> tk;
      tk.reserve(pts.tri_keys.size());
      for (size_t i = 0; i < pts.tri_keys.size(); ++i) {
        TriKey q;
        for (int c = 0; c < 3; ++c) q[c] = truth_->out_of_point[pts.tri_keys[i][c]];
        // Copies are counted as (a, b, c) sorted and (a, c, b): an odd permutation swaps them.
        std::array<u32, 2> copies = pts.tri_copies[i];
        int swaps = 0;
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 2 - a; ++b)
            if (q[b] > q[b + 1]) std::swap(q[b], q[b + 1]), ++swaps;
        if (swaps & 1) std::swap(copies[0], copies[1]);
        tk.push_back({q, copies});
      }
      std::sort(tk.begin(), tk.end());
      o.tri_keys.clear();
      o.tri_copies.clear();
      for (const auto& [q, c] : tk) o.tri_keys.push_back(q), o.tri_copies.push_back(c);
    }
    return codeFaceCopies(io_, kName, models_.orient.data(), keys, truth_ ? &truth_->ordered : nullptr, t_, tris_);
  }

  Io& io_;
  u32 n_;
  u64 t_;
  u32 faces_;
  Truth* truth_;
  u64 max_coord_;
  Models models_;
  u32 points_ = 0;
  u32 stack_distance_ = 0;
  // Per decoded half-edge.
  std::vector<u32> hv_, twin_, nxt_, prv_;
  // Per decoded cut vertex.
  std::vector<u32> cut_point_, first_he_, count_;
  std::vector<u8> is_first_;
  // Encoder's maps between its cut mesh and the decode order.
  std::vector<u32> enc_of_dec_, dec_of_enc_, dec_vertex_, point_of_out_;
  // prm: per face its relief (kNoRelief: irregular); the patches; per point its patches and relative lattice
  // coordinates (point_patches_[point_begin_[p] ..]); the points by patch and relative coordinates.
  u32 row = 0;
  std::vector<u8> face_relief_;
  std::vector<u8> face_op_;  // per face in decode order: its symbol (kNumOps for a component's first face)
  std::vector<Patch> patches_;
  std::vector<u32> point_begin_;
  std::vector<PointPatch> point_patches_;
  std::vector<LatticeEntry> at_;  // sorted by (patch, i, j)
  std::vector<u32> place_slots_;  // indices into at_ by placeHash (linear probing), kNone: empty
  struct Weights {
    u32 mask = UINT32_MAX;
    bool ok = false;
    std::array<double, 18> w{};
  };
  std::vector<Weights> weights_;  // quadraticWeights' cache
  // Per point.
  std::vector<Vec3u> pos_;
  std::vector<u8> known_, mag_;
  std::vector<Triangle> tris_;
  std::vector<OctNormal> normals_;
  std::vector<Rgba8> colors_;
  ScalarValues scalars_;
};

Status encodeImpl(const TileContext& ctx, const QuantizedMesh& mesh, u32 spacing, std::vector<u8>& out,
                  CodecStats* stats, TileSummary* summary) {
  Points pts;
  SP_RETURN_IF_ERROR(collectPoints(kName, ctx, mesh, {0, 1, 2}, pts));
  CutMesh cm;
  SP_RETURN_IF_ERROR(buildCutMesh(pts.tri_keys, cm));
  const u32 n = u32(pts.pos.size());
  const u64 t = mesh.triangles.size();
  if (stats) {
    *stats = CodecStats{};
    stats->points = n;
    stats->triangles = t;
  }
  const size_t start = out.size();
  ByteWriter w(out);
  w.varint(n);
  w.varint(t);
  w.varint(cm.faces);
  if (n > 0) {
    Truth truth;
    truth.cm = &cm;
    truth.pts = &pts;
    EncodeIo io;
    io.stats = stats;
    SP_RETURN_IF_ERROR(io.begin());
    Engine<EncodeIo> engine(io, ctx.bits, n, t, cm.faces, &truth);
    engine.layout = ctx.layout;
    engine.spacing = spacing;
    SP_RETURN_IF_ERROR(engine.run());
    SP_RETURN_IF_ERROR(io.end());
    if (stats) {
      stats->regular_faces = engine.regular_faces;
      stats->patches = engine.patch_count;
      stats->lattice_points = engine.lattice_points;
    }
    out.insert(out.end(), io.segments[0].begin(), io.segments[0].end());
  }
  if (stats) stats->payload_bytes = out.size() - start;
  if (summary) {
    *summary = summarize(mesh);
    summary->vertices = n;
    summary->faces = u32(t);
  }
  return Status::ok();
}

Result<QuantizedMesh> decodeImpl(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                 const DecodeLimits& limits, u32 spacing);

}  // namespace

Result<EncodedTile> edgebreakerEncode(const TileContext& ctx, const TileView& tile, const CodecOptions&) {
  EncodedTile e;
  SP_RETURN_IF_ERROR(encodeImpl(ctx, tile.mesh, 0, e.payload, nullptr, &e.decoded));
  return e;
}

Status edgebreakerEncodeWithStats(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out,
                                  CodecStats* stats) {
  return encodeImpl(ctx, mesh, 0, out, stats, nullptr);
}

Status edgebreakerEncodeOnLattice(const TileContext& ctx, const QuantizedMesh& mesh, uint32_t spacing,
                                  std::vector<uint8_t>& out, CodecStats* stats, TileSummary* summary) {
  if (spacing < 2 || spacing % 2 != 0 || spacing > kMaxLatticeSpacing)
    return makeError(ErrorCode::kInvalidArgument, "prm: lattice spacing " + std::to_string(spacing) +
                                                      " is not an even number in 2.." +
                                                      std::to_string(kMaxLatticeSpacing));
  return encodeImpl(ctx, mesh, spacing, out, stats, summary);
}

std::vector<int8_t> latticeFaceReliefs(const QuantizedMesh& mesh, uint32_t spacing) {
  std::vector<int8_t> relief(mesh.triangles.size(), -1);
  if (spacing < 2 || spacing % 2 != 0 || spacing > kMaxLatticeSpacing) return relief;
  const i64 row = HexLattice::withSpacing(spacing).row;
  const size_t n = mesh.positions.size();
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    const Triangle& t = mesh.triangles[f];
    if (t[0] >= n || t[1] >= n || t[2] >= n || t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;
    const u32 mask = latticeReliefs(mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]], spacing, row);
    if (mask == 0) continue;
    // A face may be a unit triangle of several reliefs' lattices: the one whose axis its normal is nearest.
    Vec3d p[3];
    for (int c = 0; c < 3; ++c)
      for (int k = 0; k < 3; ++k) p[c][size_t(k)] = double(mesh.positions[t[size_t(c)]][size_t(k)]);
    const Vec3d n = vcross(vsub(p[1], p[0]), vsub(p[2], p[0]));
    double best = -1;
    for (int r = 0; r < kLatticeKinds; ++r)
      if ((mask >> r & 1 || mask >> (r + kLatticeKinds) & 1) && std::abs(n[size_t(r / 2)]) > best)
        best = std::abs(n[size_t(r / 2)]), relief[f] = int8_t(r);
  }
  return relief;
}

Result<QuantizedMesh> edgebreakerDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                        const DecodeLimits& limits) {
  if (version < 1 || version > kPredictedAttributes)
    return makeError(ErrorCode::kUnknownVersion, "edgebreaker payload: unknown version " + std::to_string(version));
  return decodeImpl(ctx, version, payload, limits, 0);
}

Result<QuantizedMesh> edgebreakerDecodeOnLattice(const TileContext& ctx, std::span<const uint8_t> payload,
                                                 const DecodeLimits& limits, uint32_t spacing) {
  if (spacing < 2 || spacing % 2 != 0 || spacing > kMaxLatticeSpacing)
    return makeError(ErrorCode::kMalformed, "prm payload: lattice spacing " + std::to_string(spacing) +
                                                " is not an even number in 2.." + std::to_string(kMaxLatticeSpacing));
  return decodeImpl(ctx, kPredictedAttributes, payload, limits, spacing);
}

namespace {

Result<QuantizedMesh> decodeImpl(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                 const DecodeLimits& limits, u32 spacing) {
  const std::string what = spacing ? "prm payload" : "edgebreaker payload";
  ByteReader r(payload, what);
  u64 n = 0, t = 0, faces = 0;
  SP_RETURN_IF_ERROR(r.varint(n));
  SP_RETURN_IF_ERROR(r.varint(t));
  SP_RETURN_IF_ERROR(r.varint(faces));
  SP_RETURN_IF_ERROR(checkLimits(what, n, t, limits));
  // Every face of the cut mesh is an input triangle or a dummy face on one of their boundary edges.
  if (faces > 4 * t || faces > UINT32_MAX / 3 || (n == 0 && (t != 0 || faces != 0)) || (t > 0 && faces == 0))
    return makeError(ErrorCode::kMalformed, what + ": inconsistent counts");
  if (n == 0) {
    if (r.remaining() != 0) return makeError(ErrorCode::kMalformed, what + ": bytes after an empty tile");
    return QuantizedMesh{};
  }
  DecodeIo io;
  io.codec = spacing ? std::string_view("prm") : kName;
  io.segments.push_back(payload.subspan(r.position()));
  SP_RETURN_IF_ERROR(io.begin());
  Engine<DecodeIo> engine(io, ctx.bits, u32(n), t, u32(faces), nullptr);
  engine.layout = ctx.layout;
  engine.version = version;
  engine.spacing = spacing;
  SP_RETURN_IF_ERROR(engine.run());
  SP_RETURN_IF_ERROR(io.end());
  QuantizedMesh mesh = engine.mesh();
  if (mesh.triangles.size() != t)
    return makeError(ErrorCode::kMalformed, what + ": decoded " + std::to_string(mesh.triangles.size()) +
                                                " triangles, header says " + std::to_string(t));
  SP_RETURN_IF_ERROR(validateTile(ctx, mesh));
  return mesh;
}

}  // namespace
}  // namespace scanpress
