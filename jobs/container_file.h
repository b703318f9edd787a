// A container on disk: header, footer and index read on open; tiles read on demand with one pread each, so one
// tile can be decoded without reading the others.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "engine/container/container.h"
#include "jobs/file_io.h"

namespace scanpress {

class ContainerFile {
 public:
  static Result<ContainerFile> open(const std::string& path);
  const ContainerHeader& header() const { return header_; }
  const std::vector<TileEntry>& tiles() const { return tiles_; }
  uint64_t size() const { return file_->size(); }
  const std::string& path() const { return file_->path(); }
  const TileEntry* findTile(uint32_t tile_id) const;
  // Reads, verifies (both checksums) and decodes one tile (see decodeTilePayload).
  Result<QuantizedMesh> decodeTile(const TileEntry& entry, std::optional<uint32_t> level = std::nullopt,
                                   bool* complete = nullptr, bool* own_attributes = nullptr) const;
  // Reads every tile's chunk and checks both its checksums, without decoding: with the header, footer and
  // index (checked by open), every checksum of the container. What resume requires of an output before
  // skipping it.
  Status verifyChecksums() const;
  // The levels of a progressive tile (empty for single-rate codecs).
  Result<std::vector<CodecLevel>> tileLevels(const TileEntry& entry) const;
  // Reads a tile's chunk into `chunk` and returns its verified payload (a view into `chunk`).
  Result<std::span<const uint8_t>> readPayload(const TileEntry& entry, std::vector<uint8_t>& chunk) const;

 private:
  std::shared_ptr<RandomAccessFile> file_;
  ContainerHeader header_;
  std::vector<TileEntry> tiles_;
};

}  // namespace scanpress
