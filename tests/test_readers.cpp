#include <gtest/gtest.h>

#include <zstd.h>

#include <algorithm>
#include <cstring>

#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "test_util.h"

namespace scanpress {
namespace {

using testing::TempDir;
using testing::writeBytes;

template <typename T>
std::string bin(T v, bool big = false) {
  return testing::bytesOf(v, big);
}

Mesh readOk(const std::string& path, ReadStats* stats = nullptr) {
  auto r = readMeshFile(path, stats);
  EXPECT_TRUE(r.isOk()) << r.status().toString();
  return r.isOk() ? *r : Mesh();
}

TEST(PlyReader, AsciiWithNormalsColorsSkippedPropertiesAndPolygon) {
  TempDir dir;
  const std::string p = dir.file("a.ply");
  writeBytes(p,
             "ply\r\nformat ascii 1.0\r\ncomment hi\r\nelement vertex 4\r\n"
             "property float confidence\r\nproperty double z\r\nproperty float y\r\nproperty float x\r\n"
             "property float nx\r\nproperty float ny\r\nproperty float nz\r\n"
             "property uchar red\r\nproperty uchar green\r\nproperty uchar blue\r\n"
             "element face 1\r\nproperty uchar flags\r\nproperty list uchar int vertex_indices\r\n"
             "element camera 1\r\nproperty float f\r\nend_header\r\n"
             "0.5 3 2 1 0 0 1 10 20 30\r\n0.5 0 0 0 0 0 1 1 2 3\r\n0.5 0 1 0 0 1 0 4 5 6\r\n"
             "0.5 1 1 1 1 0 0 7 8 9\r\n"
             "9 4 0 1 2 3\r\n1.5\r\n");
  ReadStats stats;
  Mesh m = readOk(p, &stats);
  ASSERT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.positions[0], (Vec3d{1, 2, 3}));  // property order x/y/z reversed in the file
  EXPECT_EQ(m.normals[2], (Vec3f{0, 1, 0}));
  EXPECT_EQ(m.colors[0], (Rgba8{10, 20, 30, 255}));
  EXPECT_EQ(m.color_channels, 3);
  ASSERT_EQ(m.triangles.size(), 2u);  // quad fan-triangulated
  EXPECT_EQ(m.triangles[0], (Triangle{0, 1, 2}));
  EXPECT_EQ(m.triangles[1], (Triangle{0, 2, 3}));
  EXPECT_EQ(stats.polygons, 1u);
  EXPECT_EQ(stats.format_detail, "PLY ascii");
}

std::string binaryPly(bool big) {
  std::string h = std::string("ply\nformat ") + (big ? "binary_big_endian" : "binary_little_endian") +
                  " 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\n"
                  "property float red\nproperty float green\nproperty float blue\nproperty float alpha\n"
                  "element face 1\nproperty list ushort uint vertex_index\nproperty int flags\nend_header\n";
  for (int i = 0; i < 3; ++i) {
    h += bin<double>(i, big) + bin<double>(i * 2, big) + bin<double>(0.25, big);
    h += bin<float>(1.0f, big) + bin<float>(0.5f, big) + bin<float>(0.0f, big) + bin<float>(1.0f, big);
  }
  h += bin<uint16_t>(3, big) + bin<uint32_t>(2, big) + bin<uint32_t>(1, big) + bin<uint32_t>(0, big) +
       bin<int32_t>(-7, big);
  return h;
}

TEST(PlyReader, BinaryBothEndiansDoublePositionsFloatColors) {
  TempDir dir;
  for (bool big : {false, true}) {
    const std::string p = dir.file(big ? "be.ply" : "le.ply");
    writeBytes(p, binaryPly(big));
    Mesh m = readOk(p);
    ASSERT_EQ(m.positions.size(), 3u);
    EXPECT_EQ(m.positions[2], (Vec3d{2, 4, 0.25}));
    EXPECT_EQ(m.colors[1], (Rgba8{255, 128, 0, 255}));
    EXPECT_EQ(m.color_channels, 4);
    ASSERT_EQ(m.triangles.size(), 1u);
    EXPECT_EQ(m.triangles[0], (Triangle{2, 1, 0}));
  }
}

TEST(PlyReader, TristripsWithRestarts) {
  TempDir dir;
  const std::string p = dir.file("s.ply");
  std::string s = "ply\nformat binary_little_endian 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
                  "property float z\nelement tristrips 1\nproperty list int int vertex_indices\nend_header\n";
  for (int i = 0; i < 6; ++i) s += bin<float>(i) + bin<float>(i % 2) + bin<float>(0);
  for (int v : {8, 0, 1, 2, 3, -1, 3, 4, 5}) s += bin<int32_t>(v);
  writeBytes(p, s);
  Mesh m = readOk(p);
  ASSERT_EQ(m.triangles.size(), 3u);
  EXPECT_EQ(m.triangles[0], (Triangle{0, 1, 2}));
  EXPECT_EQ(m.triangles[1], (Triangle{2, 1, 3}));  // odd triangle flipped
  EXPECT_EQ(m.triangles[2], (Triangle{3, 4, 5}));  // restart
}

TEST(ObjReader, CornerFormsNegativeIndicesColorsAndNormals) {
  TempDir dir;
  const std::string p = dir.file("m.obj");
  writeBytes(p,
             "# comment\nmtllib x.mtl\nv 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 1 1 0 0 0 1\nv 0 1 0 1 1 1\n"
             "vt 0 0\nvn 0 0 1\nvn 0 0 -1\ng grp\ns off\nusemtl m\n"
             "f 1 2 3\nf 1/1 3/1 4/1\nf -4//2 -3//2 -1//2\nf 1/1/1 2/1/1 3/1/1 4/1/1\nl 1 2\n");
  ReadStats stats;
  Mesh m = readOk(p, &stats);
  ASSERT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.colors[1], (Rgba8{0, 255, 0, 255}));
  ASSERT_EQ(m.triangles.size(), 5u);
  EXPECT_EQ(m.triangles[2], (Triangle{0, 1, 3}));
  ASSERT_EQ(m.normals.size(), 4u);
  EXPECT_EQ(m.normals[0], (Vec3f{0, 0, -1}));  // first corner naming vertex 1 used vn 2
  EXPECT_EQ(m.normals[2], (Vec3f{0, 0, 1}));
  EXPECT_EQ(stats.polygons, 1u);
}

