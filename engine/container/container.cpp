#include "engine/container/container.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <new>
#include <string>

#include "engine/io/bytes.h"
#include "engine/io/crc32c.h"

namespace scanpress {
namespace {

constexpr uint8_t kHeaderMagic[8] = {0x89, 'S', 'P', 'Z', '\r', '\n', 0x1A, '\n'};
constexpr uint8_t kFooterMagic[8] = {0x1A, 'S', 'P', 'Z', 'E', 'O', 'F', '\n'};
constexpr uint32_t kChunkMagic = 0x454C4954;  // "TILE" little-endian
constexpr uint32_t kIndexMagic = 0x58444954;  // "TIDX"

std::string hex32(uint32_t v) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "%08x", v);
  return buf;
}

Status checkCrc(uint32_t stored, std::span<const uint8_t> covered, const std::string& what_part) {
  const uint32_t actual = crc32c(covered);
  if (stored != actual)
    return makeError(ErrorCode::kChecksum,
                     what_part + ": checksum mismatch (stored " + hex32(stored) + ", computed " + hex32(actual) + ")");
  return Status::ok();
}

std::vector<uint8_t> chunkHeader(const TileEntry& e, std::span<const uint8_t> payload) {
  std::vector<uint8_t> out;
  ByteWriter w(out);
  w.u32(kChunkMagic);
  w.u32(e.tile_id);
  w.u16(static_cast<uint16_t>(e.codec));
  w.u16(e.codec_version);
  w.u32(e.vertices);
  w.u32(e.faces);
  w.u64(payload.size());
  w.u32(crc32c(payload));
  w.u32(crc32c(out));
  return out;
}

}  // namespace

namespace {
// The lowest version that holds the header: v3 for quantized channels or material names, v2 for scalar channels.
uint32_t versionFor(const ContainerHeader& h) {
  const bool quantized =
      std::any_of(h.layout.scalars.begin(), h.layout.scalars.end(), [](const ScalarChannel& c) { return c.bits; });
  if (quantized || !h.materials.empty()) return kContainerVersionMaterials;
  return h.layout.hasScalars() ? kContainerVersionScalars : kContainerVersion;
}

// The table after the fixed header (none in v1). v2: u8 count; per channel u8 type, u8 name length, the name.
// v3: the same with u8 bits after each name, then u16 length and bytes of the material library, of the material and
// of the texture file. CRC-32C of it last.
std::vector<uint8_t> headerTable(const ContainerHeader& h, uint32_t version) {
  std::vector<uint8_t> out;
  if (version == kContainerVersion) return out;
  ByteWriter w(out);
  w.u8(static_cast<uint8_t>(h.layout.scalars.size()));
  for (const ScalarChannel& c : h.layout.scalars) {
    w.u8(static_cast<uint8_t>(c.type));
    w.u8(static_cast<uint8_t>(c.name.size()));
    for (char ch : c.name) w.u8(static_cast<uint8_t>(ch));
    if (version >= kContainerVersionMaterials) w.u8(c.bits);
  }
  if (version >= kContainerVersionMaterials)
    for (const std::string* s : {&h.materials.library, &h.materials.material, &h.materials.texture}) {
      w.u16(static_cast<uint16_t>(s->size()));
      for (char ch : *s) w.u8(static_cast<uint8_t>(ch));
    }
  w.u32(crc32c(out));
  return out;
}
}  // namespace

bool validMaterialName(const std::string& name) {
  if (name.size() > kMaxMaterialBytes) return false;
  // Well-formed UTF-8 (no overlong forms, surrogates or code points above U+10FFFF) without control characters.
  for (size_t i = 0; i < name.size();) {
    const auto b = [&](size_t k) { return static_cast<unsigned char>(name[k]); };
    const unsigned char c = b(i);
    if (c < 0x80) {
      if (c < 0x20 || c == 0x7F) return false;
      ++i;
      continue;
    }
    const size_t n = c >= 0xC2 && c <= 0xDF ? 2 : c >= 0xE0 && c <= 0xEF ? 3 : c >= 0xF0 && c <= 0xF4 ? 4 : 0;
    if (n == 0 || i + n > name.size()) return false;
    for (size_t k = 1; k < n; ++k)
      if ((b(i + k) & 0xC0) != 0x80) return false;
    if ((c == 0xE0 && b(i + 1) < 0xA0) || (c == 0xED && b(i + 1) > 0x9F) || (c == 0xF0 && b(i + 1) < 0x90) ||
        (c == 0xF4 && b(i + 1) > 0x8F))
      return false;
    i += n;
  }
  return true;
}

