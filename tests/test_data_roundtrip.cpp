// Every real scan round-trips through `store`: the decoded mesh equals the input after quantization, as the
// multiset of triangles over quantized positions with orientation kept; attributes come back as quantized.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>

#include "engine/container/container.h"
#include "jobs/commands.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs_util.h"

namespace scanpress {
namespace {

struct Scan {
  const char* file;
  uint64_t vertices;   // vertices the reader delivers (STL: distinct positions)
  uint64_t triangles;  // from ../shared/data/README.md
};

const Scan kScans[] = {
    {"aneurysm_data.stl.zst", 10204, 20294}, {"armadillo.obj.zst", 43243, 86482},
    {"bun_zipper.ply.zst", 35947, 69451},    {"bunny.stl.zst", 34834, 69451},
    {"decimated-max.obj", 5272, 10540},      {"fandisk.obj", 6475, 12946},
    {"gargo.ply.zst", 25002, 50000},         {"horse.ply.zst", 48485, 96966},
    {"igea.ply.zst", 134345, 268686},        {"lato000.ply.zst", 44461, 86766},
    {"lucy.ply.zst", 49987, 99970},          {"parasaurolophus_low_normals2.ply.zst", 28291, 54839},
    {"rs1_normals.ply.zst", 114373, 221803}, {"screwdriver.ply", 6789, 13574},
    {"turbineblade.ply.zst", 99519, 199034},
};

void PrintTo(const Scan& scan, std::ostream* os) { *os << scan.file; }

// The scan's attributes at 12-bit normals.
AttributeLayout layoutOf(const Mesh& mesh) {
  AttributeLayout layout;
  if (!mesh.normals.empty()) layout.normal_bits = 12;
  if (!mesh.colors.empty()) layout.color_channels = mesh.color_channels;
  return layout;
}

// `mesh` quantized at `bits` (its drop counts into *qs), and the same mesh after one tile of an in-memory
// container with `codec` and back.
Result<std::pair<QuantizedMesh, QuantizedMesh>> quantizedAndDecoded(const Mesh& mesh, int bits,
                                                                    const AttributeLayout& layout, CodecId codec,
                                                                    const std::string& name, QuantizeStats* qs) {
  SP_ASSIGN_OR_RETURN(Grid grid, makeGrid(boundingBox(mesh), bits));
  SP_ASSIGN_OR_RETURN(QuantizedMesh q, quantizeMesh(mesh, grid, layout, qs));
  const QuantizedMesh tiles[] = {q};
  SP_ASSIGN_OR_RETURN(auto bytes, encodeContainer(grid, layout, *findCodec(codec), tiles));
  SP_ASSIGN_OR_RETURN(auto pc, parseContainer(bytes, name));
  const auto& e = pc.tiles.at(0);
  SP_ASSIGN_OR_RETURN(auto payload, parseTileChunk(std::span(bytes).subspan(e.offset, e.chunk_bytes), e, name));
  SP_ASSIGN_OR_RETURN(QuantizedMesh decoded, decodeTilePayload(pc.header, e, payload, name));
  return std::pair{std::move(q), std::move(decoded)};
}

class DataRoundTrip : public ::testing::TestWithParam<Scan> {};

TEST_P(DataRoundTrip, StoreIsLosslessAfterQuantization) {
  const Scan& scan = GetParam();
  const std::string path = testing::sharedDataDir() + "/" + scan.file;
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared data not found: " << path << " (set SCANPRESS_DATA)";
  ReadStats stats;
  auto mesh = readMeshFile(path, &stats);
  ASSERT_TRUE(mesh.isOk()) << mesh.status().toString();
  EXPECT_EQ(stats.vertices, scan.vertices);
  EXPECT_EQ(stats.triangles, scan.triangles);
  const AttributeLayout layout = layoutOf(*mesh);

  for (int bits : {12, 16, 24}) {
    SCOPED_TRACE(bits);
    QuantizeStats qs;
    auto r = quantizedAndDecoded(*mesh, bits, layout, CodecId::kStore, scan.file, &qs);
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    const auto& [q, decoded] = *r;
    EXPECT_EQ(q.triangles.size() + qs.degenerate_triangles, scan.triangles);
    EXPECT_EQ(q.positions.size() + qs.unreferenced_vertices, scan.vertices);
    EXPECT_TRUE(testing::triangleMultiset(decoded) == testing::triangleMultiset(q));
    EXPECT_EQ(decoded.normals, q.normals);
    EXPECT_EQ(decoded.colors, q.colors);
  }
}

// The same for the progressive codecs through a container; vertices that share position and attributes come
// back merged, so the comparison is over attributed corners.
void expectLosslessAfterQuantization(const Scan& scan, CodecId codec, std::initializer_list<int> bit_depths) {
  const std::string path = testing::sharedDataDir() + "/" + scan.file;
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared data not found: " << path << " (set SCANPRESS_DATA)";
#if defined(__SANITIZE_ADDRESS__)
  if (scan.triangles > 60000)
    GTEST_SKIP() << "large scan skipped in the unoptimized sanitizer build; the Release suite round-trips it";
#endif
  std::vector<int> depths(bit_depths);
#if defined(__SANITIZE_ADDRESS__)
  depths.resize(1);  // the first grid depth only: the same code at each (the Release suite runs them all)
#endif
  auto mesh = readMeshFile(path);
  ASSERT_TRUE(mesh.isOk()) << mesh.status().toString();
  const AttributeLayout layout = layoutOf(*mesh);
  for (int bits : depths) {
    SCOPED_TRACE(bits);
    QuantizeStats qs;
    auto r = quantizedAndDecoded(*mesh, bits, layout, codec, scan.file, &qs);
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    const auto& [q, decoded] = *r;
    EXPECT_EQ(q.triangles.size() + qs.degenerate_triangles, scan.triangles);
    EXPECT_TRUE(testing::cornerMultiset(decoded, layout.normal_bits) == testing::cornerMultiset(q, layout.normal_bits));
  }
}

TEST_P(DataRoundTrip, KdtreeIsLosslessAfterQuantization) {
  expectLosslessAfterQuantization(GetParam(), CodecId::kKdtree, {12, 16, 20});
}

TEST_P(DataRoundTrip, OctreeIsLosslessAfterQuantization) {
  expectLosslessAfterQuantization(GetParam(), CodecId::kOctree, {12, 16, 24});
}

TEST_P(DataRoundTrip, EdgebreakerIsLosslessAfterQuantization) {
  expectLosslessAfterQuantization(GetParam(), CodecId::kEdgebreaker, {12, 16});
}

// Every level of both progressive codecs decodes within the limits the index sets (a coarse octree level shows the
// cliques of its vertex graph, bounded by the index's counts: see octree.cpp), and says what it means.
TEST_P(DataRoundTrip, EveryLevelDecodesWithinTheIndexLimits) {
  const Scan& scan = GetParam();
  const std::string path = testing::sharedDataDir() + "/" + scan.file;
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared data not found: " << path << " (set SCANPRESS_DATA)";
#if defined(__SANITIZE_ADDRESS__)
  if (scan.triangles > 60000)
    GTEST_SKIP() << "large scan skipped in the unoptimized sanitizer build; the Release suite decodes it";
#endif
  auto mesh = readMeshFile(path);
  ASSERT_TRUE(mesh.isOk()) << mesh.status().toString();
  const AttributeLayout layout = layoutOf(*mesh);
  auto grid = makeGrid(boundingBox(*mesh), 12);
  ASSERT_TRUE(grid.isOk());
  auto q = quantizeMesh(*mesh, *grid, layout, nullptr);
  ASSERT_TRUE(q.isOk());
  for (CodecId id : {CodecId::kKdtree, CodecId::kOctree}) {
    SCOPED_TRACE(findCodec(id)->name);
    const QuantizedMesh tiles[] = {*q};
    auto bytes = encodeContainer(*grid, layout, *findCodec(id), tiles);
    ASSERT_TRUE(bytes.isOk());
    auto pc = parseContainer(*bytes, scan.file);
    ASSERT_TRUE(pc.isOk());
    const TileEntry& e = pc->tiles.at(0);
    auto payload = parseTileChunk(std::span(*bytes).subspan(e.offset, e.chunk_bytes), e, scan.file);
    ASSERT_TRUE(payload.isOk());
    auto levels = tilePayloadLevels(pc->header, e, *payload, scan.file);
    ASSERT_TRUE(levels.isOk());
    double most = 0;
    for (const CodecLevel& lv : *levels) {
      bool complete = false;
      auto m = decodeTilePayload(pc->header, e, *payload, scan.file, lv.level, &complete);
      ASSERT_TRUE(m.isOk()) << "level " << lv.level << ": " << m.status().toString();
      EXPECT_EQ(complete, lv.complete);
      EXPECT_LE(m->positions.size(), e.vertices);
      most = std::max(most, double(m->triangles.size()) / double(e.vertices + e.faces));
    }
    RecordProperty(std::string(findCodec(id)->name) + "_most_triangles_per_element", std::to_string(most));
    EXPECT_LT(most, 1.0);  // far inside the decoder's bound of 4
  }
}

// Through files and the commands: encode, decode to PLY, read back, requantize on the container's grid.
TEST_P(DataRoundTrip, ThroughFilesWithTheCommands) {
  const Scan& scan = GetParam();
  const std::string path = testing::sharedDataDir() + "/" + scan.file;
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared data not found: " << path << " (set SCANPRESS_DATA)";
  testing::TempDir dir;
  for (int bits : {16, 24}) {
    SCOPED_TRACE(bits);
    EncodeSettings es;
    es.input = path;
    es.output = dir.file("x.spz");
    es.bits = bits;
    auto enc = encodeFile(es);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    EXPECT_EQ(enc->faces + enc->quantize.degenerate_triangles, scan.triangles);
    EXPECT_EQ(enc->bytes, std::filesystem::file_size(es.output));

    ContainerHeader header;
    auto decoded = decodeContainer(es.output, std::nullopt, &header);
    ASSERT_TRUE(decoded.isOk());
    auto original = readMeshFile(path);
    ASSERT_TRUE(original.isOk());
    auto expected = quantizeMesh(*original, header.grid, header.layout, nullptr);
    ASSERT_TRUE(expected.isOk());
    const int nb = header.layout.normal_bits;
    const auto want = testing::cornerMultiset(*expected, nb);
    EXPECT_TRUE(testing::cornerMultiset(*decoded, nb) == want);

    DecodeSettings ds;
    ds.input = es.output;
    ds.output = dir.file("x.ply");
    auto dec = decodeFile(ds);
    ASSERT_TRUE(dec.isOk()) << dec.status().toString();
    auto reread = readMeshFile(ds.output);
    ASSERT_TRUE(reread.isOk());
    auto requantized = quantizeMesh(*reread, header.grid, header.layout, nullptr);
    ASSERT_TRUE(requantized.isOk());
    EXPECT_TRUE(testing::cornerMultiset(*requantized, nb) == want) << "decoded file does not requantize exactly";
  }
}

INSTANTIATE_TEST_SUITE_P(Scans, DataRoundTrip, ::testing::ValuesIn(kScans),
                         [](const ::testing::TestParamInfo<Scan>& info) {
  std::string n = info.param.file;
  for (char& c : n)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return n;
});

TEST(BundledScan, ReadsAndRoundTrips) {
  const std::string path = std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
  testing::TempDir dir;
  EncodeSettings es;
  es.input = path;
  es.output = dir.file("b.spz");
  auto enc = encodeFile(es);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  EXPECT_EQ(enc->read.vertices, 35947u);
  EXPECT_EQ(enc->quantize.unreferenced_vertices, 1113u);
  EXPECT_EQ(enc->faces, 69451u);
  auto decoded = decodeContainer(es.output, std::vector<uint32_t>{0});
  ASSERT_TRUE(decoded.isOk());
  EXPECT_EQ(decoded->triangles.size(), 69451u);
}

}  // namespace
}  // namespace scanpress