TEST(StlReader, AsciiAndBinaryWeldBitIdenticalCorners) {
  TempDir dir;
  const std::string a = dir.file("a.stl");
  writeBytes(a,
             "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n   vertex 0 1 0\n"
             "  endloop\n endfacet\n facet normal 0 0 1\n  outer loop\n   vertex 1 0 0\n   vertex 1.0 1 0\n"
             "   vertex 0 1 0\n  endloop\n endfacet\nendsolid t\n");
  ReadStats stats;
  Mesh m = readOk(a, &stats);
  EXPECT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.triangles.size(), 2u);
  EXPECT_EQ(m.triangles[1], (Triangle{1, 3, 2}));
  EXPECT_EQ(stats.format_detail, "STL ascii");

  const std::string b = dir.file("b.stl");
  std::string s(80, ' ');
  std::memcpy(s.data(), "solid but actually binary", 25);
  s += bin<uint32_t>(2);
  const float tris[2][9] = {{0, 0, 0, 1, 0, 0, 0, 1, 0}, {1, 0, 0, 1, 1, 0, 0, 1, 0}};
  for (const auto& t : tris) {
    s += std::string(12, '\0');
    for (float c : t) s += bin<float>(c);
    s += std::string(2, '\0');
  }
  writeBytes(b, s);
  m = readOk(b, &stats);
  EXPECT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.triangles.size(), 2u);
  EXPECT_EQ(stats.format_detail, "STL binary");
  EXPECT_EQ(stats.source_vertices, 6u);
}

TEST(OffReader, PlainAndColoredWithComments) {
  TempDir dir;
  const std::string p = dir.file("m.off");
  writeBytes(p, "OFF\n# c\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n4 0 1 2 3 255 0 0\n");
  Mesh m = readOk(p);
  EXPECT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.triangles.size(), 3u);
  const std::string c = dir.file("c.off");
  writeBytes(c, "COFF 3 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n0 1 0 0.0 0.0 1.0 1.0\n3 0 1 2\n");
  m = readOk(c);
  EXPECT_EQ(m.colors[0], (Rgba8{255, 0, 0, 255}));
  EXPECT_EQ(m.colors[2], (Rgba8{0, 0, 255, 255}));
}