Status checkScalarChannels(const AttributeLayout& layout) {
  if (layout.scalars.size() > 255) return makeError(ErrorCode::kInvalidArgument, "more than 255 scalar channels");
  for (const ScalarChannel& c : layout.scalars) {
    if (!validScalarType(static_cast<uint8_t>(c.type)))
      return makeError(ErrorCode::kInvalidArgument, "scalar channel '" + c.name + "' has no valid type");
    if (!validScalarName(c.name))
      return makeError(ErrorCode::kInvalidArgument,
                       "scalar channel name '" + c.name + "': 1 to 255 printable ASCII bytes without spaces");
    if (c.bits > kMaxScalarBits || (c.bits && !isFloatScalar(c.type)))
      return makeError(ErrorCode::kInvalidArgument, "scalar channel '" + c.name + "': " + std::to_string(c.bits) +
                                                        " bits (a float channel's 1.." +
                                                        std::to_string(kMaxScalarBits) + ", or 0)");
  }
  for (size_t i = 0; i < layout.scalars.size(); ++i)
    for (size_t j = 0; j < i; ++j)
      if (layout.scalars[i].name == layout.scalars[j].name)
        return makeError(ErrorCode::kInvalidArgument, "scalar channel '" + layout.scalars[i].name + "' appears twice");
  return Status::ok();
}

std::vector<uint8_t> serializeHeader(const ContainerHeader& h) {
  const uint32_t version = versionFor(h);
  const std::vector<uint8_t> table = headerTable(h, version);
  std::vector<uint8_t> out;
  out.reserve(kHeaderSize);
  ByteWriter w(out);
  w.bytes(kHeaderMagic);
  w.u32(version);
  w.u32(static_cast<uint32_t>(kHeaderSize + table.size()));
  for (double c : h.grid.origin) w.f64(c);
  w.f64(h.grid.cell);
  w.u8(static_cast<uint8_t>(h.grid.bits));
  w.u8(h.layout.normal_bits);
  w.u8(h.layout.color_channels);
  w.u8(h.layout.color_bits == 8 ? 0 : h.layout.color_bits);  // 0: 8 bits (the byte was reserved, 0)
  w.u32(h.tile_count);
  w.u64(h.vertices);
  w.u64(h.faces);
  w.u16(h.subset_index);
  w.u16(h.subset_count);
  w.u32(crc32c(out));
  for (uint8_t b : table) w.u8(b);
  return out;
}

ContainerWriter::ContainerWriter(ByteSink& sink, const Grid& grid, const AttributeLayout& layout) : sink_(sink) {
  header_.grid = grid;
  header_.layout = layout;
}

Status ContainerWriter::begin() {
  if (header_.layout.color_bits < 1 || header_.layout.color_bits > 8)
    return makeError(ErrorCode::kInvalidArgument, "color bits must be in [1, 8]");
  if (!header_.layout.hasColors()) header_.layout.color_bits = 8;  // byte 51 is 0 without colors
  SP_RETURN_IF_ERROR(checkScalarChannels(header_.layout));
  for (const std::string* s : {&header_.materials.library, &header_.materials.material, &header_.materials.texture})
    if (!validMaterialName(*s))
      return makeError(ErrorCode::kInvalidArgument, "material name of " + std::to_string(s->size()) +
                                                        " bytes: at most " + std::to_string(kMaxMaterialBytes) +
                                                        " of UTF-8 without control characters");
  header_.version = versionFor(header_);
  const auto bytes = serializeHeader(header_);
  header_.header_size = static_cast<uint32_t>(bytes.size());
  begun_ = true;
  SP_RETURN_IF_ERROR(sink_.append(bytes));
  offset_ = bytes.size();
  return Status::ok();
}

