// The malformation sweep's inputs (issue 18, "Hardening that stays"): small valid containers of every codec,
// with and without normals and colors, and the deterministic, seeded mutations made from them. Used by the
// engine sweep (test_malformation_sweep.cpp, every mutation decoded in process) and by the CLI sample of it
// (test_sweep_cli.cpp, exit codes). Standard library and the engine only.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "engine/codecs/codec.h"
#include "engine/container/container.h"
#include "engine/shapes.h"
#include "fuzz/container_decode.h"

namespace scanpress::sweep {

struct SweepContainer {
  std::string name;  // e.g. "kdtree+normals+colors"
  bool progressive = false;
  std::vector<uint8_t> bytes;
};

// Every `step`-th triangle of `m` with the vertices they use (renumbered, attributes kept): a smaller tile.
inline QuantizedMesh everyNthTriangle(const QuantizedMesh& m, size_t step, size_t first) {
  QuantizedMesh out;
  std::vector<uint32_t> remap(m.positions.size(), UINT32_MAX);
  const size_t stride = m.positions.empty() ? 0 : m.scalars.size() / m.positions.size();
  for (size_t t = first; t < m.triangles.size(); t += step) {
    Triangle tri{};
    for (int c = 0; c < 3; ++c) {
      const uint32_t v = m.triangles[t][c];
      if (remap[v] == UINT32_MAX) {
        remap[v] = static_cast<uint32_t>(out.positions.size());
        out.positions.push_back(m.positions[v]);
        if (!m.normals.empty()) out.normals.push_back(m.normals[v]);
        if (!m.colors.empty()) out.colors.push_back(m.colors[v]);
        out.scalars.insert(out.scalars.end(), m.scalars.begin() + ptrdiff_t(v * stride),
                           m.scalars.begin() + ptrdiff_t((v + 1) * stride));
      }
      tri[c] = remap[v];
    }
    out.triangles.push_back(tri);
  }
  return out;
}

// Three tiles (an icosphere of 80 triangles and two smaller pieces of it) at 10 grid bits, for every codec,
// without attributes and with 8-bit normals and RGBA colors, and for store, kdtree and edgebreaker also with two
// scalar channels (a float and a uchar: container version 2): containers of a few hundred bytes each.
inline std::vector<SweepContainer> sweepContainers() {
  Mesh m = icosphere(1);
  for (size_t i = 0; i < m.positions.size(); ++i) {
    const Vec3d& p = m.positions[i];
    m.normals.push_back({static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2])});
    m.colors.push_back({static_cast<uint8_t>(37 * i), static_cast<uint8_t>(11 * i), 200, 255});
  }
  m.color_channels = 4;
  m.scalar_channels = {{"confidence", ScalarType::kFloat32}, {"q", ScalarType::kUint8}};
  for (size_t i = 0; i < m.positions.size(); ++i) {
    const float f = static_cast<float>(0.5 + 0.3 * m.positions[i][0]);
    uint32_t bits = 0;
    std::memcpy(&bits, &f, 4);
    m.scalars.push_back(bits);
    m.scalars.push_back(static_cast<uint32_t>((7 * i) & 255));
  }
  const Grid grid = makeGrid(boundingBox(m), 10).value();
  AttributeLayout scalars{8, 4};
  scalars.scalars = m.scalar_channels;
  std::vector<SweepContainer> out;
  for (const CodecInfo& codec : allCodecs()) {
    const bool carries = codec.id == CodecId::kStore || codec.id == CodecId::kKdtree ||
                         codec.id == CodecId::kEdgebreaker;
    for (const AttributeLayout& layout : {AttributeLayout{0, 0}, AttributeLayout{8, 4}, scalars}) {
      if (layout.hasScalars() && !carries) continue;
      const QuantizedMesh q = quantizeMesh(m, grid, layout, nullptr).value();
      const std::vector<QuantizedMesh> tiles{q, everyNthTriangle(q, 3, 0), everyNthTriangle(q, 7, 2)};
      SweepContainer c;
      c.progressive = codec.progressive();
      c.name = std::string(codec.name) + (layout.hasNormals() ? "+normals+colors" : "") +
               (layout.hasScalars() ? "+scalars" : "");
      c.bytes = encodeContainer(grid, layout, codec, tiles).value();
      out.push_back(std::move(c));
    }
  }
  return out;
}

