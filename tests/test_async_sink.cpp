// AsyncSink (jobs/mesh_io/async_sink.h): the wrapped sink sees exactly the calls a direct read makes, in order
// (vertices, triangles, and OBJ's late vertexNormals), at any queue depth and chunk size; the sink's error or
// exception stops the read with that error and nothing is delivered after it; destruction without finish() does
// not hang.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <stdexcept>
#include <string>
#include <vector>

#include "jobs/mesh_io/async_sink.h"
#include "test_util.h"

namespace scanpress {
namespace {

// Appends a separator and a number (GCC 12 warns, wrongly, about `"," + std::to_string(x)`).
template <typename T>
void put(std::string& e, char separator, T value) {
  e += separator;
  e += std::to_string(value);
}

// Writes down every call, with its data.
class RecordingSink : public MeshSink {
 public:
  explicit RecordingSink(int fail_at = -1, bool throw_instead = false) : fail_at_(fail_at), throw_(throw_instead) {}
  Status vertices(std::span<const Vec3d> p, std::span<const Vec3f> n, std::span<const Rgba8> c, uint8_t channels,
                  const ScalarChunk& s) override {
    std::string e("v");
    for (size_t k : {p.size(), n.size(), c.size(), size_t(channels), s.channels.size(), s.values.size()})
      put(e, '/', k);
    for (uint32_t w : s.values) put(e, '%', w);
    for (const Vec3d& v : p)
      for (double x : v) put(e, ':', x);
    for (const Vec3f& v : n) put(e, ';', v[2]);
    for (const Rgba8& v : c) put(e, '#', int(v[0]));
    return record(std::move(e));
  }
  Status triangles(std::span<const Triangle> t) override {
    std::string e("t");
    put(e, '/', t.size());
    for (const Triangle& x : t)
      for (uint32_t v : x) put(e, ':', v);
    return record(std::move(e));
  }
  Status vertexNormals(uint64_t first, std::span<const Vec3f> n) override {
    std::string e("n");
    put(e, '/', first);
    put(e, '/', n.size());
    for (const Vec3f& v : n) put(e, ':', v[0]);
    return record(std::move(e));
  }
  std::vector<std::string> calls;

 private:
  Status record(std::string e) {
    if (static_cast<int>(calls.size()) == fail_at_) {
      if (throw_) throw std::runtime_error("sink threw");
      return makeError(ErrorCode::kMalformed, "sink refused call " + std::to_string(fail_at_));
    }
    calls.push_back(std::move(e));
    return Status::ok();
  }
  int fail_at_;
  bool throw_;
};

class AsyncSinkTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // An OBJ whose faces assign normals (delivered late, through vertexNormals), and a PLY with colors.
    std::string obj;
    for (int i = 0; i < 300; ++i) obj += "v " + std::to_string(i) + " " + std::to_string(i % 7) + " 0.5\n";
    for (int i = 0; i < 3; ++i) obj += "vn 0 0 " + std::to_string(i + 1) + "\n";
    for (int i = 0; i + 2 < 300; ++i)
      obj += "f " + std::to_string(i + 1) + "//" + std::to_string(i % 3 + 1) + " " + std::to_string(i + 2) + " " +
             std::to_string(i + 3) + "\n";
    testing::writeBytes(dir_.file("a.obj"), obj);
    std::string ply =
        "ply\nformat ascii 1.0\nelement vertex 200\nproperty float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\nelement face 198\n"
        "property list uchar int vertex_indices\nend_header\n";
    for (int i = 0; i < 200; ++i) ply += std::to_string(i) + " 1 2 " + std::to_string(i % 256) + " 0 0\n";
    for (int i = 0; i < 198; ++i)
      ply += "3 " + std::to_string(i) + " " + std::to_string(i + 1) + " " + std::to_string(i + 2) + "\n";
    testing::writeBytes(dir_.file("b.ply"), ply);
  }
  testing::TempDir dir_;
};