Status ContainerWriter::addTile(uint32_t tile_id, const CodecInfo& codec, const TileSummary& decoded,
                                std::span<const uint8_t> payload, uint16_t version) {
  if (entries_.size() >= kMaxTiles) return makeError(ErrorCode::kLimitExceeded, "too many tiles");
  if (version > codec.version)
    return makeError(ErrorCode::kInternal, "tile " + std::to_string(tile_id) + ": " + std::string(codec.name) +
                                               " version " + std::to_string(version) + " is newer than this build's");
  if (!codec.floor.admits(header_.layout, decoded.vertices, decoded.faces, payload.size()))
    return makeError(ErrorCode::kInternal, "tile " + std::to_string(tile_id) + ": " + std::string(codec.name) +
                                               " wrote " + std::to_string(payload.size()) + " bytes for " +
                                               std::to_string(decoded.vertices) + " vertices and " +
                                               std::to_string(decoded.faces) + " faces, below its payload floor");
  TileEntry e;
  e.tile_id = tile_id;
  e.codec = codec.id;
  e.codec_version = version ? version : codec.version;
  e.offset = offset_;
  e.vertices = decoded.vertices;
  e.faces = decoded.faces;
  e.lo = decoded.lo;
  e.hi = decoded.hi;
  const auto head = chunkHeader(e, payload);
  e.chunk_bytes = head.size() + payload.size();
  SP_RETURN_IF_ERROR(sink_.append(head));
  SP_RETURN_IF_ERROR(sink_.append(payload));
  offset_ += e.chunk_bytes;
  header_.vertices += e.vertices;
  header_.faces += e.faces;
  entries_.push_back(e);
  return Status::ok();
}

Status ContainerWriter::finish() {
  std::vector<uint8_t> index;
  ByteWriter w(index);
  w.u32(kIndexMagic);
  w.u32(static_cast<uint32_t>(entries_.size()));
  for (const auto& e : entries_) {
    w.u32(e.tile_id);
    w.u16(static_cast<uint16_t>(e.codec));
    w.u16(e.codec_version);
    w.u64(e.offset);
    w.u64(e.chunk_bytes);
    w.u32(e.vertices);
    w.u32(e.faces);
    for (uint32_t c : e.lo) w.u32(c);
    for (uint32_t c : e.hi) w.u32(c);
  }
  w.u32(crc32c(index));
  std::vector<uint8_t> footer;
  ByteWriter f(footer);
  f.u64(offset_);
  f.u64(index.size());
  f.u32(header_.version);
  f.u32(crc32c(footer));
  f.bytes(kFooterMagic);
  SP_RETURN_IF_ERROR(sink_.append(index));
  SP_RETURN_IF_ERROR(sink_.append(footer));
  offset_ += index.size() + footer.size();
  header_.tile_count = static_cast<uint32_t>(entries_.size());
  return sink_.writeAt(0, serializeHeader(header_));
}

Result<uint32_t> headerSizeOf(std::span<const uint8_t> bytes, const std::string& what) {
  const std::string where = what + ": header";
  if (bytes.size() < kHeaderSize)
    return makeError(ErrorCode::kTruncated, where + ": the file ends at byte " + std::to_string(bytes.size()) +
                                                ", a container header needs " + std::to_string(kHeaderSize) + " bytes");
  if (std::memcmp(bytes.data(), kHeaderMagic, 8) != 0)
    return makeError(ErrorCode::kMalformed, where + " at byte 0: not a scanpress container (bad magic)");
  ByteReader r(bytes.first(kHeaderSize), where);
  std::span<const uint8_t> magic;
  SP_RETURN_IF_ERROR(r.bytes(8, magic));
  uint32_t version = 0, header_size = 0;
  SP_RETURN_IF_ERROR(r.u32(version));
  if (version < kContainerVersion || version > kContainerVersionMaterials)
    return makeError(ErrorCode::kUnknownVersion, where + " at byte 8: container format version " +
                                                     std::to_string(version) + " is not known to this build (knows " +
                                                     std::to_string(kContainerVersion) + " to " +
                                                     std::to_string(kContainerVersionMaterials) + ")");
  SP_RETURN_IF_ERROR(r.u32(header_size));
  uint32_t stored_crc = 0;
  std::memcpy(&stored_crc, bytes.data() + kHeaderSize - 4, 4);
  SP_RETURN_IF_ERROR(checkCrc(stored_crc, bytes.first(kHeaderSize - 4),
                              where + " at byte " + std::to_string(kHeaderSize - 4)));
  // v1: exactly the fixed header; v2: a table of at least one channel (7 bytes) and at most 255; v3: a table of
  // no channel and three empty names (11 bytes) or more.
  const size_t least = version == kContainerVersion          ? kHeaderSize
                       : version == kContainerVersionScalars ? kHeaderSize + 7
                                                             : kHeaderSize + 11;
  if (version == kContainerVersion ? header_size != kHeaderSize : header_size < least || header_size > kMaxHeaderSize)
    return makeError(ErrorCode::kMalformed, where + " at byte 12: header size " + std::to_string(header_size) +
                                                " for container format version " + std::to_string(version));
  return header_size;
}

