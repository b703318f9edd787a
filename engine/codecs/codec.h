// Tile codecs: pure functions from a quantized tile mesh to bytes and back.
//
// Codec ids are written to disk and are frozen: never renumber or reuse one. A codec's version is stored with
// every tile it writes; decoders accept every version they know and fail with kUnknownVersion otherwise.
// Decoders treat their input as hostile: they never read outside the payload, check counts against the bytes
// that remain before allocating, and validate what they return (indices < vertex count, coordinates on the grid).
#pragma once

#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

#include "engine/mesh.h"
#include "engine/status.h"

namespace scanpress {

enum class CodecId : uint16_t {
  kStore = 1,
};

// What every tile of a container shares: the grid's bits and the attribute layout (from the container header).
struct TileContext {
  int bits = 16;
  AttributeLayout layout;
};

struct CodecInfo {
  CodecId id;
  std::string_view name;
  uint16_t version;  // the version this build writes
  // Appends the encoded tile to `out`.
  Status (*encode)(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out);
  Result<QuantizedMesh> (*decode)(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload);
};

std::span<const CodecInfo> allCodecs();
const CodecInfo* findCodec(CodecId id);
const CodecInfo* findCodec(std::string_view name);

// Checks a decoded tile: attribute arrays sized to the vertex count, indices in range, coordinates on the grid.
Status validateTile(const TileContext& ctx, const QuantizedMesh& mesh);

// `store`: the reference codec (store.cpp).
Status storeEncode(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out);
Result<QuantizedMesh> storeDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload);

}  // namespace scanpress
