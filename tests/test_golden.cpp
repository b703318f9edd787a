// Golden streams: one container per codec and format version (tests/golden/<codec>-v<version>.spz), written once
// and kept forever. Every build decodes each to the mesh it was made from, and the encoder of the version it writes
// must still produce exactly those bytes: changing a format means a new version and a new golden file, never an
// edit of an old one. SCANPRESS_WRITE_GOLDEN=1 writes the files that are missing (it never overwrites one).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <set>

#include "engine/container/container.h"
#include "engine/io/bytes.h"
#include "engine/quantize.h"
#include "engine/shapes.h"
#include "engine/stages/stage.h"
#include "test_util.h"

namespace scanpress {
namespace {

struct Golden {
  Grid grid;
  AttributeLayout layout{12, 3};
  QuantizedMesh mesh;
};

// A small mesh with what the codecs must keep: normals and colors, a vertex at the position of another with a
// different normal, a duplicated and a reversed triangle, an isolated vertex.
const Golden& golden() {
  static const Golden g = [] {
    Golden x;
    const Mesh sphere = testing::coloredIcosphere(2);
    x.grid = *makeGrid(boundingBox(sphere), 12);
    x.mesh = *quantizeMesh(sphere, x.grid, x.layout, nullptr);
    QuantizedMesh& m = x.mesh;
    const uint32_t twin = uint32_t(m.positions.size());
    m.positions.push_back(m.positions[0]);
    m.normals.push_back({uint16_t(m.normals[0][0] ^ 1), m.normals[0][1]});
    m.colors.push_back(m.colors[0]);
    size_t far = 0;  // a triangle away from vertex 0, to share an edge with the twin
    while (m.positions[m.triangles[far][1]] == m.positions[0] || m.positions[m.triangles[far][2]] == m.positions[0])
      ++far;
    m.triangles.push_back({twin, m.triangles[far][1], m.triangles[far][2]});
    m.triangles.push_back(m.triangles[7]);
    m.triangles.push_back({m.triangles[9][0], m.triangles[9][2], m.triangles[9][1]});
    m.positions.push_back({2048, 2048, 2048});  // isolated, inside the sphere
    m.normals.push_back({0, 0});
    m.colors.push_back({0, 0, 0, 255});
    return x;
  }();
  return g;
}

// prm remeshes the golden mesh on a lattice of 0.2 of the grid (820 cells, about its triangles' size).
CodecOptions goldenOptions() {
  CodecOptions o;
  o.prm.grid = 0.2;
  return o;
}

// The last version with a golden stream of the golden mesh: the codec's, but prm's is 1 (it writes version 2 only
// for scalar channels, which the golden mesh has none of: that stream is scalars-prm.spz, test_scalar_channels.cpp).
int lastGoldenVersion(const CodecInfo& codec) { return codec.id == CodecId::kPrm ? 1 : codec.version; }
// Versions with no golden stream of the golden mesh: pm's 4 (scalar channels only: scalars-pm.spz).
bool noGoldenStream(const CodecInfo& codec, int version) { return codec.id == CodecId::kPm && version == 4; }

std::string goldenPath(const CodecInfo& codec, int version) {
  return std::string(SCANPRESS_GOLDEN) + "/" + std::string(codec.name) + "-v" + std::to_string(version) + ".spz";
}

// A digest (FNV-1a, 64 bits) of a mesh's triangles with their corners' positions, octahedral normal codes and
// colors, each triangle rotated to start at its smallest corner, sorted: the same for the same triangles whatever
// the vertex order. Integers only, so the same on every platform.
uint64_t cornerDigest(const QuantizedMesh& m) {
  using Key = std::array<uint32_t, 3 * 5>;
  std::vector<Key> tris;
  for (const Triangle& t : m.triangles) {
    std::array<std::array<uint32_t, 5>, 3> c;
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = t[size_t(k)];
      const Vec3u& p = m.positions[v];
      const uint32_t n = m.normals.empty() ? 0 : uint32_t(m.normals[v][0]) << 16 | m.normals[v][1];
      const uint32_t col = m.colors.empty() ? 0
                                            : uint32_t(m.colors[v][0]) << 24 | uint32_t(m.colors[v][1]) << 16 |
                                                  uint32_t(m.colors[v][2]) << 8 | m.colors[v][3];
      c[size_t(k)] = {p[0], p[1], p[2], n, col};
    }
    std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
    Key key{};
    for (int k = 0; k < 3; ++k) std::copy(c[size_t(k)].begin(), c[size_t(k)].end(), key.begin() + 5 * k);
    tris.push_back(key);
  }
  std::sort(tris.begin(), tris.end());
  uint64_t h = 0xcbf29ce484222325ull;
  for (const Key& key : tris)
    for (uint32_t x : key)
      for (int b = 0; b < 4; ++b) h = (h ^ ((x >> (8 * b)) & 0xFF)) * 0x100000001b3ull;
  return h;
}

// cornerDigest of each prm golden stream's decoded mesh (prm-v1.spz), recorded with the stream.
constexpr uint64_t kPrmGoldenDigest[] = {0xde82287590593730ull};

// The golden stream of `version` decodes to the golden mesh.
void expectDecodesToGolden(const CodecInfo& codec, int version, const std::vector<uint8_t>& bytes,
                           const std::string& path) {
  SCOPED_TRACE(path);
  const Golden& g = golden();
  auto parsed = parseContainer(bytes, path);
  ASSERT_TRUE(parsed.isOk()) << parsed.status().toString();
  ASSERT_EQ(parsed->tiles.size(), 1u);
  const auto& e = parsed->tiles[0];
  EXPECT_EQ(e.codec, codec.id);
  EXPECT_EQ(e.codec_version, version);
  auto payload = parseTileChunk(std::span(bytes).subspan(e.offset, e.chunk_bytes), e, path);
  ASSERT_TRUE(payload.isOk()) << payload.status().toString();
  auto decoded = decodeTilePayload(parsed->header, e, *payload, path);
  ASSERT_TRUE(decoded.isOk()) << decoded.status().toString();
  if (codec.id == CodecId::kPm) {
    // pm keeps triangles over positions (welded, without those repeating a position); before v3 it derives
    // attributes.
    auto positional = [](const QuantizedMesh& m) {
      std::vector<testing::PosTriangle> out;
      for (const auto& t : testing::triangleMultiset(m))
        if (t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) out.push_back(t);
      return out;
    };
    EXPECT_TRUE(positional(*decoded) == positional(g.mesh));
    EXPECT_EQ(decoded->normals.size(), decoded->positions.size());
    if (version >= 5) {
      // v5 keeps every corner's attributes (wedges).
      QuantizedMesh kept = g.mesh;
      std::erase_if(kept.triangles, [&](const Triangle& t) {
        const auto& p = kept.positions;
        return p[t[0]] == p[t[1]] || p[t[1]] == p[t[2]] || p[t[0]] == p[t[2]];
      });
      EXPECT_TRUE(testing::cornerMultiset(*decoded, g.layout.normal_bits) ==
                  testing::cornerMultiset(kept, g.layout.normal_bits));
    } else if (version >= 3) {
      // From v3 each position shows the attributes of the golden mesh's first vertex there.
      std::map<Vec3u, size_t> first;
      for (size_t v = 0; v < g.mesh.positions.size(); ++v) first.emplace(g.mesh.positions[v], v);
      for (size_t v = 0; v < decoded->positions.size(); ++v) {
        const size_t o = first.at(decoded->positions[v]);
        if (g.layout.hasNormals()) {
          EXPECT_EQ(decoded->normals[v], g.mesh.normals[o]) << v;
        }
        if (g.layout.hasColors()) {
          EXPECT_EQ(decoded->colors[v], g.mesh.colors[o]) << v;
        }
      }
    }
  } else if (codec.id == CodecId::kPrm) {
    // prm's stream is its coder's: the remeshing before it is the encoder's choice (it improves without a new
    // version), so the golden stream is checked against the coder alone. It was remeshed (not the golden mesh),
    // and this build's coder, given the decoded mesh on the stream's lattice, writes exactly its payload.
    EXPECT_FALSE(testing::triangleMultiset(*decoded) == testing::triangleMultiset(g.mesh))
        << "the golden mesh was not remeshed";
    // What it decodes to, as a digest of its triangles with their corners' raw attributes, recorded when the
    // stream was written: a change to encoder and decoder alike cannot pass the re-encoding below unnoticed.
    EXPECT_EQ(cornerDigest(*decoded), kPrmGoldenDigest[version - 1]) << std::hex << cornerDigest(*decoded);
    auto spacing = prmPayloadSpacing(*payload);
    ASSERT_TRUE(spacing.isOk());
    std::vector<uint8_t> again;
    ByteWriter(again).varint(*spacing);
    TileSummary summary;
    ASSERT_TRUE(edgebreakerEncodeOnLattice(TileContext{g.grid.bits, g.layout}, *decoded, *spacing, again, nullptr,
                                           &summary)
                    .isOk());
    EXPECT_TRUE(std::equal(again.begin(), again.end(), payload->begin(), payload->end()))
        << "this build's prm coder writes the golden mesh differently: a format change needs a new version";
  } else {
    EXPECT_TRUE(testing::cornerMultiset(*decoded, g.layout.normal_bits) ==
                testing::cornerMultiset(g.mesh, g.layout.normal_bits));
  }
}

class GoldenStream : public ::testing::TestWithParam<CodecId> {};

// Every version this build knows still decodes (old archives stay readable); the version it writes is written
// byte for byte as its golden stream.
TEST_P(GoldenStream, DecodesToItsMeshAndTheEncoderStillWritesIt) {
  const CodecInfo& codec = *findCodec(GetParam());
  const Golden& g = golden();
  const QuantizedMesh tiles[] = {g.mesh};
  auto now = encodeContainer(g.grid, g.layout, codec, tiles, goldenOptions());
  ASSERT_TRUE(now.isOk()) << now.status().toString();
  auto parsed_now = parseContainer(*now, "now");
  ASSERT_TRUE(parsed_now.isOk()) << parsed_now.status().toString();
  const int written = parsed_now->tiles.at(0).codec_version;
  EXPECT_EQ(written, lastGoldenVersion(codec));
  const std::string path = goldenPath(codec, written);
  if (!std::filesystem::exists(path)) {
    const char* write = std::getenv("SCANPRESS_WRITE_GOLDEN");
    ASSERT_TRUE(write && std::string(write) == "1")
        << path << " is missing: a new codec or version needs its golden stream (SCANPRESS_WRITE_GOLDEN=1)";
    testing::writeBytes(path, std::string(now->begin(), now->end()));
  }
  for (int version = 1; version <= written; ++version) {
    if (noGoldenStream(codec, version)) continue;
    const std::string older = goldenPath(codec, version);
    ASSERT_TRUE(std::filesystem::exists(older)) << older << " is missing: golden streams are kept forever";
    expectDecodesToGolden(codec, version, testing::readBytes(older), older);
  }
  if (codec.id == CodecId::kPrm) {
    // The encoder's remeshing may change (see expectDecodesToGolden): today's stream decodes to the remesh stage's
    // mesh of the golden mesh (normals and colors interpolated), which is smaller coded than the mesh as it is.
    const CodecOptions o = goldenOptions();
    auto remeshed = remeshTile(TileContext{g.grid.bits, g.layout}, TileView{g.mesh, {}}, o.prm.tau,
                               prmSpacing(o.prm, g.grid.bits));
    ASSERT_TRUE(remeshed.isOk()) << remeshed.status().toString();
    auto parsed = parseContainer(*now, "now");
    ASSERT_TRUE(parsed.isOk());
    const auto& e = parsed->tiles[0];
    auto payload = parseTileChunk(std::span(*now).subspan(e.offset, e.chunk_bytes), e, "now");
    ASSERT_TRUE(payload.isOk());
    auto decoded = decodeTilePayload(parsed->header, e, *payload, "now");
    ASSERT_TRUE(decoded.isOk()) << decoded.status().toString();
    EXPECT_TRUE(testing::cornerMultiset(*decoded, g.layout.normal_bits) ==
                testing::cornerMultiset(remeshed->mesh, g.layout.normal_bits));
    return;
  }
  EXPECT_TRUE(*now == testing::readBytes(path))
      << "this build writes " << codec.name << " v" << written
      << " differently from its golden stream: a format change needs a new version";
}

// A golden stream's one tile: the file's bytes, the parsed container, the tile's payload (a view into the bytes).
struct GoldenTile {
  std::vector<uint8_t> bytes;
  ParsedContainer parsed;
  std::span<const uint8_t> payload;
};
void readGoldenTile(const std::string& path, GoldenTile& out) {
  out.bytes = testing::readBytes(path);
  auto parsed = parseContainer(out.bytes, path);
  ASSERT_TRUE(parsed.isOk()) << parsed.status().toString();
  out.parsed = std::move(parsed).value();
  const auto& e = out.parsed.tiles[0];
  auto payload = parseTileChunk(std::span(out.bytes).subspan(e.offset, e.chunk_bytes), e, path);
  ASSERT_TRUE(payload.isOk());
  out.payload = *payload;
}

// A tile of an older version copied into a new container (as `merge` does with parts from an older build) keeps
// its version and still decodes to its mesh.
TEST_P(GoldenStream, OlderTilesKeepTheirVersionWhenCopied) {
  const CodecInfo& codec = *findCodec(GetParam());
  const Golden& g = golden();
  for (int version = 1; version < lastGoldenVersion(codec); ++version) {
    if (noGoldenStream(codec, version)) continue;
    const std::string path = goldenPath(codec, version);
    GoldenTile tile;
    ASSERT_NO_FATAL_FAILURE(readGoldenTile(path, tile));
    const auto& e = tile.parsed.tiles[0];
    std::vector<uint8_t> copy;
    VectorSink sink(copy);
    ContainerWriter writer(sink, g.grid, g.layout);
    ASSERT_TRUE(writer.begin().isOk());
    ASSERT_TRUE(writer.addTile(0, codec, TileSummary{e.vertices, e.faces, e.lo, e.hi}, tile.payload, e.codec_version)
                    .isOk());
    ASSERT_TRUE(writer.finish().isOk());
    expectDecodesToGolden(codec, version, copy, path + " (copied)");
  }
}

// The coarse levels of every golden stream whose version codes attributes through its levels (kdtree, octree and
// pm from v3) show, at each vertex, the normal and color of a golden-mesh point in its cell (past the last level that
// codes its births, the cell of its ancestor at that level), and the levels before it derive them.
TEST_P(GoldenStream, CoarseLevelsShowTheGoldenMeshsAttributes) {
  const CodecInfo& codec = *findCodec(GetParam());
  if (!codec.progressive() || codec.coarse_attributes_from == 0) GTEST_SKIP() << codec.name << ": derived";
  const Golden& g = golden();
  for (int version = 1; version <= lastGoldenVersion(codec); ++version) {
    if (noGoldenStream(codec, version)) continue;
    const std::string path = goldenPath(codec, version);
    SCOPED_TRACE(path);
    GoldenTile tile;
    ASSERT_NO_FATAL_FAILURE(readGoldenTile(path, tile));
    const auto& e = tile.parsed.tiles[0];
    auto levels = tilePayloadLevels(tile.parsed.header, e, tile.payload, path);
    ASSERT_TRUE(levels.isOk());
    if (codec.id == CodecId::kPm) {
      // pm's vertex i of every level is vertex i of the last level (each split appends): from v3 it shows its own
      // attributes (those it has at the last level, which expectDecodesToGolden checks) or, where its level defers
      // them, those of an ancestor (a lower vertex number); the base's vertices show their own.
      auto full = decodeTilePayload(tile.parsed.header, e, tile.payload, path);
      ASSERT_TRUE(full.isOk());
      for (const CodecLevel& l : *levels) {
        bool own = false;
        auto m = decodeTilePayload(tile.parsed.header, e, tile.payload, path, l.level, nullptr, &own);
        ASSERT_TRUE(m.isOk()) << m.status().toString();
        EXPECT_EQ(own, version >= codec.coarse_attributes_from) << "level " << l.level;
        if (!own) continue;
        std::set<std::pair<OctNormal, Rgba8>> lower;  // what vertices 0..v show at the last level
        for (size_t v = 0; v < m->positions.size(); ++v) {
          lower.insert({full->normals[v], full->colors[v]});
          if (v < levels->front().vertices) {
            ASSERT_EQ(m->normals[v], full->normals[v]) << "level " << l.level << " vertex " << v;
            ASSERT_EQ(m->colors[v], full->colors[v]) << "level " << l.level << " vertex " << v;
          }
          ASSERT_TRUE(lower.count({m->normals[v], m->colors[v]})) << "level " << l.level << " vertex " << v;
        }
      }
      continue;
    }
    const uint32_t limit = std::max<uint32_t>(64, e.vertices / 16);
    int last_coded = -1;
    size_t own_levels = 0;
    for (size_t i = 1; i + 1 < levels->size(); ++i) {
      const uint32_t level = (*levels)[i].level;
      bool own = false;
      auto m = decodeTilePayload(tile.parsed.header, e, tile.payload, path, level, nullptr, &own);
      ASSERT_TRUE(m.isOk()) << m.status().toString();
      EXPECT_EQ(own, version >= codec.coarse_attributes_from) << "level " << level;
      if (!own) continue;
      if (m->positions.size() <= limit) last_coded = int(level);
      ASSERT_GE(last_coded, 0);
      // kdtree and octree v4 (creases.h): a vertex by a crease or seam may show a value chosen among its
      // ancestors' (one within the range of its corners' points' values): a point of the tile's, not always of its
      // cell's.
      const bool chosen = (codec.id == CodecId::kKdtree || codec.id == CodecId::kOctree) && version >= 4;
      EXPECT_EQ(testing::verticesShowingNoPointOfTheirCell(g.mesh, *m, g.grid.bits, chosen ? 0 : last_coded), 0u)
          << "level " << level;
      ++own_levels;
    }
    if (version >= codec.coarse_attributes_from) {
      EXPECT_GE(own_levels, 3u);
    }
  }
}

// Without normals and colors, pm v3 writes v2's bytes (FORMAT.md, "Attributes of pm levels"): the golden mesh
// without its attributes codes to the payload of the v2 golden stream (v2 kept none).
TEST(GoldenStreamPm, WithoutAttributesVersion3WritesVersion2Bytes) {
  const CodecInfo& pm = *findCodec(CodecId::kPm);
  const Golden& g = golden();
  GoldenTile tile;
  ASSERT_NO_FATAL_FAILURE(readGoldenTile(goldenPath(pm, 2), tile));
  QuantizedMesh bare = g.mesh;
  bare.normals.clear();
  bare.colors.clear();
  auto now = pm.encode(TileContext{g.grid.bits, {}}, TileView{bare, {}}, goldenOptions());
  ASSERT_TRUE(now.isOk()) << now.status().toString();
  EXPECT_TRUE(std::equal(now->payload.begin(), now->payload.end(), tile.payload.begin(), tile.payload.end()));
}

std::vector<CodecId> everyCodec() {
  std::vector<CodecId> ids;
  for (const auto& c : allCodecs()) ids.push_back(c.id);
  return ids;
}

INSTANTIATE_TEST_SUITE_P(Codecs, GoldenStream, ::testing::ValuesIn(everyCodec()),
                         [](const ::testing::TestParamInfo<CodecId>& info) {
  return std::string(findCodec(info.param)->name);
});

}  // namespace
}  // namespace scanpress