Result<ContainerHeader> parseHeader(std::span<const uint8_t> bytes, const std::string& what) {
  const std::string where = what + ": header";
  SP_ASSIGN_OR_RETURN(const uint32_t header_size, headerSizeOf(bytes, what));
  if (bytes.size() < header_size)
    return makeError(ErrorCode::kTruncated, where + ": the file ends at byte " + std::to_string(bytes.size()) +
                                                ", its header needs " + std::to_string(header_size) + " bytes");
  ByteReader r(bytes.first(kHeaderSize), where);
  std::span<const uint8_t> magic;
  SP_RETURN_IF_ERROR(r.bytes(8, magic));
  ContainerHeader h;
  h.header_size = header_size;
  uint32_t size_field = 0;
  SP_RETURN_IF_ERROR(r.u32(h.version));
  SP_RETURN_IF_ERROR(r.u32(size_field));
  for (double& c : h.grid.origin) SP_RETURN_IF_ERROR(r.f64(c));
  SP_RETURN_IF_ERROR(r.f64(h.grid.cell));
  uint8_t bits = 0, reserved = 0;
  SP_RETURN_IF_ERROR(r.u8(bits));
  SP_RETURN_IF_ERROR(r.u8(h.layout.normal_bits));
  SP_RETURN_IF_ERROR(r.u8(h.layout.color_channels));
  SP_RETURN_IF_ERROR(r.u8(reserved));
  SP_RETURN_IF_ERROR(r.u32(h.tile_count));
  SP_RETURN_IF_ERROR(r.u64(h.vertices));
  SP_RETURN_IF_ERROR(r.u64(h.faces));
  SP_RETURN_IF_ERROR(r.u16(h.subset_index));
  SP_RETURN_IF_ERROR(r.u16(h.subset_count));
  h.grid.bits = bits;
  if (bits < kMinGridBits || bits > kMaxGridBits)
    return makeError(ErrorCode::kMalformed, where + " at byte 48: grid bits " + std::to_string(bits));
  if (!(h.grid.cell > 0.0) || !std::isfinite(h.grid.cell) || !std::isfinite(h.grid.origin[0]) ||
      !std::isfinite(h.grid.origin[1]) || !std::isfinite(h.grid.origin[2]))
    return makeError(ErrorCode::kMalformed, where + " at byte 16: grid origin or cell not finite and positive");
  if (h.layout.normal_bits != 0 && (h.layout.normal_bits < 4 || h.layout.normal_bits > 16))
    return makeError(ErrorCode::kMalformed, where + " at byte 49: normal bits " + std::to_string(h.layout.normal_bits));
  if (h.layout.color_channels != 0 && h.layout.color_channels != 3 && h.layout.color_channels != 4)
    return makeError(ErrorCode::kMalformed,
                     where + " at byte 50: color channels " + std::to_string(h.layout.color_channels));
  // Byte 51: color bits, 0 meaning 8 (files before this field wrote 0).
  if (reserved > 7 || (reserved != 0 && h.layout.color_channels == 0))
    return makeError(ErrorCode::kMalformed, where + " at byte 51: color bits " + std::to_string(reserved) +
                                                (h.layout.color_channels ? "" : " without colors"));
  h.layout.color_bits = reserved == 0 ? 8 : reserved;
  if (h.subset_count == 1 || h.subset_index >= std::max<uint16_t>(h.subset_count, 1))
    return makeError(ErrorCode::kMalformed, where + " at byte 72: subset " + std::to_string(h.subset_index) + " of " +
                                                std::to_string(h.subset_count));
  if (h.tile_count > kMaxTiles)
    return makeError(ErrorCode::kLimitExceeded, where + " at byte 52: " + std::to_string(h.tile_count) + " tiles");
  if (h.version >= kContainerVersionScalars) {
    const bool v3 = h.version >= kContainerVersionMaterials;
    const auto table = bytes.subspan(kHeaderSize, header_size - kHeaderSize);
    uint32_t table_crc = 0;
    std::memcpy(&table_crc, table.data() + table.size() - 4, 4);
    SP_RETURN_IF_ERROR(checkCrc(table_crc, table.first(table.size() - 4),
                                where + " at byte " + std::to_string(header_size - 4)));
    ByteReader t(table.first(table.size() - 4), where + " scalar channels", kHeaderSize);
    uint8_t count = 0;
    SP_RETURN_IF_ERROR(t.u8(count));
    if (count == 0 && !v3) return t.error(ErrorCode::kMalformed, "a version 2 header with no scalar channel");
    for (uint8_t i = 0; i < count; ++i) {
      uint8_t type = 0, length = 0;
      SP_RETURN_IF_ERROR(t.u8(type));
      if (!validScalarType(type))
        return t.error(ErrorCode::kMalformed, "scalar channel " + std::to_string(i) + ": type " + std::to_string(type));
      SP_RETURN_IF_ERROR(t.u8(length));
      std::span<const uint8_t> name;
      SP_RETURN_IF_ERROR(t.bytes(length, name));
      uint8_t channel_bits = 0;
      if (v3) SP_RETURN_IF_ERROR(t.u8(channel_bits));
      h.layout.scalars.push_back({std::string(name.begin(), name.end()), static_cast<ScalarType>(type), channel_bits});
    }
    if (v3)
      for (std::string* s : {&h.materials.library, &h.materials.material, &h.materials.texture}) {
        uint16_t length = 0;
        SP_RETURN_IF_ERROR(t.u16(length));
        std::span<const uint8_t> text;
        SP_RETURN_IF_ERROR(t.bytes(length, text));
        s->assign(text.begin(), text.end());
        if (!validMaterialName(*s))
          return t.error(ErrorCode::kMalformed, "material name of " + std::to_string(length) + " bytes");
      }
    if (t.remaining() != 0) return t.error(ErrorCode::kMalformed, "bytes after the scalar channels");
    if (Status s = checkScalarChannels(h.layout); !s.isOk())
      return makeError(ErrorCode::kMalformed, where + " at byte " + std::to_string(kHeaderSize) + ": " + s.message());
  }
  return h;
}

