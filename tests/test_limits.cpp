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
  EXPECT_TRUE(writer.addTile(7, *findCodec(codec), summary, payload, findCodec(codec)->version).isOk());
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
  EXPECT_EQ(writer.addTile(0, *findCodec(CodecId::kStore), summary, payload, 1).code(), ErrorCode::kInternal);
}

}  // namespace
}  // namespace scanpress

namespace scanpress {
namespace {}  // namespace
}  // namespace scanpress
