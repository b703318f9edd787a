// Container format v1, v2 and v3 (.spz): the byte-level layout is specified in FORMAT.md next to this file. v2 is v1
// with a scalar-channel table after the fixed header; v3's table adds each channel's bits (quantized texture
// coordinates) and the material names. A writer writes the lowest version that holds its header.
//
//   header | tile chunk | tile chunk | ... | tile index | footer (magic last)
//
// Tiles decode independently; a reader needs the header, the footer, the index and one chunk to decode one
// tile. Everything is covered by CRC-32C checksums. This module only formats and parses bytes: the file I/O is
// the caller's (jobs/), through ByteSink for writing and spans for reading.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "engine/codecs/codec.h"
#include "engine/mesh.h"
#include "engine/quantize.h"
#include "engine/status.h"

namespace scanpress {

constexpr uint32_t kContainerVersion = 1;
constexpr uint32_t kContainerVersionScalars = 2;    // v1 plus the scalar channels' table after the fixed header
constexpr uint32_t kContainerVersionMaterials = 3;  // v2's table with channel bits and the material names
constexpr size_t kHeaderSize = 80;                  // the fixed header (the whole header of v1)
constexpr size_t kMaxMaterialBytes = 1024;          // of each material name
constexpr size_t kMaxHeaderSize = kHeaderSize + 1 + 255 * (3 + 255) + 3 * (2 + kMaxMaterialBytes) + 4;
constexpr size_t kFooterSize = 32;
constexpr size_t kChunkHeaderSize = 36;
constexpr size_t kIndexEntrySize = 56;
constexpr uint32_t kMaxTiles = 1u << 24;

struct ContainerHeader {
  uint32_t version = kContainerVersion;  // the lowest that holds the header (ContainerWriter::begin)
  uint32_t header_size = kHeaderSize;    // where the first chunk starts
  Grid grid;
  AttributeLayout layout;
  uint32_t tile_count = 0;
  uint64_t vertices = 0;  // sum over tiles (border vertices count once per tile that holds them)
  uint64_t faces = 0;
  // A partial container (`encode --subset i/N`): the tiles t with t % N == i of the whole tiling, for `merge`.
  // 0 and 0: a whole container.
  uint16_t subset_index = 0, subset_count = 0;
  // Written back to decoded OBJ and PLY files (v3).
  MaterialNames materials;
  bool partial() const { return subset_count != 0; }
};

// A material name the header can hold: at most kMaxMaterialBytes of well-formed UTF-8 without control characters.
bool validMaterialName(const std::string& name);

struct TileEntry {
  uint32_t tile_id = 0;
  CodecId codec = CodecId::kStore;
  uint16_t codec_version = 0;
  uint64_t offset = 0;       // of the chunk (its header) from the start of the file
  uint64_t chunk_bytes = 0;  // chunk header + payload
  uint32_t vertices = 0;
  uint32_t faces = 0;
  Vec3u lo{0, 0, 0};  // quantized bounds of the tile's vertices (inclusive); lo > hi when the tile is empty
  Vec3u hi{0, 0, 0};
};

struct Footer {
  uint64_t index_offset = 0;
  uint64_t index_bytes = 0;
  uint32_t version = kContainerVersion;  // the header's
};

// The layout's scalar channels can be written: at most 255, valid types and names, no name twice.
Status checkScalarChannels(const AttributeLayout& layout);

// Where the writer puts bytes: appended in order, plus one rewrite of the header at the end.
class ByteSink {
 public:
  virtual ~ByteSink() = default;
  virtual Status append(std::span<const uint8_t> bytes) = 0;
  virtual Status writeAt(uint64_t offset, std::span<const uint8_t> bytes) = 0;
};

// In memory (encodeContainer, tests).
class VectorSink : public ByteSink {
 public:
  explicit VectorSink(std::vector<uint8_t>& out) : out_(out) {}
  Status append(std::span<const uint8_t> b) override {
    out_.insert(out_.end(), b.begin(), b.end());
    return Status::ok();
  }
  Status writeAt(uint64_t offset, std::span<const uint8_t> b) override {
    if (offset + b.size() > out_.size()) return makeError(ErrorCode::kInternal, "writeAt past the end");
    std::copy(b.begin(), b.end(), out_.begin() + static_cast<ptrdiff_t>(offset));
    return Status::ok();
  }

