// What the container fuzz target and the malformation sweep do with a (possibly malformed) container in
// memory: repair its checksums after a mutation, so that a mutated file reaches the decoders instead of
// stopping at a checksum, and decode everything in it (every tile whole, every level of every progressive
// tile) within the index's limits, as `scanpress decode` and `decode --level/--bytes` would.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <span>
#include <unordered_map>
#include <vector>

#include "engine/container/container.h"
#include "engine/io/crc32c.h"

namespace scanpress::fuzzing {

inline uint64_t loadU64(const std::vector<uint8_t>& b, uint64_t at) {
  uint64_t v = 0;
  std::memcpy(&v, b.data() + at, 8);
  return v;
}
inline void storeCrc(std::vector<uint8_t>& b, uint64_t at, std::span<const uint8_t> covered) {
  const uint32_t crc = crc32c(covered);
  std::memcpy(b.data() + at, &crc, 4);
}

// Recomputes every CRC-32C that FORMAT.md places where this file's own fields say: the header's, a version 2
// header's channel table (its size from byte 12), the footer's, each chunk's (walking the chunks from the header's
// end by their payload lengths, up to the index) and the index's. Fields that point outside the file are left
// alone (the parser must refuse them).
inline void repairChecksums(std::vector<uint8_t>& b) {
  const uint64_t n = b.size();
  const std::span<const uint8_t> all(b);
  if (n >= kHeaderSize) storeCrc(b, kHeaderSize - 4, all.first(kHeaderSize - 4));
  if (n < kHeaderSize + kFooterSize) return;
  uint32_t header_size = 0;
  std::memcpy(&header_size, b.data() + 12, 4);
  if (header_size < kHeaderSize + 5 || header_size > kMaxHeaderSize || header_size > n - kFooterSize)
    header_size = uint32_t(kHeaderSize);
  if (header_size > kHeaderSize) storeCrc(b, header_size - 4, all.subspan(kHeaderSize, header_size - kHeaderSize - 4));
  const uint64_t footer = n - kFooterSize;
  storeCrc(b, footer + 20, all.subspan(footer, 20));
  const uint64_t index_offset = loadU64(b, footer), index_bytes = loadU64(b, footer + 8);
  const bool index_inside = index_offset >= header_size && index_offset <= footer && index_bytes >= 12 &&
                            index_bytes <= footer - index_offset;
  const uint64_t chunks_end = index_inside ? index_offset : footer;
  for (uint64_t at = header_size; at + kChunkHeaderSize <= chunks_end;) {
    const uint64_t payload_bytes = loadU64(b, at + 20);
    if (payload_bytes > chunks_end - at - kChunkHeaderSize) break;
    storeCrc(b, at + 28, all.subspan(at + kChunkHeaderSize, payload_bytes));
    storeCrc(b, at + 32, all.subspan(at, 32));
    at += kChunkHeaderSize + payload_bytes;
  }
  if (index_inside) storeCrc(b, index_offset + index_bytes - 4, all.subspan(index_offset, index_bytes - 4));
}

// What decodeEverything did: decoder calls (whole tiles and levels) and how they ended.
struct DecodeCounts {
  uint64_t containers_parsed = 0;  // header, footer and index accepted
  uint64_t decodes = 0;            // decoder calls: whole tiles and levels
  uint64_t decodes_ok = 0;
  uint64_t decode_errors = 0;    // a clean error: a Status, not a crash
  uint64_t decodes_skipped = 0;  // repeats of a decode already done (DecodeOptions::seen)
};

struct DecodeOptions {
  // Check every chunk (its checksums and fields) before decoding any tile, and stop at the first bad one, as
  // `info --verify` does; otherwise decode every tile whose chunk is good (the fuzz target: more decoder
  // coverage).
  bool verify_first = false;
  // When set: the hashes of the (header, chunk header, payload) triples decoded so far, with the first error
  // their decodes gave. A tile that was already decoded with the same bytes is not decoded again (decoding is
  // deterministic; its outcome is taken from here): a mutation of one tile then costs that tile's decodes
  // only.
  std::unordered_map<uint64_t, Status>* seen = nullptr;
};

// FNV-1a, 64 bits, continuing from `h`.
inline uint64_t fnv1a(std::span<const uint8_t> bytes, uint64_t h = 0xcbf29ce484222325ull) {
  for (const uint8_t c : bytes) h = (h ^ c) * 0x100000001b3ull;
  return h;
}

// One tile: whole, then every level (cut at its end) and one past the last. `decoded` takes each decoder
// call's status, `note` any other error.
template <typename Decoded, typename Note>
void decodeTile(const ContainerHeader& header, const TileEntry& e, std::span<const uint8_t> payload, Decoded& decoded,
                Note& note) {
  decoded(decodeTilePayload(header, e, payload, "fuzz").status());
  auto levels = tilePayloadLevels(header, e, payload, "fuzz");
  if (!levels.isOk()) {
    note(levels.status());
    return;
  }
  for (const CodecLevel& level : *levels) {
    const auto cut = payload.first(std::min<uint64_t>(level.end_bytes, payload.size()));
    decoded(decodeTilePayload(header, e, cut, "fuzz", level.level).status());
  }
  if (!levels->empty()) decoded(decodeTilePayload(header, e, payload, "fuzz", levels->back().level + 1).status());
}

// Parses the container and decodes every tile whole and, for progressive codecs, every level from the payload
// cut at the level's end (as `decode --bytes` does) and one level past the last. Keeps going after a failing
// tile so that one mutation reaches every decoder it can. Returns the first error (ok when everything
// decoded).
inline Status decodeEverything(std::span<const uint8_t> file, DecodeCounts& counts, const DecodeOptions& options = {}) {
  auto parsed = parseContainer(file, "fuzz");
  if (!parsed.isOk()) return parsed.status();
  ++counts.containers_parsed;
  Status first = Status::ok();
  auto note = [&](const Status& s) {
    if (s.isOk()) return;
    if (first.isOk()) first = s;
  };
  auto decoded = [&](const Status& s) {
    ++counts.decodes;
    ++(s.isOk() ? counts.decodes_ok : counts.decode_errors);
    note(s);
  };
  const ContainerHeader& header = parsed->header;
  std::vector<Result<std::span<const uint8_t>>> payloads;
  for (const TileEntry& e : parsed->tiles) {
    payloads.push_back(parseTileChunk(file.subspan(e.offset, e.chunk_bytes), e, "fuzz"));
    if (options.verify_first && !payloads.back().isOk()) return payloads.back().status();
  }
  for (size_t t = 0; t < parsed->tiles.size(); ++t) {
    const TileEntry& e = parsed->tiles[t];
    const auto& payload = payloads[t];
    if (!payload.isOk()) {
      note(payload.status());
      continue;
    }
    uint64_t hash = 0;
    if (options.seen) {
      hash = fnv1a(file.subspan(e.offset, e.chunk_bytes), fnv1a(file.first(parsed->header.header_size)));
      if (const auto it = options.seen->find(hash); it != options.seen->end()) {
        ++counts.decodes_skipped;
        note(it->second);
        continue;
      }
    }
    const Status before = first;
    first = Status::ok();
    decodeTile(header, e, *payload, decoded, note);
    if (options.seen) options.seen->emplace(hash, first);
    if (!before.isOk()) first = before;
  }
  return first;
}

}  // namespace scanpress::fuzzing