Result<Footer> parseFooter(std::span<const uint8_t> last, uint64_t file_size, const std::string& what) {
  const std::string where = what + ": footer";
  if (file_size < kHeaderSize + kFooterSize || last.size() < kFooterSize)
    return makeError(ErrorCode::kTruncated,
                     where + ": the file ends at byte " + std::to_string(file_size) + ", too short for a container");
  last = last.last(kFooterSize);
  const uint64_t base = file_size - kFooterSize;
  if (std::memcmp(last.data() + 24, kFooterMagic, 8) != 0)
    return makeError(ErrorCode::kTruncated, where + " at byte " + std::to_string(base + 24) +
                                                ": footer magic missing (file truncated or not a container)");
  ByteReader r(last, where, base);
  Footer f;
  uint32_t version = 0, stored_crc = 0;
  SP_RETURN_IF_ERROR(r.u64(f.index_offset));
  SP_RETURN_IF_ERROR(r.u64(f.index_bytes));
  SP_RETURN_IF_ERROR(r.u32(version));
  f.version = version;
  SP_RETURN_IF_ERROR(r.u32(stored_crc));
  SP_RETURN_IF_ERROR(checkCrc(stored_crc, last.first(20), where + " at byte " + std::to_string(base + 20)));
  if (version < kContainerVersion || version > kContainerVersionMaterials)
    return makeError(ErrorCode::kUnknownVersion, where + " at byte " + std::to_string(base + 16) +
                                                     ": container format version " + std::to_string(version));
  if (f.index_offset < kHeaderSize || f.index_bytes < 12 || f.index_offset > base ||
      f.index_bytes != base - f.index_offset)
    return makeError(ErrorCode::kMalformed,
                     where + " at byte " + std::to_string(base) + ": index location does not match the file size");
  return f;
}

