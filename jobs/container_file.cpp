#include "jobs/container_file.h"

namespace scanpress {

Result<ContainerFile> ContainerFile::open(const std::string& path) {
  ContainerFile cf;
  SP_ASSIGN_OR_RETURN(auto file, RandomAccessFile::open(path));
  cf.file_ = std::move(file);
  std::vector<uint8_t> buf;
  const uint64_t size = cf.file_->size();
  if (size < kHeaderSize + kFooterSize)
    return makeError(ErrorCode::kTruncated, path + ": the file ends at byte " + std::to_string(size) +
                                                ", too short for a scanpress container (" +
                                                std::to_string(kHeaderSize + kFooterSize) + " bytes at least)");
  SP_RETURN_IF_ERROR(cf.file_->read(0, kHeaderSize, buf));
  SP_ASSIGN_OR_RETURN(const uint32_t header_size, headerSizeOf(buf, path));
  if (header_size > kHeaderSize) {
    if (header_size > size - kFooterSize)
      return makeError(ErrorCode::kTruncated, path + ": header at byte 12: the header's " +
                                                  std::to_string(header_size) + " bytes run past the file's end");
    SP_RETURN_IF_ERROR(cf.file_->read(0, header_size, buf));
  }
  SP_ASSIGN_OR_RETURN(cf.header_, parseHeader(buf, path));
  SP_RETURN_IF_ERROR(cf.file_->read(size - kFooterSize, kFooterSize, buf));
  Footer footer;
  SP_ASSIGN_OR_RETURN(footer, parseFooter(buf, size, path));
  SP_RETURN_IF_ERROR(cf.file_->read(footer.index_offset, footer.index_bytes, buf));
  SP_ASSIGN_OR_RETURN(cf.tiles_, parseIndex(buf, cf.header_, footer, path));
  return cf;
}

const TileEntry* ContainerFile::findTile(uint32_t tile_id) const {
  for (const auto& t : tiles_)
    if (t.tile_id == tile_id) return &t;
  return nullptr;
}

Result<std::span<const uint8_t>> ContainerFile::readPayload(const TileEntry& entry, std::vector<uint8_t>& chunk) const {
  SP_RETURN_IF_ERROR(file_->read(entry.offset, entry.chunk_bytes, chunk));
  return parseTileChunk(chunk, entry, path());
}

Result<QuantizedMesh> ContainerFile::decodeTile(const TileEntry& entry, std::optional<uint32_t> level, bool* complete,
                                                bool* own_attributes) const {
  std::vector<uint8_t> chunk;
  SP_ASSIGN_OR_RETURN(auto payload, readPayload(entry, chunk));
  return decodeTilePayload(header_, entry, payload, path(), level, complete, own_attributes);
}

Status ContainerFile::verifyChecksums() const {
  std::vector<uint8_t> chunk;
  for (const TileEntry& entry : tiles_) {
    auto payload = readPayload(entry, chunk);
    if (!payload.isOk()) return payload.status();
  }
  return Status::ok();
}

Result<std::vector<CodecLevel>> ContainerFile::tileLevels(const TileEntry& entry) const {
  const CodecInfo* codec = findCodec(entry.codec);
  if (!codec || !codec->levels) return std::vector<CodecLevel>{};
  std::vector<uint8_t> chunk;
  SP_ASSIGN_OR_RETURN(auto payload, readPayload(entry, chunk));
  return tilePayloadLevels(header_, entry, payload, path());
}

}  // namespace scanpress