 private:
  std::vector<uint8_t>& out_;
};

// Writes a container: begin(), addTile() per tile in the order they should appear, finish(). Totals in the
// header are filled in by finish(). Not thread-safe: one serial writer per output.
class ContainerWriter {
 public:
  ContainerWriter(ByteSink& sink, const Grid& grid, const AttributeLayout& layout);
  Status begin();
  // `decoded` is what the codec's decoder yields from `payload` (EncodedTile::decoded): the index records it.
  // Fails with kInternal if the counts are below the codec's payload floor (the reader would refuse the file).
  // `version`: the payload's codec version (EncodedTile::version; 0: the one this build writes; a merge of older
  // parts passes theirs). No default: a kdtree tile without creases is version 3.
  Status addTile(uint32_t tile_id, const CodecInfo& codec, const TileSummary& decoded,
                 std::span<const uint8_t> payload, uint16_t version);
  // A tile as its encoder returned it (its payload's version included).
  Status addTile(uint32_t tile_id, const CodecInfo& codec, const EncodedTile& tile) {
    return addTile(tile_id, codec, tile.decoded, tile.payload, tile.version);
  }
  Status finish();
  // Marks the container as subset `index` of `count` (before finish()).
  void setSubset(uint16_t index, uint16_t count) { header_.subset_index = index, header_.subset_count = count; }
  // The material names to keep (ContainerHeader's): before begin() (finish() rewrites the header in place, so its
  // size is fixed then); kInternal after.
  Status setMaterial(MaterialNames names) {
    if (begun_) return makeError(ErrorCode::kInternal, "the container's material names are set after its header");
    header_.materials = std::move(names);
    return Status::ok();
  }
  uint64_t bytesWritten() const { return offset_; }
  const ContainerHeader& header() const { return header_; }

 private:
  ByteSink& sink_;
  ContainerHeader header_;
  std::vector<TileEntry> entries_;
  uint64_t offset_ = 0;
  bool begun_ = false;
};

std::vector<uint8_t> serializeHeader(const ContainerHeader& header);

// Parsers. `what` names the file in error messages. Offsets in messages are absolute file offsets.
// The header's size from its first kHeaderSize bytes (magic, version and fixed part's checksum checked): a reader
// reads that many bytes for parseHeader.
Result<uint32_t> headerSizeOf(std::span<const uint8_t> fixed, const std::string& what);
// The whole header (`bytes` may run past it).
Result<ContainerHeader> parseHeader(std::span<const uint8_t> bytes, const std::string& what);
Result<Footer> parseFooter(std::span<const uint8_t> last_bytes, uint64_t file_size, const std::string& what);
Result<std::vector<TileEntry>> parseIndex(std::span<const uint8_t> bytes, const ContainerHeader& header,
                                          const Footer& footer, const std::string& what);

// Checks a tile chunk (header fields against the index entry, both checksums) and returns its payload.
Result<std::span<const uint8_t>> parseTileChunk(std::span<const uint8_t> chunk, const TileEntry& entry,
                                                const std::string& what);

// The index entry's counts as hard limits for the tile's decoder.
DecodeLimits limitsOf(const TileEntry& entry);

// Decodes a verified payload with the entry's codec, within the limits of the entry's counts (a payload that
// claims more is kMalformed before anything is allocated), and checks that the complete tile has exactly the
// index's counts. With a `level` (progressive codecs only; kInvalidArgument otherwise) the tile's mesh at that
// level (see CodecLevel); `complete` says whether that was the tile's last level with its vertices as given (false
// for a payload that welds by position, CodecInfo::keepsAttributes: such tiles weld by position); `own_attributes`
// whether the mesh's normals and colors are the tile's own (CodecInfo::showsOwnAttributes: a complete tile of a
// codec that keeps them, or levels coded with them) rather than derived from its triangles. Running out of memory
// while decoding is a data error (kMalformed): only a hostile payload can ask for more than its index allows.
Result<QuantizedMesh> decodeTilePayload(const ContainerHeader& header, const TileEntry& entry,
                                        std::span<const uint8_t> payload, const std::string& what,
                                        std::optional<uint32_t> level = std::nullopt, bool* complete = nullptr,
                                        bool* own_attributes = nullptr);
// The levels of a progressive tile's payload (empty for single-rate codecs).
Result<std::vector<CodecLevel>> tilePayloadLevels(const ContainerHeader& header, const TileEntry& entry,
                                                  std::span<const uint8_t> payload, const std::string& what);

// Whole-container helpers for in-memory buffers (tests, and small files).
Result<std::vector<uint8_t>> encodeContainer(const Grid& grid, const AttributeLayout& layout, const CodecInfo& codec,
                                             std::span<const QuantizedMesh> tiles, const CodecOptions& options = {});
struct ParsedContainer {
  ContainerHeader header;
  std::vector<TileEntry> tiles;
};
Result<ParsedContainer> parseContainer(std::span<const uint8_t> file, const std::string& what);

}  // namespace scanpress
