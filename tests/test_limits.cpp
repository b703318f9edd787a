// The index bounds the decoder (DESIGN.md decision 10): crafted containers whose checksums are all valid, whose
// index is small and honest-looking, and whose payloads claim far more, are refused by `decode` with exit 2, a
// message naming the tile, and little memory; an index that claims more than its payload bytes can hold is
// refused when the file is opened.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>

#include "engine/container/container.h"
#include "engine/io/bytes.h"
#include "engine/io/crc32c.h"
#include "jobs_util.h"
#include "test_util.h"

namespace scanpress {
namespace {

class MemorySink : public ByteSink {
 public:
  Status append(std::span<const uint8_t> b) override {
    bytes.insert(bytes.end(), b.begin(), b.end());
    return Status::ok();
  }
  Status writeAt(uint64_t offset, std::span<const uint8_t> b) override {
    std::copy(b.begin(), b.end(), bytes.begin() + static_cast<ptrdiff_t>(offset));
    return Status::ok();
  }
  std::vector<uint8_t> bytes;
};

// A one-tile container with `payload` under an index entry of `vertices` and `faces`, every checksum valid.
std::vector<uint8_t> craft(CodecId codec, const std::vector<uint8_t>& payload, uint32_t vertices, uint32_t faces) {
  Grid grid;
  grid.bits = 12;
  grid.cell = 1.0 / 4096;
  MemorySink sink;
  ContainerWriter writer(sink, grid, AttributeLayout{});
  EXPECT_TRUE(writer.begin().isOk());
  TileSummary summary;
  summary.vertices = vertices;
  summary.faces = faces;
  summary.lo = {0, 0, 0};
  summary.hi = {9, 9, 9};
  EXPECT_TRUE(writer.addTile(7, *findCodec(codec), summary, payload).isOk());
  EXPECT_TRUE(writer.finish().isOk());
  return sink.bytes;
}

struct Outcome {
  int exit_code = -1;
  std::string output;
  uint64_t peak_rss = 0;
};

Outcome decodeWithCli(const std::vector<uint8_t>& container) {
  testing::TempDir dir;
  const std::string in = dir.file("crafted.spz"), peak = dir.file("peak.txt");
  std::ofstream(in, std::ios::binary)
      .write(reinterpret_cast<const char*>(container.data()), static_cast<std::streamsize>(container.size()));
  Outcome o;
  o.exit_code = testing::runScanpress("decode '" + in + "' '" + dir.file("out.ply") + "'", &o.output,
                                      "SCANPRESS_PEAK_RSS_FILE='" + peak + "'");
  std::ifstream(peak) >> o.peak_rss;
  return o;
}

constexpr uint64_t kPeakLimit = 64ull << 20;

void expectRefused(const Outcome& o, const std::string& what) {
  EXPECT_EQ(o.exit_code, 2) << o.output;
  EXPECT_NE(o.output.find("tile 7"), std::string::npos) << o.output;
  EXPECT_NE(o.output.find(what), std::string::npos) << o.output;
#if !defined(__SANITIZE_ADDRESS__)  // shadow memory and quarantine make RSS meaningless under ASan
  EXPECT_GT(o.peak_rss, 0u);
  EXPECT_LT(o.peak_rss, kPeakLimit) << o.output;
#endif
}

TEST(IndexLimits, StorePayloadClaimingMoreVerticesThanTheIndexIsRefused) {
  for (uint32_t claimed : {1u << 26, 0xFFFFFFFFu}) {
    SCOPED_TRACE(claimed);
    // 2^26 (or 2^32 - 1) vertices at zero bits per axis fit in a 23-byte payload.
    std::vector<uint8_t> payload;
    ByteWriter w(payload);
    w.u32(claimed);
    w.u32(0);
    for (int a = 0; a < 3; ++a) w.u32(0), w.u8(0);
    expectRefused(decodeWithCli(craft(CodecId::kStore, payload, 3, 1)), "the tile index allows 3");
  }
  // One vertex and 2^26 triangles.
  std::vector<uint8_t> payload;
  ByteWriter w(payload);
  w.u32(1);
  w.u32(1u << 26);
  for (int a = 0; a < 3; ++a) w.u32(0), w.u8(0);
  expectRefused(decodeWithCli(craft(CodecId::kStore, payload, 3, 1)), "the tile index allows 3 and 1");
}

TEST(IndexLimits, HierarchyPayloadClaimingMoreVerticesThanTheIndexIsRefused) {
  for (CodecId codec : {CodecId::kKdtree, CodecId::kOctree})
    for (uint64_t claimed : {uint64_t(1) << 26, uint64_t(1) << 32}) {
      SCOPED_TRACE(std::string(findCodec(codec)->name) + " " + std::to_string(claimed));
      std::vector<uint8_t> payload;
      ByteWriter w(payload);
      w.varint(claimed);
      w.varint(1);
      payload.resize(payload.size() + 4000, 0x5A);
      expectRefused(decodeWithCli(craft(codec, payload, 3, 1)), "the tile index allows 3");
    }
}

TEST(IndexLimits, IndexClaimingMoreThanItsPayloadCanHoldIsRefused) {
  // A store payload of 23 bytes cannot hold 2^26 vertices: the floor is one bit per vertex (FORMAT.md).
  std::vector<uint8_t> payload(23, 0);
  const auto bytes = craft(CodecId::kStore, payload, 3, 1);
  // Rewrite the entry's vertex count (and the chunk header's copy) with valid checksums: through the writer, with a
  // floor-admitting payload, then patching the counts is what an attacker does; parseIndex must refuse it.
  auto patched = bytes;
  auto pc = parseContainer(patched, "mem");
  ASSERT_TRUE(pc.isOk());
  Footer f;
  {
    auto footer = parseFooter(std::span(patched).last(kFooterSize), patched.size(), "mem");
    ASSERT_TRUE(footer.isOk());
    f = *footer;
  }
  const uint32_t huge = 1u << 26;
  std::memcpy(patched.data() + f.index_offset + 8 + 24, &huge, 4);
  const uint32_t crc = crc32c(std::span(patched).subspan(f.index_offset, f.index_bytes - 4));
  std::memcpy(patched.data() + f.index_offset + f.index_bytes - 4, &crc, 4);
  // The header's totals must agree, or the index is refused for that instead.
  ContainerHeader h = pc->header;
  h.vertices = huge;
  const auto head = serializeHeader(h);
  std::copy(head.begin(), head.end(), patched.begin());
  const Outcome o = decodeWithCli(patched);
  EXPECT_EQ(o.exit_code, 2) << o.output;
  EXPECT_NE(o.output.find("tile 7 claims 67108864 vertices"), std::string::npos) << o.output;
  EXPECT_NE(o.output.find("more than codec store can code"), std::string::npos) << o.output;
}

// The encoder's own tiles are within their floors, so the writer never produces a file the reader refuses; a
// payload below the floor is refused by the writer.
TEST(IndexLimits, WriterRefusesCountsBelowTheFloor) {
  Grid grid;
  MemorySink sink;
  ContainerWriter writer(sink, grid, AttributeLayout{});
  ASSERT_TRUE(writer.begin().isOk());
  TileSummary summary;
  summary.vertices = 1u << 20;
  const std::vector<uint8_t> payload(100, 0);
  EXPECT_EQ(writer.addTile(0, *findCodec(CodecId::kStore), summary, payload).code(), ErrorCode::kInternal);
}

}  // namespace
}  // namespace scanpress

