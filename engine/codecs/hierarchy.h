// What the two progressive hierarchy codecs (kdtree.cpp, octree.cpp) share: the distinct points of a tile in
// Morton order with its triangles as unordered keys, the root cube, the level-segmented payload header, the
// range-coder plumbing of an engine that is templated on encoding or decoding, and the final segment's coding of
// triangle orientation and multiplicity and of raw attributes (payload v1; v2's predicted ones: attributes.h).
// Internal to engine/codecs.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "engine/codecs/codec.h"
#include "engine/entropy/range_coder.h"

namespace scanpress::hierarchy {

using u8 = uint8_t;
using u32 = uint32_t;
using u64 = uint64_t;
using Key = unsigned __int128;
using Axes = std::array<int, 3>;    // the order in which a level splits the axes
using TriKey = std::array<u32, 3>;  // a triangle's corners, sorted

constexpr u32 kMaxPoints = 1u << 26;
constexpr u64 kMaxTriangles = 1ull << 28;

// The interleaved bits of p, most significant level first, axes in `axes` order within a level.
Key mortonKey(const Vec3u& p, int bits, const Axes& axes);

// A tile's distinct (position, normal, color, scalars) points sorted by Morton key (ties by attributes), and its triangles
// as sorted keys over point indices with the copies in each orientation (0: as sorted a,b,c; 1: a,c,b).
struct Points {
  std::vector<Vec3u> pos;
  std::vector<OctNormal> normals;
  std::vector<Rgba8> colors;
  ScalarValues scalars;  // the layout's scalarStride() words per point
  size_t stride() const { return pos.empty() ? 0 : scalars.size() / pos.size(); }
  std::vector<TriKey> tri_keys;
  std::vector<std::array<u32, 2>> tri_copies;
};
Status collectPoints(std::string_view codec, const TileContext& ctx, const QuantizedMesh& mesh, const Axes& axes,
                     Points& out);

// The smallest grid-aligned cube holding the Morton-sorted points: its level k0 (side 2^(bits-k0)) and corner.
void rootCube(const Points& pts, int bits, const Axes& axes, int& k0, Vec3u& root);

// Payload header: varint N, varint T; when N > 0: u8 k0, [u8 axis order], 3 x varint root cell index,
// varint S, S x varint segment length.
struct Header {
  u32 n = 0;
  u64 t = 0;
  int k0 = 0;
  Vec3u root{0, 0, 0};
  Axes axes{0, 1, 2};
  std::vector<u64> seg_len;
  size_t header_bytes = 0;
};
struct HeaderFormat {
  std::string_view codec;
  bool axis_order = false;  // the header names the axis order (one of the six permutations)
  size_t segments(int bits, int k0) const { return size_t(bits - k0 + 1); }
};
// Pads the last segment with zero bytes up to the codec's payload floor.
void writeHeader(const HeaderFormat& f, const Header& h, int bits, const AttributeLayout& layout,
                 const std::vector<std::vector<u8>>& segments, std::vector<u8>& out);
// Checks the counts against `limits` (the index's) before anything is allocated.
Result<Header> readHeader(const HeaderFormat& f, const TileContext& ctx, std::span<const u8> payload,
                          const DecodeLimits& limits);
Status checkVersion(std::string_view codec, uint16_t version);
std::vector<CodecLevel> headerLevels(const Header& h, int bits);
// A payload's levels, from its header (CodecInfo::levels).
Result<std::vector<CodecLevel>> payloadLevels(const HeaderFormat& f, const TileContext& ctx, uint16_t version,
                                              std::span<const u8> payload, const DecodeLimits& limits);
// What the encoder returns for a payload it wrote from `mesh`: the payload, the counts its header gives (the
// distinct points, every triangle), the bounds of the mesh's positions (the points'), the levels.
Result<EncodedTile> encodedTile(const HeaderFormat& f, const TileContext& ctx, const QuantizedMesh& mesh,
                                std::vector<u8> payload);
// The checks on a decoded mesh: the header's triangle count at the lossless level, then validateTile.
Status checkDecoded(std::string_view codec, const TileContext& ctx, const Header& h, int target,
                    const QuantizedMesh& mesh);
// The segments that decoding up to `target` needs (all of them for the lossless level), checked against the payload.
Result<std::vector<std::span<const u8>>> levelSegments(std::string_view codec, const Header& h, int bits,
                                                       std::span<const u8> payload, int target);

// Range-coder plumbing for an engine templated on the direction: the encoder writes one segment per begin/end
// pair and meters ideal bits into a stats field; the decoder reads the segments in order.
struct EncodeIo {
  std::vector<std::vector<u8>> segments;
  std::unique_ptr<RangeEncoder> enc;
  CodecStats* stats = nullptr;
  Status begin() {
    segments.emplace_back();
    enc = std::make_unique<RangeEncoder>(segments.back());
    return Status::ok();
  }
  Status end() {
    enc->finish();
    enc.reset();
    return Status::ok();
  }
  void meter(double CodecStats::*part) { enc->setCostMeter(stats ? &(stats->*part) : nullptr); }
  int bit(BitModel& m, int v) {
    enc->encodeBit(m, v);
    return v;
  }
  u32 sym(SymbolModel& m, u32 v) {
    enc->encodeSymbol(m, v);
    return v;
  }
  u32 uniform(u32 v, u32 n) {
    enc->encodeUniform(v, n);
    return v;
  }
  u32 bits(u32 v, int n) {
    enc->encodeBits(v, n);
    return v;
  }
};

struct DecodeIo {
  std::string_view codec;
  std::vector<std::span<const u8>> segments;
  size_t next = 0;
  std::unique_ptr<RangeDecoder> dec;
  Status begin();
  Status end();
  void meter(double CodecStats::*) {}
  int bit(BitModel& m, int) { return dec->decodeBit(m); }
  u32 sym(SymbolModel& m, u32) { return dec->decodeSymbol(m); }
  u32 uniform(u32, u32 n) { return dec->decodeUniform(n); }
  u32 bits(u32, int n) { return dec->decodeBits(n); }
};

// Orientation bit (0: as sorted a,b,c; 1: a,c,b) that makes triangle u traverse x->y opposite to parent t.
u8 consistentOrientation(const TriKey& t, u8 ot, const TriKey& u, u32 x, u32 y);

// Breadth-first over the sorted, distinct triangle keys across shared edges; calls visit(u, parent, x, y) in a
// fixed order (parent < 0 for the first triangle of a component; x->y the shared edge as the parent lists it).
// visit returns the orientation decided for u.
template <class Visit>
void breadthFirst(const std::vector<TriKey>& keys, std::vector<u8>& orient, Visit visit);

// The keys as triangles, oriented to agree across shared edges where they can (coarse levels carry no codes).
std::vector<Triangle> orientedTriangles(const std::vector<TriKey>& keys);

// The triangles of the final level: for each key (breadth-first), one copy as the parent's orientation predicts,
// one copy the other way, or explicit counts of both. `truth` (encoder) holds keys and copies over the same
// vertex names; `orient_models` are two 3-symbol models (first triangle of a component, the others).
template <class Io>
Status codeFaceCopies(Io& io, std::string_view codec, SymbolModel* orient_models, const std::vector<TriKey>& keys,
                      const Points* truth, u64 max_triangles, std::vector<Triangle>& out);

// Normals and colors per vertex, raw; truth (encoder) in the vertices' order.
template <class Io>
void codeRawAttributes(Io& io, const AttributeLayout& layout, u32 n, const Points* truth,
                       std::vector<OctNormal>& normals, std::vector<Rgba8>& colors);

template <class T>
bool eraseOne(std::vector<T>& v, T x) {
  for (size_t i = 0; i < v.size(); ++i)
    if (v[i] == x) {
      v[i] = v.back();
      v.pop_back();
      return true;
    }
  return false;
}
template <class T>
void replaceOne(std::vector<T>& v, T from, T to) {
  for (auto& e : v)
    if (e == from) {
      e = to;
      return;
    }
}

// Sorts (key, flags) entries and merges those of one key by or-ing their flags.
template <class K>
void sortAndMergeFlags(std::vector<std::pair<K, u8>>& v) {
  std::sort(v.begin(), v.end());
  size_t n = 0;
  for (size_t i = 0; i < v.size(); ++i) {
    if (n > 0 && v[n - 1].first == v[i].first) v[n - 1].second |= v[i].second;
    else v[n++] = v[i];
  }
  v.resize(n);
}

// How many of the Morton-ordered points [s, e) have bit `bit` of `axis` clear: the lower half of a split.
inline u32 lowerHalf(const std::vector<Vec3u>& pos, u32 s, u32 e, int axis, int bit) {
  const auto first = pos.begin() + s;
  return static_cast<u32>(std::partition_point(first, pos.begin() + e,
                                               [&](const Vec3u& q) { return ((q[axis] >> bit) & 1) == 0; }) -
                          first);
}

// Where the centroid of the neighbours `nb` (doubled centers in c2) lies relative to a split plane, in units of
// `half` (bins 0..9; kCentroidBins - 1: no neighbours): geometry predicted from connectivity.
constexpr int kCentroidBins = 11;
inline int centroidBin(const std::vector<u32>& nb, const std::vector<Vec3u>& c2, int axis, double plane, double half) {
  if (nb.empty()) return kCentroidBins - 1;
  u64 sum = 0;
  for (u32 n : nb) sum += c2[n][axis];
  const double t = (0.5 * double(sum) / double(nb.size()) - plane) / half;
  static constexpr double kEdges[] = {-2, -1, -0.5, -0.15, 0, 0.15, 0.5, 1, 2};
  int bin = 0;
  while (bin < 9 && t >= kEdges[bin]) ++bin;
  return bin;
}

// --- templates -------------------------------------------------------------------------------------------------

// The triangles on each edge of the keys: for each smaller corner lo, (hi, third corner, triangle index) sorted.
struct EdgeThirds {
  std::vector<u32> start;  // per vertex lo, into items; one extra entry at the end
  std::vector<std::array<u32, 3>> items;
  explicit EdgeThirds(const std::vector<TriKey>& keys);
};

template <class Visit>
void breadthFirst(const std::vector<TriKey>& keys, std::vector<u8>& orient, Visit visit) {
  const size_t nt = keys.size();
  orient.assign(nt, 0);
  const EdgeThirds adj(keys);
  std::vector<u8> seen(nt, 0);
  std::vector<u32> queue;
  for (size_t root = 0; root < nt; ++root) {
    if (seen[root]) continue;
    seen[root] = 1;
    orient[root] = visit(root, -1, 0, 0);
    queue.assign(1, u32(root));
    for (size_t head = 0; head < queue.size(); ++head) {
      const u32 t = queue[head];
      const auto& k = keys[t];
      for (int side = 0; side < 3; ++side) {
        const u32 x = k[side], y = k[(side + 1) % 3];
        const u32 lo = std::min(x, y), hi = std::max(x, y);
        const auto end = adj.items.begin() + adj.start[lo + 1];
        auto it = std::lower_bound(adj.items.begin() + adj.start[lo], end, std::array<u32, 3>{hi, 0, 0});
        for (; it != end && (*it)[0] == hi; ++it) {
          const u32 u = (*it)[2];
          if (seen[u]) continue;
          seen[u] = 1;
          orient[u] = visit(u, int(t), x, y);
          queue.push_back(u);
        }
      }
    }
  }
}

inline u32 codeCount(auto& io, u32 v) {
  int len = 0;
  while (len < 32 && (v >> len) != 0) ++len;
  len = int(io.uniform(u32(len), 33));
  return len == 0 ? 0 : io.bits(v, len);
}

template <class Io>
Status codeFaceCopies(Io& io, std::string_view codec, SymbolModel* orient_models, const std::vector<TriKey>& keys,
                      const Points* truth, u64 max_triangles, std::vector<Triangle>& out) {
  std::vector<u8> orient;
  Status status = Status::ok();
  u64 total = 0;
  out.clear();
  breadthFirst(keys, orient, [&](size_t u, int t, u32 x, u32 y) -> u8 {
    const u8 pred = t < 0 ? 0 : consistentOrientation(keys[t], orient[t], keys[u], x, y);
    u32 fwd = 0, bwd = 0, sym = 2;
    if (truth) {
      auto it = std::lower_bound(truth->tri_keys.begin(), truth->tri_keys.end(), keys[u]);
      if (it == truth->tri_keys.end() || *it != keys[u]) {
        status = makeError(ErrorCode::kInternal, std::string(codec) + " encoder: triangle set mismatch");
        return 0;
      }
      fwd = truth->tri_copies[it - truth->tri_keys.begin()][0];
      bwd = truth->tri_copies[it - truth->tri_keys.begin()][1];
      if (fwd + bwd == 1) sym = ((fwd == 1) == (pred == 0)) ? 0 : 1;
    }
    sym = io.sym(orient_models[t < 0 ? 0 : 1], sym);
    if (sym == 0) fwd = pred == 0, bwd = pred == 1;
    else if (sym == 1) fwd = pred == 1, bwd = pred == 0;
    else {
      fwd = codeCount(io, fwd);
      bwd = codeCount(io, bwd);
    }
    total += u64(fwd) + bwd;
    if (fwd + u64(bwd) == 0 || total > max_triangles) {
      if (status.isOk())
        status = makeError(ErrorCode::kMalformed, std::string(codec) + " payload: triangle copies out of range");
      return 0;
    }
    const auto& k = keys[u];
    for (u32 i = 0; i < fwd; ++i) out.push_back({k[0], k[1], k[2]});
    for (u32 i = 0; i < bwd; ++i) out.push_back({k[0], k[2], k[1]});
    return fwd > 0 ? 0 : 1;
  });
  if (status.isOk() && truth && keys.size() != truth->tri_keys.size())
    status = makeError(ErrorCode::kInternal, std::string(codec) + " encoder: triangle set mismatch");
  return status;
}

template <class Io>
void codeRawAttributes(Io& io, const AttributeLayout& layout, u32 n, const Points* truth,
                       std::vector<OctNormal>& normals, std::vector<Rgba8>& colors) {
  if (layout.hasNormals()) {
    normals.resize(n);
    for (u32 i = 0; i < n; ++i)
      for (int c = 0; c < 2; ++c)
        normals[i][c] = static_cast<uint16_t>(io.bits(truth ? truth->normals[i][c] : 0, layout.normal_bits));
  }
  if (layout.hasColors()) {
    colors.assign(n, Rgba8{0, 0, 0, 255});
    for (u32 i = 0; i < n; ++i)
      for (int c = 0; c < layout.color_channels; ++c)
        colors[i][c] = static_cast<u8>(io.bits(truth ? truth->colors[i][c] : 0, 8));
  }
}

}  // namespace scanpress::hierarchy