Result<std::vector<TileEntry>> parseIndex(std::span<const uint8_t> bytes, const ContainerHeader& header,
                                          const Footer& footer, const std::string& what) {
  const std::string where = what + ": tile index";
  if (bytes.size() != footer.index_bytes)
    return makeError(ErrorCode::kTruncated, where + " at byte " + std::to_string(footer.index_offset) + ": expected " +
                                                std::to_string(footer.index_bytes) + " bytes");
  if (footer.index_offset < header.header_size)
    return makeError(ErrorCode::kMalformed, where + " at byte " + std::to_string(footer.index_offset) +
                                                ": the index starts inside the header (" +
                                                std::to_string(header.header_size) + " bytes)");
  if (footer.version != header.version)
    return makeError(ErrorCode::kMalformed, what + ": footer says container format version " +
                                                std::to_string(footer.version) + ", the header " +
                                                std::to_string(header.version));
  uint32_t stored_crc = 0;
  std::memcpy(&stored_crc, bytes.data() + bytes.size() - 4, 4);
  SP_RETURN_IF_ERROR(checkCrc(stored_crc, bytes.first(bytes.size() - 4),
                              where + " at byte " + std::to_string(footer.index_offset + bytes.size() - 4)));
  ByteReader r(bytes, where, footer.index_offset);
  uint32_t magic = 0, count = 0;
  SP_RETURN_IF_ERROR(r.u32(magic));
  if (magic != kIndexMagic) return r.error(ErrorCode::kMalformed, "bad index magic");
  SP_RETURN_IF_ERROR(r.u32(count));
  if (count != header.tile_count)
    return r.error(ErrorCode::kMalformed, "index lists " + std::to_string(count) + " tiles, header says " +
                                              std::to_string(header.tile_count));
  if (uint64_t(count) * kIndexEntrySize + 12 != bytes.size())
    return r.error(ErrorCode::kMalformed, "index size does not match its tile count");
  std::vector<TileEntry> entries(count);
  uint64_t next_offset = header.header_size, vertices = 0, faces = 0;
  for (uint32_t i = 0; i < count; ++i) {
    TileEntry& e = entries[i];
    uint16_t codec = 0;
    SP_RETURN_IF_ERROR(r.u32(e.tile_id));
    SP_RETURN_IF_ERROR(r.u16(codec));
    e.codec = static_cast<CodecId>(codec);
    SP_RETURN_IF_ERROR(r.u16(e.codec_version));
    SP_RETURN_IF_ERROR(r.u64(e.offset));
    SP_RETURN_IF_ERROR(r.u64(e.chunk_bytes));
    SP_RETURN_IF_ERROR(r.u32(e.vertices));
    SP_RETURN_IF_ERROR(r.u32(e.faces));
    for (uint32_t& c : e.lo) SP_RETURN_IF_ERROR(r.u32(c));
    for (uint32_t& c : e.hi) SP_RETURN_IF_ERROR(r.u32(c));
    // Chunks are contiguous, in index order, between the header and the index.
    if (e.offset != next_offset || e.chunk_bytes < kChunkHeaderSize || e.chunk_bytes > footer.index_offset - e.offset)
      return r.error(ErrorCode::kMalformed, "tile " + std::to_string(e.tile_id) + " has an invalid location");
    next_offset = e.offset + e.chunk_bytes;
    // The counts bound the decoder, so they must be what the payload's size can hold (unknown codecs fail later).
    if (const CodecInfo* codec = findCodec(e.codec);
        codec && !codec->floor.admits(header.layout, e.vertices, e.faces, e.chunk_bytes - kChunkHeaderSize))
      return r.error(ErrorCode::kMalformed,
                     "tile " + std::to_string(e.tile_id) + " claims " + std::to_string(e.vertices) + " vertices and " +
                         std::to_string(e.faces) + " faces in " + std::to_string(e.chunk_bytes - kChunkHeaderSize) +
                         " payload bytes, more than codec " + std::string(codec->name) + " can code in them");
    vertices += e.vertices;
    faces += e.faces;
    for (uint32_t j = 0; j < i; ++j)
      if (entries[j].tile_id == e.tile_id)
        return r.error(ErrorCode::kMalformed, "tile id " + std::to_string(e.tile_id) + " appears twice");
  }
  if (next_offset != footer.index_offset)
    return makeError(ErrorCode::kMalformed, where + " at byte " + std::to_string(footer.index_offset) +
                                                ": tile chunks end at byte " + std::to_string(next_offset) +
                                                ", not where the index starts");
  if (vertices != header.vertices || faces != header.faces)
    return makeError(ErrorCode::kMalformed, where + " at byte " + std::to_string(footer.index_offset) +
                                                ": tile counts do not add up to the header's totals (at byte 56)");
  return entries;
}