namespace scanpress {
namespace {

// Item 5's bound: the densest containers under 1 MiB that the floors admit, through every command that reads a
// container. Each is written by the encoder (so its counts are the most a payload of its size may claim, padded up
// to the floor where the codec compresses below it), and once more with its coded bytes scrambled (a hostile
// payload under a valid header and checksums, which decodes garbage for as long as it can).
constexpr uint64_t kContainerLimit = 1ull << 20;
constexpr uint64_t kCommandPeakLimit = 256ull << 20;

// The most vertices (points) or lattice vertices (plane) whose floor still fits under kContainerLimit.
uint64_t maxElements(const CodecInfo& codec, const AttributeLayout& layout, double faces_per_vertex) {
  const PayloadFloor& f = codec.floor;
  const double per_vertex = f.bits_per_vertex + 2.0 * layout.normal_bits + 8.0 * layout.color_channels +
                            faces_per_vertex * f.bits_per_face;
  return static_cast<uint64_t>((kContainerLimit - 8192 + f.slack_bytes) * 8 / per_vertex);
}

QuantizedMesh densePoints(uint64_t n, uint32_t side, const AttributeLayout& layout) {
  QuantizedMesh m;
  for (uint64_t i = 0; i < n; ++i) {
    const uint64_t c = i % (uint64_t(side) * side * side);
    m.positions.push_back({uint32_t(c % side), uint32_t(c / side % side), uint32_t(c / side / side)});
  }
  if (layout.hasNormals()) m.normals.assign(n, OctNormal{7, 9});
  if (layout.hasColors()) m.colors.assign(n, Rgba8{1, 2, 3, 255});
  return m;
}

QuantizedMesh densePlane(uint64_t n) {
  const auto w = static_cast<uint32_t>(std::sqrt(double(n)));
  QuantizedMesh m;
  for (uint32_t y = 0; y < w; ++y)
    for (uint32_t x = 0; x < w; ++x) m.positions.push_back({x, y, 0});
  for (uint32_t y = 0; y + 1 < w; ++y)
    for (uint32_t x = 0; x + 1 < w; ++x) {
      const uint32_t a = y * w + x;
      m.triangles.push_back({a, a + 1, a + w + 1});
      m.triangles.push_back({a, a + w + 1, a + w});
    }
  return m;
}

// The plane in `strips` tiles of whole rows of cells: their border rows are welded by decode.
std::vector<QuantizedMesh> planeStrips(const QuantizedMesh& plane, uint32_t strips) {
  const auto w = static_cast<uint32_t>(std::sqrt(double(plane.positions.size())));
  std::vector<QuantizedMesh> out(strips);
  for (uint32_t k = 0; k < strips; ++k) {
    const uint32_t y0 = k * (w - 1) / strips, y1 = (k + 1) * (w - 1) / strips;
    QuantizedMesh& m = out[k];
    for (uint32_t y = y0; y <= y1; ++y)
      for (uint32_t x = 0; x < w; ++x) m.positions.push_back(plane.positions[size_t(y) * w + x]);
    for (uint32_t y = 0; y < y1 - y0; ++y)
      for (uint32_t x = 0; x + 1 < w; ++x) {
        const uint32_t a = y * w + x;
        m.triangles.push_back({a, a + 1, a + w + 1});
        m.triangles.push_back({a, a + w + 1, a + w});
      }
  }
  return out;
}

struct Dense {
  std::string name;
  std::vector<uint8_t> bytes;
};

std::vector<Dense> densestContainers() {
  Grid grid;
  grid.bits = 16;
  grid.cell = 1.0 / 65536;
  std::vector<Dense> out;
  for (const auto& codec : allCodecs())
    for (int shape = 0; shape < 4; ++shape) {
      // 0: points, 1: points with normals and colors, 2: a plane of two triangles per vertex, 3: that plane in 8
      // tiles (welded by decode). store keeps
      // duplicates, so its points repeat on a 4-cell lattice (3 bits each, padded to the floor); kdtree and
      // octree merge them, so theirs are distinct.
      const AttributeLayout layout = shape == 1 ? AttributeLayout{4, 3} : AttributeLayout{};
      uint64_t n = maxElements(codec, layout, shape >= 2 ? 2.0 : 0.0);
      const uint32_t side = codec.id == CodecId::kStore ? 2 : 128;
      Result<std::vector<uint8_t>> bytes = std::vector<uint8_t>();
      // A store plane costs more than its floor (its indices take 20 bits): fewer vertices, until it fits.
      for (int attempt = 0; attempt < 3 && (attempt == 0 || bytes->size() >= kContainerLimit); ++attempt) {
        if (attempt > 0) n = uint64_t(double(n) * (kContainerLimit - 16384) / double(bytes->size()));
        QuantizedMesh m = shape >= 2 ? densePlane(n) : densePoints(n, side, layout);
        bytes = encodeContainer(grid, layout, codec, shape == 3 ? planeStrips(m, 8) : std::vector<QuantizedMesh>{m});
        if (!bytes.isOk()) break;
      }
      EXPECT_TRUE(bytes.isOk()) << bytes.status().message();
      if (!bytes.isOk()) continue;
      const std::string name = std::string(codec.name) + (shape == 0   ? "-points"
                                                          : shape == 1 ? "-attr"
                                                          : shape == 2 ? "-plane"
                                                                       : "-strips");
      EXPECT_LT(bytes->size(), kContainerLimit) << name;
      // As much as the floor lets it claim (a store plane, shrunk to fit, as much as its indices let it).
      EXPECT_GT(bytes->size(), kContainerLimit * 3 / 4) << name;
      out.push_back({name, *bytes});
      // A store payload is exactly its counts' bits: nothing to garble.
      if (codec.id == CodecId::kStore || shape == 3) continue;
      // The coded bytes scrambled past the payload's header (under 200 bytes), checksums recomputed.
      auto hostile = *bytes;
      auto parsed = parseContainer(hostile, "mem");
      EXPECT_TRUE(parsed.isOk());
      if (!parsed.isOk()) continue;
      const TileEntry& e = parsed->tiles.at(0);
      uint64_t state = 0x9E3779B97F4A7C15ull;
      for (uint64_t i = e.offset + kChunkHeaderSize + 200; i < e.offset + e.chunk_bytes - 4; ++i) {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        hostile[i] = static_cast<uint8_t>(state >> 56);
      }
      const uint64_t crc_at = e.offset + e.chunk_bytes - 4;
      const uint32_t crc = crc32c(std::span(hostile).subspan(e.offset, crc_at - e.offset));
      std::memcpy(hostile.data() + crc_at, &crc, 4);
      out.push_back({name + "-scrambled", std::move(hostile)});
    }
  return out;
}

TEST(IndexLimits, DensestContainersUnderOneMebibyteStayUnder256MiBInEveryCommand) {
  const std::vector<std::string> commands = {
      "decode '{in}' '{dir}/out.ply'", "decode --level 8 '{in}' '{dir}/out.ply'",
      "decode '{in}' '{dir}/out.obj'", "info '{in}'",
      "info --verify --json '{in}'",   "measure '{in}' '{in}'",
      "render '{in}' '{dir}/out.png'"};
  for (const Dense& d : densestContainers()) {
    testing::TempDir dir;
    const std::string in = dir.file("dense.spz"), peak = dir.file("peak.txt");
    std::ofstream(in, std::ios::binary)
        .write(reinterpret_cast<const char*>(d.bytes.data()), static_cast<std::streamsize>(d.bytes.size()));
    for (std::string command : commands) {
      if (d.name.starts_with("store") && command.find("--level") != std::string::npos) continue;  // single-rate
      for (auto [key, value] : {std::pair<std::string, std::string>{"{in}", in}, {"{dir}", dir.path()}})
        for (size_t at; (at = command.find(key)) != std::string::npos;) command.replace(at, key.size(), value);
      SCOPED_TRACE(d.name + ": " + command);
      std::string output;
      std::remove(peak.c_str());
      const int code = testing::runScanpress(command, &output, "SCANPRESS_PEAK_RSS_FILE='" + peak + "'");
      EXPECT_TRUE(code == 0 || code == 2) << code << " " << output;
      uint64_t peak_rss = 0;
      std::ifstream(peak) >> peak_rss;
#if !defined(__SANITIZE_ADDRESS__)
      EXPECT_GT(peak_rss, 0u);
      EXPECT_LT(peak_rss, kCommandPeakLimit) << output;
#endif
      std::printf("%s | %s | exit %d | peak %.1f MiB\n", d.name.c_str(), command.substr(0, command.find(' ')).c_str(),
                  code, peak_rss / 1048576.0);
    }
  }
}

}  // namespace
}  // namespace scanpress