TEST(Readers, ZstdCompressedInputAndContentSniffing) {
  TempDir dir;
  const std::string plain = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                            "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                            "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  std::string packed(ZSTD_compressBound(plain.size()), '\0');
  packed.resize(ZSTD_compress(packed.data(), packed.size(), plain.data(), plain.size(), 3));
  writeBytes(dir.file("m.ply.zst"), packed);
  writeBytes(dir.file("noext"), packed);  // format found from the content
  for (const char* name : {"m.ply.zst", "noext"}) {
    Mesh m = readOk(dir.file(name));
    EXPECT_EQ(m.positions.size(), 3u);
    EXPECT_EQ(m.triangles.size(), 1u);
  }
}

TEST(Readers, StreamingDeliversBoundedChunksVerticesFirst) {
  TempDir dir;
  const std::string p = dir.file("grid.obj");
  std::string s;
  const int n = 60;
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) s += "v " + std::to_string(x) + " " + std::to_string(y) + " 0\n";
  for (int y = 0; y + 1 < n; ++y)
    for (int x = 0; x + 1 < n; ++x) {
      const int a = y * n + x + 1;
      s += "f " + std::to_string(a) + " " + std::to_string(a + 1) + " " + std::to_string(a + n + 1) + " " +
           std::to_string(a + n) + "\n";
    }
  writeBytes(p, s);
  struct CountingSink : MeshSink {
    size_t max_chunk = 0, vertex_count = 0, triangle_count = 0;
    bool order_ok = true;
    Status vertices(std::span<const Vec3d> p, std::span<const Vec3f>, std::span<const Rgba8>, uint8_t) override {
      max_chunk = std::max(max_chunk, p.size());
      vertex_count += p.size();
      return Status::ok();
    }
    Status triangles(std::span<const Triangle> t) override {
      max_chunk = std::max(max_chunk, t.size());
      for (const auto& tri : t)
        for (uint32_t v : tri) order_ok &= v < vertex_count;
      triangle_count += t.size();
      return Status::ok();
    }
    Status vertexNormals(uint64_t, std::span<const Vec3f>) override { return Status::ok(); }
  } sink;
  ReadOptions opt;
  opt.chunk = 500;
  auto r = readMesh(p, sink, opt);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_EQ(sink.vertex_count, size_t(n * n));
  EXPECT_EQ(sink.triangle_count, size_t(2 * (n - 1) * (n - 1)));
  EXPECT_LE(sink.max_chunk, 500u);
  EXPECT_TRUE(sink.order_ok);
}

TEST(Writers, PlyAndObjRoundTripThroughReaders) {
  TempDir dir;
  Mesh m = testing::octahedron(1.5);
  for (size_t i = 0; i < m.positions.size(); ++i) {
    m.normals.push_back({0, 0, 1});
    m.colors.push_back({static_cast<uint8_t>(i * 30), 2, 3, 255});
  }
  m.color_channels = 3;
  for (bool dbl : {false, true}) {
    ASSERT_TRUE(writePly(dir.file("o.ply"), m, {dbl}).isOk());
    Mesh r = readOk(dir.file("o.ply"));
    EXPECT_EQ(r.positions, m.positions);
    EXPECT_EQ(r.normals, m.normals);
    EXPECT_EQ(r.colors, m.colors);
    EXPECT_EQ(r.triangles, m.triangles);
  }
  ASSERT_TRUE(writeObj(dir.file("o.obj"), m).isOk());
  Mesh r = readOk(dir.file("o.obj"));
  EXPECT_EQ(r.positions, m.positions);
  EXPECT_EQ(r.normals, m.normals);
  EXPECT_EQ(r.colors, m.colors);
  EXPECT_EQ(r.triangles, m.triangles);
  EXPECT_EQ(writeMeshFile(dir.file("o.stl"), m).code(), ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace scanpress
