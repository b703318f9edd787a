#include "engine/codecs/hierarchy.h"

#include <algorithm>

#include "engine/io/bytes.h"
#include "engine/octahedral.h"
#include "engine/quantize.h"

namespace scanpress::hierarchy {
namespace {

constexpr Axes kAxisOrders[6] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};

int axisOrderIndex(const Axes& axes) {
  for (int i = 0; i < 6; ++i)
    if (kAxisOrders[i] == axes) return i;
  return 0;
}

}  // namespace

Key mortonKey(const Vec3u& p, int bits, const Axes& axes) {
  Key k = 0;
  for (int b = bits - 1; b >= 0; --b)
    for (int a : axes) k = (k << 1) | ((p[a] >> b) & 1);
  return k;
}

Status collectPoints(std::string_view codec, const TileContext& ctx, const QuantizedMesh& mesh, const Axes& axes,
                     Points& out) {
  const std::string name(codec);
  const size_t nv = mesh.positions.size();
  if (nv >= kMaxPoints || mesh.triangles.size() >= kMaxTriangles)
    return makeError(ErrorCode::kLimitExceeded, name + ": tile has more than 2^26 vertices or 2^28 triangles");
  if (ctx.layout.hasNormals() != !mesh.normals.empty() || (ctx.layout.hasNormals() && mesh.normals.size() != nv) ||
      ctx.layout.hasColors() != !mesh.colors.empty() || (ctx.layout.hasColors() && mesh.colors.size() != nv) ||
      mesh.scalars.size() != nv * size_t(ctx.layout.scalarStride()))
    return makeError(ErrorCode::kInvalidArgument, name + ": attributes do not match the layout");
  const size_t stride = size_t(ctx.layout.scalarStride());
  const u32 max_coord = (1u << ctx.bits) - 1;
  for (const auto& p : mesh.positions)
    if (p[0] > max_coord || p[1] > max_coord || p[2] > max_coord)
      return makeError(ErrorCode::kInvalidArgument, name + ": vertex outside the grid");
  // Colors below 8 bits must sit on their levels: the predicted coding codes levels.
  for (size_t i = 0; i < mesh.colors.size(); ++i)
    if (quantizeColor(mesh.colors[i], ctx.layout) != mesh.colors[i])
      return makeError(ErrorCode::kInvalidArgument,
                       name + ": color of vertex " + std::to_string(i) + " is not one of " +
                           std::to_string(1 << ctx.layout.color_bits) + " levels per channel (quantizeColor)");
  // Quantized scalar channels must sit on their levels: the predicted coding codes levels.
  for (size_t i = 0, offset = 0; i < ctx.layout.scalars.size();
       offset += size_t(scalarTypeWords(ctx.layout.scalars[i].type)), ++i)
    if (const ScalarChannel& c = ctx.layout.scalars[i]; c.bits)
      for (size_t v = 0; v < nv; ++v)
        if (!onScalarLevel(c, mesh.scalars.data() + v * stride + offset))
          return makeError(ErrorCode::kInvalidArgument, name + ": " + c.name + " of vertex " + std::to_string(v) +
                                                            " is not a multiple of 2^-" + std::to_string(int(c.bits)) +
                                                            " (snapScalar)");
  // Octahedral codes run to 2^bits - 2 (octahedral.h); the predicted coding (attributes.h) codes no other.
  const u32 max_oct = ctx.layout.hasNormals() ? (1u << ctx.layout.normal_bits) - 2 : 0;
  for (size_t i = 0; i < mesh.normals.size(); ++i)
    if (mesh.normals[i][0] > max_oct || mesh.normals[i][1] > max_oct)
      return makeError(ErrorCode::kInvalidArgument, name + ": normal of vertex " + std::to_string(i) +
                                                        " is not an octahedral code (above 2^bits - 2)");

  std::vector<Key> keys(nv);
  for (size_t i = 0; i < nv; ++i) keys[i] = mortonKey(mesh.positions[i], ctx.bits, axes);
  auto attrLess = [&](u32 a, u32 b) {
    if (!mesh.normals.empty() && mesh.normals[a] != mesh.normals[b]) return mesh.normals[a] < mesh.normals[b];
    if (!mesh.colors.empty() && mesh.colors[a] != mesh.colors[b]) return mesh.colors[a] < mesh.colors[b];
    if (stride)
      return std::lexicographical_compare(mesh.scalars.begin() + a * stride, mesh.scalars.begin() + (a + 1) * stride,
                                          mesh.scalars.begin() + b * stride, mesh.scalars.begin() + (b + 1) * stride);
    return false;
  };
  std::vector<u32> order(nv);
  for (size_t i = 0; i < nv; ++i) order[i] = u32(i);
  std::sort(order.begin(), order.end(), [&](u32 a, u32 b) {
    if (keys[a] != keys[b]) return keys[a] < keys[b];
    return attrLess(a, b);
  });
  out = Points{};
  std::vector<u32> point_of(nv);
  for (size_t i = 0; i < nv; ++i) {
    const u32 v = order[i];
    if (i == 0 || keys[v] != keys[order[i - 1]] || attrLess(order[i - 1], v)) {
      out.pos.push_back(mesh.positions[v]);
      if (!mesh.normals.empty()) out.normals.push_back(mesh.normals[v]);
      if (!mesh.colors.empty()) out.colors.push_back(mesh.colors[v]);
      out.scalars.insert(out.scalars.end(), mesh.scalars.begin() + v * stride, mesh.scalars.begin() + (v + 1) * stride);
    }
    point_of[v] = u32(out.pos.size() - 1);
  }

  std::vector<std::pair<TriKey, u8>> tris;
  tris.reserve(mesh.triangles.size());
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    TriKey q;
    for (int c = 0; c < 3; ++c) {
      if (mesh.triangles[t][c] >= nv)
        return makeError(ErrorCode::kInvalidArgument,
                         name + ": triangle " + std::to_string(t) + " indexes past the vertices");
      q[c] = point_of[mesh.triangles[t][c]];
    }
    if (out.pos[q[0]] == out.pos[q[1]] || out.pos[q[1]] == out.pos[q[2]] || out.pos[q[0]] == out.pos[q[2]])
      return makeError(ErrorCode::kInvalidArgument,
                       name + ": triangle " + std::to_string(t) + " has two corners in one grid cell");
    const int r = int(std::min_element(q.begin(), q.end()) - q.begin());
    std::rotate(q.begin(), q.begin() + r, q.end());
    u8 o = 0;
    if (q[1] > q[2]) std::swap(q[1], q[2]), o = 1;
    tris.push_back({q, o});
  }
  std::sort(tris.begin(), tris.end());
  for (const auto& [q, o] : tris) {
    if (out.tri_keys.empty() || out.tri_keys.back() != q) {
      out.tri_keys.push_back(q);
      out.tri_copies.push_back({0, 0});
    }
    out.tri_copies.back()[o]++;
  }
  return Status::ok();
}