Result<std::span<const uint8_t>> parseTileChunk(std::span<const uint8_t> chunk, const TileEntry& e,
                                                const std::string& what) {
  const std::string where = what + ": tile " + std::to_string(e.tile_id);
  const std::string at = " at byte " + std::to_string(e.offset);
  if (chunk.size() != e.chunk_bytes || chunk.size() < kChunkHeaderSize)
    return makeError(ErrorCode::kTruncated, where + at + ": chunk is shorter than the index says");
  ByteReader r(chunk, where, e.offset);
  uint32_t magic = 0, tile_id = 0, vertices = 0, faces = 0, payload_crc = 0, head_crc = 0;
  uint16_t codec = 0, version = 0;
  uint64_t payload_bytes = 0;
  SP_RETURN_IF_ERROR(r.u32(magic));
  SP_RETURN_IF_ERROR(r.u32(tile_id));
  SP_RETURN_IF_ERROR(r.u16(codec));
  SP_RETURN_IF_ERROR(r.u16(version));
  SP_RETURN_IF_ERROR(r.u32(vertices));
  SP_RETURN_IF_ERROR(r.u32(faces));
  SP_RETURN_IF_ERROR(r.u64(payload_bytes));
  SP_RETURN_IF_ERROR(r.u32(payload_crc));
  SP_RETURN_IF_ERROR(r.u32(head_crc));
  if (magic != kChunkMagic)
    return makeError(ErrorCode::kMalformed, where + ": bad chunk magic at byte " + std::to_string(e.offset));
  SP_RETURN_IF_ERROR(checkCrc(head_crc, chunk.first(kChunkHeaderSize - 4), where + " chunk header" + at));
  if (tile_id != e.tile_id || codec != static_cast<uint16_t>(e.codec) || version != e.codec_version ||
      vertices != e.vertices || faces != e.faces || payload_bytes != e.chunk_bytes - kChunkHeaderSize)
    return makeError(ErrorCode::kMalformed, where + " chunk header" + at + ": disagrees with the tile index");
  const auto payload = chunk.subspan(kChunkHeaderSize);
  SP_RETURN_IF_ERROR(checkCrc(payload_crc, payload,
                              where + " payload at byte " + std::to_string(e.offset + kChunkHeaderSize)));
  return payload;
}

DecodeLimits entryLimits(const TileEntry& e) { return DecodeLimits{e.vertices, e.faces}; }

namespace {

Result<const CodecInfo*> codecOf(const TileEntry& e, const std::string& where) {
  const CodecInfo* codec = findCodec(e.codec);
  if (!codec)
    return makeError(ErrorCode::kUnknownCodec, where + ": codec id " + std::to_string(static_cast<int>(e.codec)) +
                                                   " is not known to this build");
  return codec;
}

}  // namespace