// The mutation families. "Repaired" ones recompute every checksum afterwards (fuzzing::repairChecksums), so
// that the edit reaches the parser's and decoders' logic; the others must all be refused (a checksum, a magic
// or a size catches them).
enum class Family {
  kTruncation,         // every prefix
  kBitFlip,            // every bit of every byte
  kBitFlipRepaired,    // every bit of every byte, checksums repaired
  kOverwrite,          // every byte set to a seeded random value
  kOverwriteRepaired,  // every byte set to 0x00, 0xFF, 0x80 and a seeded random value, checksums repaired
  kTrailing,           // 1..64 seeded random bytes appended, and a second footer appended
  kHeaderEdit,         // header fields set to edge values, checksums repaired
  kIndexEdit,          // a tile's counts, codec, version or bounds changed in its index entry and chunk header
                       // alike (totals adjusted), checksums repaired
  kPayloadEdit,        // 1..8 seeded random bytes overwritten inside one tile's payload, checksums repaired
};
constexpr Family kFamilies[] = {Family::kTruncation, Family::kBitFlip,           Family::kBitFlipRepaired,
                                Family::kOverwrite,  Family::kOverwriteRepaired, Family::kTrailing,
                                Family::kHeaderEdit, Family::kIndexEdit,         Family::kPayloadEdit};

inline const char* familyName(Family f) {
  switch (f) {
    case Family::kTruncation: return "truncation";
    case Family::kBitFlip: return "bit flip";
    case Family::kBitFlipRepaired: return "bit flip, CRC repaired";
    case Family::kOverwrite: return "byte overwrite";
    case Family::kOverwriteRepaired: return "byte overwrite, CRC repaired";
    case Family::kTrailing: return "trailing bytes";
    case Family::kHeaderEdit: return "header edit, CRC repaired";
    case Family::kIndexEdit: return "index+chunk edit, CRC repaired";
    case Family::kPayloadEdit: return "payload edit, CRC repaired";
  }
  return "?";
}
// Whether every mutation of the family must be refused (no repair: a checksum or the layout catches it).
inline bool mustBeRefused(Family f) {
  return f == Family::kTruncation || f == Family::kBitFlip || f == Family::kOverwrite || f == Family::kTrailing;
}

template <typename T>
void put(std::vector<uint8_t>& b, uint64_t at, T v) {
  std::memcpy(b.data() + at, &v, sizeof v);
}
template <typename T>
T get(const std::vector<uint8_t>& b, uint64_t at) {
  T v;
  std::memcpy(&v, b.data() + at, sizeof v);
  return v;
}

