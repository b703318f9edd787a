// Codec `store` (id 1): the reference codec. Quantized positions and triangle indices packed tightly, plus
// normals (octahedral, the container's normal bits) and colors (8 bits per channel) when the scan has them.
// No prediction and no entropy coding: it is the baseline the real codecs are measured against, and the
// codec that proves the container end to end.
//
// Payload v1 (little-endian):
//   u32 vertex count V, u32 triangle count T
//   if V > 0: per axis x,y,z: u32 minimum coordinate, u8 bits b_a (enough for max - min)
//   bit stream (LSB first): V x (b_x + b_y + b_z) bits of (coordinate - minimum),
//   3T x bitsFor(V-1) bits of vertex indices, V x 2 x normal_bits bits of octahedral normals (if any),
//   V x 8 x channels bits of colors (if any), then per vertex each scalar channel's value at its type's width
//   (container version 2; float64 as two 32-bit words, low first); zero padding to the byte.
#include <algorithm>
#include <string>

#include "engine/codecs/codec.h"
#include "engine/entropy/bit_io.h"
#include "engine/io/bytes.h"

namespace scanpress {

Result<EncodedTile> storeEncode(const TileContext& ctx, const TileView& tile, const CodecOptions&) {
  const QuantizedMesh& mesh = tile.mesh;
  const size_t n = mesh.positions.size();
  if (n > UINT32_MAX || mesh.triangles.size() > UINT32_MAX)
    return makeError(ErrorCode::kLimitExceeded, "tile has more than 2^32-1 vertices or triangles");
  EncodedTile result;
  result.decoded = summarize(mesh);
  std::vector<uint8_t>& out = result.payload;
  ByteWriter w(out);
  w.u32(static_cast<uint32_t>(n));
  w.u32(static_cast<uint32_t>(mesh.triangles.size()));
  if (n == 0) return result;
  const Vec3u& lo = result.decoded.lo;
  const Vec3u& hi = result.decoded.hi;
  int axis_bits[3];
  for (int a = 0; a < 3; ++a) axis_bits[a] = bitsFor(hi[a] - lo[a]);
  // A tile below the codec's floor (FORMAT.md; a dense lattice spends few bits per vertex) spends more coordinate
  // bits than its range needs, up to the grid's: the decoder accepts any width within the grid.
  const int index_bits = bitsFor(n - 1);
  int scalar_bits = 0;
  for (const ScalarChannel& c : ctx.layout.scalars) scalar_bits += 8 * scalarTypeBytes(c.type);
  const int extra_bits = 2 * ctx.layout.normal_bits + 8 * ctx.layout.color_channels + scalar_bits;
  const uint64_t need = findCodec(CodecId::kStore)->floor.minPayloadBytes(ctx.layout, n, mesh.triangles.size());
  auto payloadBytes = [&] {
    const uint64_t bits = uint64_t(axis_bits[0] + axis_bits[1] + axis_bits[2] + extra_bits) * n +
                          uint64_t(mesh.triangles.size()) * 3 * index_bits;
    return out.size() + 15 + (bits + 7) / 8;
  };
  while (payloadBytes() < need) {
    int* a = std::min_element(axis_bits, axis_bits + 3);
    if (*a >= ctx.bits) break;  // the writer refuses the tile, as it does every tile below its floor
    ++*a;
  }
  for (int a = 0; a < 3; ++a) {
    w.u32(lo[a]);
    w.u8(static_cast<uint8_t>(axis_bits[a]));
  }
  BitWriter bw(out);
  for (const auto& p : mesh.positions)
    for (int a = 0; a < 3; ++a) bw.put(p[a] - lo[a], axis_bits[a]);
  for (const auto& t : mesh.triangles)
    for (uint32_t v : t) bw.put(v, index_bits);
  if (ctx.layout.hasNormals())
    for (const auto& e : mesh.normals) bw.put(e[0], ctx.layout.normal_bits), bw.put(e[1], ctx.layout.normal_bits);
  if (ctx.layout.hasColors())
    for (const auto& c : mesh.colors)
      for (int k = 0; k < ctx.layout.color_channels; ++k) bw.put(c[k], 8);
  // Scalar channels (container v2): per vertex, each channel's value at its type's width.
  const size_t stride = size_t(ctx.layout.scalarStride());
  for (size_t v = 0; v < n; ++v) {
    const uint32_t* w = mesh.scalars.data() + v * stride;
    for (const ScalarChannel& c : ctx.layout.scalars) {
      if (c.type == ScalarType::kFloat64) bw.put(w[0], 32), bw.put(w[1], 32), w += 2;
      else bw.put(*w++, 8 * scalarTypeBytes(c.type));
    }
  }
  bw.flush();
  return result;
}

Result<QuantizedMesh> storeDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                  const DecodeLimits& limits) {
  if (version != 1)
    return makeError(ErrorCode::kUnknownVersion,
                     "store codec version " + std::to_string(version) + " is not known to this build (knows 1)");
  ByteReader r(payload, "store payload");
  uint32_t n = 0, t = 0;
  SP_RETURN_IF_ERROR(r.u32(n));
  SP_RETURN_IF_ERROR(r.u32(t));
  SP_RETURN_IF_ERROR(checkLimits("store payload", n, t, limits));
  QuantizedMesh mesh;
  if (n == 0) {
    if (t != 0) return r.error(ErrorCode::kMalformed, "triangles without vertices");
    return mesh;
  }
  Vec3u lo;
  int axis_bits[3];
  for (int a = 0; a < 3; ++a) {
    uint8_t b = 0;
    SP_RETURN_IF_ERROR(r.u32(lo[a]));
    SP_RETURN_IF_ERROR(r.u8(b));
    // Decoded coordinates are lo + (< 2^b) < 2^25: no overflow; validateTile checks they lie on the grid.
    if (b > ctx.bits || lo[a] > (1u << ctx.bits) - 1)
      return r.error(ErrorCode::kMalformed, "axis range exceeds the grid");
    axis_bits[a] = b;
  }
  const int index_bits = bitsFor(uint64_t(n) - 1);
  uint64_t scalar_bits = 0;
  for (const ScalarChannel& c : ctx.layout.scalars) scalar_bits += 8u * uint64_t(scalarTypeBytes(c.type));
  const uint64_t per_vertex = uint64_t(axis_bits[0]) + axis_bits[1] + axis_bits[2] + 2u * ctx.layout.normal_bits +
                              8u * ctx.layout.color_channels + scalar_bits;
  const uint64_t need_bits = per_vertex * n + uint64_t(t) * 3 * index_bits;
  if ((need_bits + 7) / 8 != r.remaining())
    return r.error(ErrorCode::kMalformed, "payload holds " + std::to_string(r.remaining()) + " bytes, counts need " +
                                              std::to_string((need_bits + 7) / 8));
  std::span<const uint8_t> rest;
  SP_RETURN_IF_ERROR(r.bytes(r.remaining(), rest));
  BitReader br(rest);
  mesh.positions.resize(n);
  for (auto& p : mesh.positions)
    for (int a = 0; a < 3; ++a) p[a] = lo[a] + br.get(axis_bits[a]);
  mesh.triangles.resize(t);
  for (auto& tri : mesh.triangles)
    for (auto& v : tri) v = br.get(index_bits);
  if (ctx.layout.hasNormals()) {
    mesh.normals.resize(n);
    for (auto& e : mesh.normals)
      e[0] = static_cast<uint16_t>(br.get(ctx.layout.normal_bits)),
      e[1] = static_cast<uint16_t>(br.get(ctx.layout.normal_bits));
  }
  if (ctx.layout.hasColors()) {
    mesh.colors.resize(n);
    for (auto& c : mesh.colors) {
      c = {0, 0, 0, 255};
      for (int k = 0; k < ctx.layout.color_channels; ++k) c[k] = static_cast<uint8_t>(br.get(8));
    }
  }
  mesh.scalars.resize(size_t(n) * size_t(ctx.layout.scalarStride()));
  for (size_t v = 0, i = 0; v < n; ++v)
    for (const ScalarChannel& c : ctx.layout.scalars) {
      if (c.type == ScalarType::kFloat64) mesh.scalars[i] = br.get(32), mesh.scalars[i + 1] = br.get(32), i += 2;
      else mesh.scalars[i++] = br.get(8 * scalarTypeBytes(c.type));
    }
  if (br.overrun()) return makeError(ErrorCode::kTruncated, "store payload ends inside the bit stream");
  SP_RETURN_IF_ERROR(validateTile(ctx, mesh).withContext("store payload"));
  return mesh;
}

}  // namespace scanpress