void rootCube(const Points& pts, int bits, const Axes& axes, int& k0, Vec3u& root) {
  k0 = bits;
  const Key diff = mortonKey(pts.pos.front(), bits, axes) ^ mortonKey(pts.pos.back(), bits, axes);
  for (int b = 3 * bits - 1; b >= 0; --b)
    if ((diff >> b) & 1) {
      k0 = (3 * bits - 1 - b) / 3;
      break;
    }
  for (int a = 0; a < 3; ++a) root[a] = k0 == 0 ? 0 : (pts.pos[0][a] >> (bits - k0)) << (bits - k0);
}

void writeHeader(const HeaderFormat& f, const Header& h, int bits, const AttributeLayout& layout,
                 const std::vector<std::vector<u8>>& segments, std::vector<u8>& out) {
  const size_t start = out.size();
  ByteWriter w(out);
  w.varint(h.n);
  w.varint(h.t);
  if (h.n == 0) return;
  w.u8(static_cast<u8>(h.k0));
  if (f.axis_order) w.u8(static_cast<u8>(axisOrderIndex(h.axes)));
  for (int a = 0; a < 3; ++a) w.varint(h.k0 == 0 ? 0 : h.root[a] >> (bits - h.k0));
  w.varint(segments.size());
  // A payload below its codec's floor (FORMAT.md: dense lattices code at 0.15 bit per point) is padded with zero
  // bytes at the end of its last segment, which the range decoder never reads: the floor bounds what an index may
  // claim per byte, and every tile the encoder meets stays writable.
  auto varintSize = [](u64 v) {
    u64 n = 1;
    while (v >= 0x80) v >>= 7, ++n;
    return n;
  };
  u64 data = 0;
  for (const auto& s : segments) data += s.size();
  const u64 need = findCodec(f.codec)->floor.minPayloadBytes(layout, h.n, h.t);
  u64 pad = 0;
  for (;;) {  // a longer last segment may take a longer varint
    u64 head = out.size() - start;
    for (size_t i = 0; i < segments.size(); ++i)
      head += varintSize(segments[i].size() + (i + 1 == segments.size() ? pad : 0));
    if (head + data + pad >= need) break;
    pad = need - head - data;
  }
  for (size_t i = 0; i < segments.size(); ++i) w.varint(segments[i].size() + (i + 1 == segments.size() ? pad : 0));
  for (const auto& s : segments) w.bytes(s);
  out.resize(out.size() + pad, 0);
}