Result<std::vector<CodecLevel>> tilePayloadLevels(const ContainerHeader& header, const TileEntry& e,
                                                  std::span<const uint8_t> payload, const std::string& what) {
  const std::string where = what + ": tile " + std::to_string(e.tile_id);
  SP_ASSIGN_OR_RETURN(const CodecInfo* codec, codecOf(e, where));
  if (!codec->levels) return std::vector<CodecLevel>{};
  auto levels = codec->levels(TileContext{header.grid.bits, header.layout}, e.codec_version, payload, entryLimits(e));
  if (!levels.isOk()) return levels.status().withContext(where);
  return levels;
}

Result<QuantizedMesh> decodeTilePayload(const ContainerHeader& header, const TileEntry& e,
                                        std::span<const uint8_t> payload, const std::string& what,
                                        std::optional<uint32_t> level, bool* complete, bool* own_attributes) {
  const std::string where = what + ": tile " + std::to_string(e.tile_id);
  SP_ASSIGN_OR_RETURN(const CodecInfo* codec, codecOf(e, where));
  const TileContext ctx{header.grid.bits, header.layout};
  const DecodeLimits limits = entryLimits(e);
  bool partial = false, coarse_own = false;
  if (level) {
    if (!codec->decode_level)
      return makeError(ErrorCode::kInvalidArgument, where + ": codec " + std::string(codec->name) +
                                                        " is single-rate; it has no levels to choose from");
    SP_ASSIGN_OR_RETURN(auto levels, tilePayloadLevels(header, e, payload, what));
    partial = !levels.empty() && *level < levels.back().level;
    coarse_own = partial && codec->showsOwnAttributes(e.codec_version, true, *level <= levels.front().level);
  }
  try {
    auto mesh = partial ? codec->decode_level(ctx, e.codec_version, payload, *level, limits)
                        : codec->decode(ctx, e.codec_version, payload, limits);
    if (!mesh.isOk()) return mesh.status().withContext(where);
    // A payload that welds by position (pm before v5) never yields a complete tile: its tiles weld as coarse ones
    // do, with their own attributes from the version that codes them.
    if (complete) *complete = !partial && codec->keepsAttributes(e.codec_version);
    if (own_attributes)
      *own_attributes = partial ? coarse_own : codec->showsOwnAttributes(e.codec_version, false, false);
    if (partial) return mesh;
    if (mesh->positions.size() != e.vertices || mesh->triangles.size() != e.faces)
      return makeError(ErrorCode::kMalformed, where + ": decoded " + std::to_string(mesh->positions.size()) +
                                                  " vertices and " + std::to_string(mesh->triangles.size()) +
                                                  " faces, the index says " + std::to_string(e.vertices) + " and " +
                                                  std::to_string(e.faces));
    return mesh;
  } catch (const std::bad_alloc&) {
    return makeError(ErrorCode::kMalformed,
                     where + ": out of memory while decoding (" + std::to_string(payload.size()) + " payload bytes)");
  }
}

Result<std::vector<uint8_t>> encodeContainer(const Grid& grid, const AttributeLayout& layout, const CodecInfo& codec,
                                             std::span<const QuantizedMesh> tiles, const CodecOptions& options) {
  std::vector<uint8_t> out;
  VectorSink sink(out);
  ContainerWriter writer(sink, grid, layout);
  SP_RETURN_IF_ERROR(writer.begin());
  const TileContext ctx{grid.bits, layout};
  for (size_t i = 0; i < tiles.size(); ++i) {
    SP_ASSIGN_OR_RETURN(EncodedTile tile, encodeMesh(codec, ctx, tiles[i], options));
    SP_RETURN_IF_ERROR(writer.addTile(static_cast<uint32_t>(i), codec, tile));
  }
  SP_RETURN_IF_ERROR(writer.finish());
  return out;
}

Result<ParsedContainer> parseContainer(std::span<const uint8_t> file, const std::string& what) {
  ParsedContainer pc;
  SP_ASSIGN_OR_RETURN(pc.header, parseHeader(file, what));
  Footer footer;
  SP_ASSIGN_OR_RETURN(footer, parseFooter(file, file.size(), what));
  SP_ASSIGN_OR_RETURN(pc.tiles,
                      parseIndex(file.subspan(footer.index_offset, footer.index_bytes), pc.header, footer, what));
  return pc;
}

}  // namespace scanpress