TEST_F(AsyncSinkTest, TheSinkSeesTheCallsOfADirectRead) {
  for (const char* name : {"a.obj", "b.ply"}) {
    for (size_t chunk : {size_t(7), size_t(64), size_t(1) << 16}) {
      ReadOptions options;
      options.chunk = chunk;
      RecordingSink direct;
      ASSERT_TRUE(readMesh(dir_.file(name), direct, options).isOk());
      ASSERT_GT(direct.calls.size(), 1u);
      for (size_t depth : {size_t(1), size_t(4)}) {
        SCOPED_TRACE(std::string(name) + " chunk " + std::to_string(chunk) + " depth " + std::to_string(depth));
        RecordingSink wrapped;
        AsyncSink async(wrapped, depth);
        auto read = readMesh(dir_.file(name), async, options);
        ASSERT_TRUE(read.isOk()) << read.status().toString();
        ASSERT_TRUE(async.finish().isOk());
        EXPECT_EQ(wrapped.calls, direct.calls);
      }
    }
  }
  // The OBJ's late normals are among the calls, after the triangles.
  RecordingSink direct;
  ASSERT_TRUE(readMesh(dir_.file("a.obj"), direct).isOk());
  EXPECT_EQ(direct.calls.back().substr(0, 1), "n");
}

TEST_F(AsyncSinkTest, TheSinksErrorStopsTheReadAndNothingFollowsIt) {
  ReadOptions options;
  options.chunk = 10;
  for (bool throws : {false, true}) {
    RecordingSink wrapped(3, throws);
    AsyncSink async(wrapped, 2);
    auto read = readMesh(dir_.file("b.ply"), async, options);
    const Status finished = async.finish();
    ASSERT_FALSE(read.isOk());
    ASSERT_FALSE(finished.isOk());
    EXPECT_EQ(wrapped.calls.size(), 3u);  // the calls before the failing one, none after it
    if (!throws) {
      EXPECT_EQ(finished.code(), ErrorCode::kMalformed);
      EXPECT_NE(read.status().message().find("sink refused call 3"), std::string::npos) << read.status().toString();
    } else {
      EXPECT_NE(finished.message().find("sink threw"), std::string::npos) << finished.toString();
    }
    EXPECT_EQ(async.finish().code(), finished.code());  // finish() again: the same answer
  }
}

TEST_F(AsyncSinkTest, DestructionWithoutFinishDeliversEverything) {
  RecordingSink wrapped;
  {
    AsyncSink async(wrapped, 1);
    ASSERT_TRUE(readMesh(dir_.file("a.obj"), async).isOk());
  }
  RecordingSink direct;
  ASSERT_TRUE(readMesh(dir_.file("a.obj"), direct).isOk());
  EXPECT_EQ(wrapped.calls, direct.calls);
}

// The encode's survey keeps a mesh for its second pass unless reading the file again is cheaper: only an
// uncompressed binary PLY.
TEST_F(AsyncSinkTest, OnlyAnUncompressedBinaryPlyIsCheapToReadAgain) {
  const std::string header = "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nend_header\n";
  testing::writeBytes(dir_.file("bin.ply"), header);
  testing::writeBytes(dir_.file("bin.PLY"), header);
  testing::writeBytes(dir_.file("bin.ply.zst"), header);  // not really compressed: the name decides
  testing::writeBytes(dir_.file("late.ply"),
                      "ply\nformat ascii 1.0\ncomment format binary_little_endian\nend_header\n");
  EXPECT_TRUE(cheapToReadAgain(dir_.file("bin.ply")));
  EXPECT_TRUE(cheapToReadAgain(dir_.file("bin.PLY")));
  EXPECT_FALSE(cheapToReadAgain(dir_.file("bin.ply.zst")));
  EXPECT_FALSE(cheapToReadAgain(dir_.file("b.ply")));     // ascii
  EXPECT_FALSE(cheapToReadAgain(dir_.file("late.ply")));  // ascii; "format binary" only in a comment
  EXPECT_FALSE(cheapToReadAgain(dir_.file("a.obj")));
  EXPECT_FALSE(cheapToReadAgain(dir_.file("missing.ply")));
  // A FIFO is neither opened nor read (that would block, or take the header from the reader).
  ASSERT_EQ(::mkfifo(dir_.file("pipe.ply").c_str(), 0600), 0);
  EXPECT_FALSE(cheapToReadAgain(dir_.file("pipe.ply")));
}

}  // namespace
}  // namespace scanpress