Status checkVersion(std::string_view codec, uint16_t version) {
  // 2: predicted attributes; 3: coarse levels with their own (attributes.h); 4: with their creases (creases.h).
  const CodecInfo* info = findCodec(codec);
  const uint16_t known = info ? info->version : 3;
  if (version < 1 || version > known)
    return makeError(ErrorCode::kUnknownVersion, std::string(codec) + " codec version " + std::to_string(version) +
                                                     " is not known to this build (knows 1 to " +
                                                     std::to_string(known) + ")");
  return Status::ok();
}

Result<Header> readHeader(const HeaderFormat& f, const TileContext& ctx, std::span<const u8> payload,
                          const DecodeLimits& limits) {
  ByteReader r(payload, std::string(f.codec) + " payload");
  Header h;
  u64 n = 0;
  SP_RETURN_IF_ERROR(r.varint(n));
  SP_RETURN_IF_ERROR(r.varint(h.t));
  SP_RETURN_IF_ERROR(checkLimits(std::string(f.codec) + " payload", n, h.t, limits));
  if (n > kMaxPoints || h.t > kMaxTriangles)
    return r.error(ErrorCode::kLimitExceeded, "tile claims " + std::to_string(n) + " vertices and " +
                                                  std::to_string(h.t) + " triangles (limits 2^26, 2^28)");
  if (n > 1024 * u64(payload.size()) + 1024 || h.t > 64 * n + 64)
    return r.error(ErrorCode::kMalformed, "counts too large for the payload");
  h.n = static_cast<u32>(n);
  if (h.n == 0) {
    if (h.t != 0) return r.error(ErrorCode::kMalformed, "triangles without vertices");
    h.header_bytes = r.position();
    return h;
  }
  u8 k0 = 0;
  SP_RETURN_IF_ERROR(r.u8(k0));
  if (k0 > ctx.bits) return r.error(ErrorCode::kMalformed, "root level beyond the grid");
  h.k0 = k0;
  if (f.axis_order) {
    u8 order = 0;
    SP_RETURN_IF_ERROR(r.u8(order));
    if (order >= 6) return r.error(ErrorCode::kMalformed, "axis order " + std::to_string(order) + " is not 0..5");
    h.axes = kAxisOrders[order];
  }
  for (int a = 0; a < 3; ++a) {
    u64 idx = 0;
    SP_RETURN_IF_ERROR(r.varint(idx));
    if (idx >= (u64(1) << k0)) return r.error(ErrorCode::kMalformed, "root cell outside the grid");
    h.root[a] = static_cast<u32>(idx << (ctx.bits - k0));
  }
  u64 segs = 0;
  SP_RETURN_IF_ERROR(r.varint(segs));
  if (segs != f.segments(ctx.bits, k0)) return r.error(ErrorCode::kMalformed, "wrong number of level segments");
  h.seg_len.resize(segs);
  for (auto& len : h.seg_len) {
    SP_RETURN_IF_ERROR(r.varint(len));
    if (len > (u64(1) << 40)) return r.error(ErrorCode::kMalformed, "segment length out of range");
  }
  h.header_bytes = r.position();
  return h;
}

std::vector<CodecLevel> headerLevels(const Header& h, int bits) {
  std::vector<CodecLevel> levels;
  auto level = [&](int l, u64 end) {
    CodecLevel c;
    c.level = u32(l);
    c.end_bytes = end;
    c.kind = LevelKind::kCells;
    c.cell_bits = u32(bits - l);
    c.complete = l == bits;
    levels.push_back(c);
  };
  u64 end = h.header_bytes;
  if (h.n == 0) {
    level(bits, end);
    return levels;
  }
  level(h.k0, end);
  for (size_t i = 0; i + 1 < h.seg_len.size(); ++i) {
    end += h.seg_len[i];
    level(h.k0 + int(i) + 1, end);
  }
  end += h.seg_len.back();
  if (levels.back().level == u32(bits)) levels.back().end_bytes = end;
  else level(bits, end);
  return levels;
}

Result<std::vector<CodecLevel>> payloadLevels(const HeaderFormat& f, const TileContext& ctx, uint16_t version,
                                              std::span<const u8> payload, const DecodeLimits& limits) {
  SP_RETURN_IF_ERROR(checkVersion(f.codec, version));
  SP_ASSIGN_OR_RETURN(Header h, readHeader(f, ctx, payload, limits));
  return headerLevels(h, ctx.bits);
}

