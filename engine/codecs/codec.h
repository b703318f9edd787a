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
  kKdtree = 2,
  kOctree = 3,
};

// What every tile of a container shares: the grid's bits and the attribute layout (from the container header).
struct TileContext {
  int bits = 16;
  AttributeLayout layout;
};

// A level of a progressive payload: decoding it needs the first `end_bytes` bytes of the payload. Level L has
// cells of 2^(bits-L) grid cells per axis; level == bits is the lossless mesh.
struct CodecLevel {
  uint32_t level = 0;
  uint64_t end_bytes = 0;
};

// Adds to total[L], for every level L < total.size(), the payload bytes a tile with these levels (as `levels`
// lists them, coarse to fine, non-empty) needs for L; a level coarser than the tile's first needs the first one's.
void addLevelBytes(std::span<const CodecLevel> levels, std::vector<uint64_t>& total);

struct CodecInfo {
  CodecId id;
  std::string_view name;
  uint16_t version;  // the version this build writes
  // Appends the encoded tile to `out`.
  Status (*encode)(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out);
  Result<QuantizedMesh> (*decode)(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload);
  // Progressive codecs only (nullptr otherwise): the levels a payload holds, and the mesh of one level from a
  // payload that may be cut after that level's end_bytes.
  Result<std::vector<CodecLevel>> (*levels)(const TileContext& ctx, uint16_t version,
                                            std::span<const uint8_t> payload) = nullptr;
  Result<QuantizedMesh> (*decode_level)(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                        uint32_t level) = nullptr;
  // Codecs whose decoder yields a different vertex count than the encoder was given (kdtree merges vertices
  // that share position and attributes): that count, read from a payload this build wrote. nullptr: the same.
  uint64_t (*payload_vertices)(std::span<const uint8_t> payload) = nullptr;
};

// The vertex count the codec's decoder will produce for `payload`, encoded from `mesh`.
uint64_t decodedVertexCount(const CodecInfo& codec, const QuantizedMesh& mesh, std::span<const uint8_t> payload);

std::span<const CodecInfo> allCodecs();
const CodecInfo* findCodec(CodecId id);
const CodecInfo* findCodec(std::string_view name);

// Checks a decoded tile: attribute arrays sized to the vertex count, indices in range, coordinates on the grid.
Status validateTile(const TileContext& ctx, const QuantizedMesh& mesh);

// `store`: the reference codec (store.cpp).
Status storeEncode(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out);
Result<QuantizedMesh> storeDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload);

// The progressive hierarchy codecs (kdtree, octree) merge vertices that share position and attributes: the
// vertex count their decoders yield, read from the payload's header.
uint64_t hierarchyPayloadVertices(std::span<const uint8_t> payload);

// `kdtree`: progressive lossless coding after Gandoin & Devillers (kdtree.cpp).
Status kdtreeEncode(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out);
Result<QuantizedMesh> kdtreeDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload);
Result<std::vector<CodecLevel>> kdtreeLevels(const TileContext& ctx, uint16_t version,
                                             std::span<const uint8_t> payload);
Result<QuantizedMesh> kdtreeDecodeLevel(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                        uint32_t level);

// `octree`: embedded mesh coding after Magnor & Girod (octree.cpp).
Status octreeEncode(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out);
Result<QuantizedMesh> octreeDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload);
Result<std::vector<CodecLevel>> octreeLevels(const TileContext& ctx, uint16_t version,
                                             std::span<const uint8_t> payload);
Result<QuantizedMesh> octreeDecodeLevel(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                        uint32_t level);

// What a progressive encoding (kdtree, octree) spent, in bits (ideal arithmetic-coding costs; the bytes add flushes and headers).
struct CodecStats {
  uint64_t points = 0;         // distinct coded vertices
  uint64_t triangles = 0;      // triangles coded (with multiplicity)
  uint64_t splits = 0;         // cell splits with both halves non-empty (vertex splits)
  uint64_t edge_expansions = 0;  // of those, coded as edge expansions
  double geometry_bits = 0;
  double connectivity_bits = 0;  // vertex splits, triangle orientation and multiplicity
  double attribute_bits = 0;
  uint64_t payload_bytes = 0;
};
Status kdtreeEncodeWithStats(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out,
                             CodecStats* stats);
// `contexts` false codes every symbol kind with one adaptive model (no contexts): for measuring what the contexts
// gain; such a payload is not decodable.
Status octreeEncodeWithStats(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out,
                             CodecStats* stats, bool contexts = true);

}  // namespace scanpress