// Calls `visit` with every mutation of `family` made from the valid container `base`, in a fixed order;
// `seed` (with the family) seeds the random values. `payload_edits` is the number of kPayloadEdit mutations.
inline void forEachMutation(const std::vector<uint8_t>& base, Family family, uint64_t seed, int payload_edits,
                            const std::function<void(const std::vector<uint8_t>&)>& visit) {
  std::mt19937_64 rng(seed * 131 + static_cast<uint64_t>(family));
  const uint64_t n = base.size();
  std::vector<uint8_t> b;
  switch (family) {
    case Family::kTruncation:
      for (uint64_t len = 0; len < n; ++len) visit(std::vector<uint8_t>(base.begin(), base.begin() + len));
      return;
    case Family::kBitFlip:
    case Family::kBitFlipRepaired:
      for (uint64_t i = 0; i < n; ++i)
        for (int bit = 0; bit < 8; ++bit) {
          b = base;
          b[i] ^= static_cast<uint8_t>(1u << bit);
          if (family == Family::kBitFlipRepaired) fuzzing::repairChecksums(b);
          visit(b);
        }
      return;
    case Family::kOverwrite:
      for (uint64_t i = 0; i < n; ++i) {
        b = base;
        b[i] = static_cast<uint8_t>(b[i] ^ (1 + rng() % 255));  // always a different value
        visit(b);
      }
      return;
    case Family::kOverwriteRepaired:
      for (uint64_t i = 0; i < n; ++i)
        for (const int v : {0x00, 0xFF, 0x80, -1}) {
          b = base;
          b[i] = static_cast<uint8_t>(v >= 0 ? v : static_cast<int>(rng() & 0xFF));
          fuzzing::repairChecksums(b);
          visit(b);
        }
      return;
    case Family::kTrailing:
      for (int k = 1; k <= 64; ++k) {
        b = base;
        for (int i = 0; i < k; ++i) b.push_back(static_cast<uint8_t>(rng()));
        visit(b);
      }
      b = base;
      b.insert(b.end(), base.end() - kFooterSize, base.end());
      visit(b);
      return;
    case Family::kHeaderEdit: {
      const double inf = std::numeric_limits<double>::infinity(), nan = std::numeric_limits<double>::quiet_NaN();
      auto edit = [&](auto change) {
        b = base;
        change(b);
        fuzzing::repairChecksums(b);
        visit(b);
      };
      for (uint32_t v : {0u, 2u, 0xFFFFFFFFu}) edit([&](auto& x) { put<uint32_t>(x, 8, v); });
      for (uint32_t v : {0u, 79u, 81u, 0xFFFFFFFFu}) edit([&](auto& x) { put<uint32_t>(x, 12, v); });
      const double doubles[] = {0.0, -0.0, -1.0, 5e-324, 1e-308, 1e-300, 1e300, 1e308, -1e308, inf, -inf, nan};
      for (uint64_t at : {16, 24, 32, 40})
        for (double v : doubles) edit([&](auto& x) { put<double>(x, at, v); });
      for (uint64_t at : {48, 49, 50, 51})
        for (int v = 0; v < 256; ++v) edit([&](auto& x) { x[at] = static_cast<uint8_t>(v); });
      const uint32_t tiles = get<uint32_t>(base, 52);
      for (uint32_t v : {0u, 1u, tiles - 1, tiles + 1, kMaxTiles, kMaxTiles + 1, 0xFFFFFFFFu})
        edit([&](auto& x) { put<uint32_t>(x, 52, v); });
      for (uint64_t at : {56, 64}) {
        const uint64_t total = get<uint64_t>(base, at);
        for (uint64_t v : {uint64_t{0}, total - 1, total + 1, uint64_t{1} << 32, ~uint64_t{0}})
          edit([&](auto& x) { put<uint64_t>(x, at, v); });
      }
      for (uint32_t v : {1u, 0xFFFFFFFFu}) edit([&](auto& x) { put<uint32_t>(x, 72, v); });
      // Version 2: every byte of the scalar-channel table set to edge values (count, types, name lengths, names).
      const uint32_t header_size = get<uint32_t>(base, 12);
      for (uint64_t at = kHeaderSize; at + 4 < header_size; ++at)
        for (int v : {0, 1, 7, 8, 9, 32, 255}) edit([&](auto& x) { x[at] = static_cast<uint8_t>(v); });
      return;
    }
    case Family::kIndexEdit: {
      const ParsedContainer pc = parseContainer(base, "sweep").value();
      const uint64_t index_offset = get<uint64_t>(base, n - kFooterSize);
      for (size_t t = 0; t < pc.tiles.size(); ++t) {
        const TileEntry& e = pc.tiles[t];
        const uint64_t entry = index_offset + 8 + t * kIndexEntrySize;
        // A count field: index entry offset, chunk header offset, header total offset.
        auto editCount =
            [&](uint64_t entry_at, uint64_t chunk_at, uint64_t total_at, uint32_t old_value, uint32_t value) {
          b = base;
          put<uint32_t>(b, entry + entry_at, value);
          put<uint32_t>(b, e.offset + chunk_at, value);
          put<uint64_t>(b, total_at, get<uint64_t>(b, total_at) - old_value + value);
          fuzzing::repairChecksums(b);
          visit(b);
        };
        for (const bool faces : {false, true}) {
          const uint32_t old_value = faces ? e.faces : e.vertices;
          for (uint32_t v : {0u, 1u, 2u, 3u, old_value - 1, old_value + 1, 2 * old_value, old_value << 4, 1u << 16,
                             1u << 20, 1u << 26, 0xFFFFFFFFu})
            editCount(faces ? 28 : 24, faces ? 16 : 12, faces ? 64 : 56, old_value, v);
        }
        for (uint16_t codec : {0, 1, 2, 3, 4, 0xFFFF})
          for (uint16_t version : {0, 1, 2}) {
            b = base;
            put<uint16_t>(b, entry + 4, codec);
            put<uint16_t>(b, e.offset + 8, codec);
            put<uint16_t>(b, entry + 6, version);
            put<uint16_t>(b, e.offset + 10, version);
            fuzzing::repairChecksums(b);
            visit(b);
          }
        for (uint64_t at = 32; at < kIndexEntrySize; at += 4)  // bounds: lo and hi
          for (uint32_t v : {0u, 1023u, 1024u, 0xFFFFFFFFu}) {
            b = base;
            put<uint32_t>(b, entry + at, v);
            fuzzing::repairChecksums(b);
            visit(b);
          }
      }
      return;
    }
    case Family::kPayloadEdit: {
      const ParsedContainer pc = parseContainer(base, "sweep").value();
      for (int k = 0; k < payload_edits; ++k) {
        const TileEntry& e = pc.tiles[rng() % pc.tiles.size()];
        const uint64_t payload = e.chunk_bytes - kChunkHeaderSize;
        if (payload == 0) continue;
        b = base;
        const int bytes = 1 + static_cast<int>(rng() % 8);
        for (int i = 0; i < bytes; ++i) b[e.offset + kChunkHeaderSize + rng() % payload] = static_cast<uint8_t>(rng());
        fuzzing::repairChecksums(b);
        visit(b);
      }
      return;
    }
  }
}

}  // namespace scanpress::sweep