Result<EncodedTile> encodedTile(const HeaderFormat& f, const TileContext& ctx, const QuantizedMesh& mesh,
                                std::vector<u8> payload) {
  SP_ASSIGN_OR_RETURN(Header h, readHeader(f, ctx, payload, DecodeLimits{UINT32_MAX, UINT32_MAX}));
  EncodedTile e;
  const TileSummary bounds = summarize(mesh);
  e.decoded.vertices = h.n;
  e.decoded.faces = u32(h.t);
  e.decoded.lo = bounds.lo;
  e.decoded.hi = bounds.hi;
  e.levels = headerLevels(h, ctx.bits);
  e.payload = std::move(payload);
  return e;
}

Status checkDecoded(std::string_view codec, const TileContext& ctx, const Header& h, int target,
                    const QuantizedMesh& mesh) {
  if (target >= ctx.bits && mesh.triangles.size() != h.t)
    return makeError(ErrorCode::kMalformed, std::string(codec) + " payload: decoded " +
                                                std::to_string(mesh.triangles.size()) + " triangles, header says " +
                                                std::to_string(h.t));
  return validateTile(ctx, mesh);
}

Result<std::vector<std::span<const u8>>> levelSegments(std::string_view codec, const Header& h, int bits,
                                                       std::span<const u8> payload, int target) {
  const std::string name(codec);
  // Every level after the root up to `target`, and the final segment for the last level.
  const size_t needed = target >= bits ? h.seg_len.size() : size_t(std::max(0, target - h.k0));
  std::vector<std::span<const u8>> segments;
  size_t pos = h.header_bytes;
  for (size_t i = 0; i < needed; ++i) {
    if (h.seg_len[i] > payload.size() - pos)
      return makeError(ErrorCode::kTruncated, name + " payload: level segment " + std::to_string(i) + " needs " +
                                                  std::to_string(h.seg_len[i]) + " bytes at offset " +
                                                  std::to_string(pos) + ", " + std::to_string(payload.size() - pos) +
                                                  " left");
    segments.push_back(payload.subspan(pos, h.seg_len[i]));
    pos += h.seg_len[i];
  }
  if (target >= bits && pos != payload.size())
    return makeError(ErrorCode::kMalformed,
                     name + " payload: " + std::to_string(payload.size() - pos) + " bytes after the last segment");
  return segments;
}

Status DecodeIo::begin() {
  if (next >= segments.size())
    return makeError(ErrorCode::kTruncated, std::string(codec) + " payload: segment missing");
  dec = std::make_unique<RangeDecoder>(segments[next++]);
  return Status::ok();
}

Status DecodeIo::end() {
  const bool bad = dec->overrun();
  dec.reset();
  if (bad)
    return makeError(ErrorCode::kMalformed, std::string(codec) + " payload: segment " + std::to_string(next - 1) +
                                                " ends before its symbols do");
  return Status::ok();
}

u8 consistentOrientation(const TriKey& t, u8 ot, const TriKey& u, u32 x, u32 y) {
  auto forward = [](const TriKey& k, u32 a, u32 b) {
    return (k[0] == a && k[1] == b) || (k[1] == a && k[2] == b) || (k[2] == a && k[0] == b);
  };
  const bool dir_t = forward(t, x, y) != bool(ot);
  return static_cast<u8>(forward(u, x, y) == dir_t);  // u must not run x->y where t does
}

EdgeThirds::EdgeThirds(const std::vector<TriKey>& keys) {
  u32 n = 0;
  for (const auto& k : keys) n = std::max(n, k[2] + 1);
  start.assign(n + 1, 0);
  for (const auto& k : keys) ++start[k[0] + 1], ++start[k[0] + 1], ++start[k[1] + 1];
  for (u32 v = 0; v < n; ++v) start[v + 1] += start[v];
  items.resize(start[n]);
  std::vector<u32> at(start.begin(), start.end() - 1);
  for (size_t t = 0; t < keys.size(); ++t) {
    const auto& k = keys[t];
    items[at[k[0]]++] = {k[1], k[2], u32(t)};
    items[at[k[0]]++] = {k[2], k[1], u32(t)};
    items[at[k[1]]++] = {k[2], k[0], u32(t)};
  }
  for (u32 v = 0; v < n; ++v) std::sort(items.begin() + start[v], items.begin() + start[v + 1]);
}

std::vector<Triangle> orientedTriangles(const std::vector<TriKey>& keys) {
  std::vector<u8> orient;
  breadthFirst(keys, orient, [&](size_t u, int t, u32 x, u32 y) -> u8 {
    return t < 0 ? 0 : consistentOrientation(keys[t], orient[t], keys[u], x, y);
  });
  std::vector<Triangle> out;
  out.reserve(keys.size());
  for (size_t t = 0; t < keys.size(); ++t)
    out.push_back(orient[t] ? Triangle{keys[t][0], keys[t][2], keys[t][1]}
                            : Triangle{keys[t][0], keys[t][1], keys[t][2]});
  return out;
}

}  // namespace scanpress::hierarchy
