#include <gtest/gtest.h>

#include <bit>

#include <zstd.h>

#include <algorithm>
#include <cstring>

#include "jobs/mesh_io/input.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs_util.h"

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
  std::string s =
      "ply\nformat binary_little_endian 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
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
  // As the file has the vertices (no wedges: a vertex's normal is its first corner's).
  auto as_in_file = readMeshFile(p, &stats, ReadOptions::asInFile());
  ASSERT_TRUE(as_in_file.isOk()) << as_in_file.status().toString();
  Mesh m = *as_in_file;
  ASSERT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.colors[1], (Rgba8{0, 255, 0, 255}));
  ASSERT_EQ(m.triangles.size(), 5u);
  EXPECT_EQ(m.triangles[2], (Triangle{0, 1, 3}));
  ASSERT_EQ(m.normals.size(), 4u);
  EXPECT_EQ(m.normals[0], (Vec3f{0, 0, -1}));  // first corner naming vertex 1 used vn 2
  EXPECT_EQ(m.normals[2], (Vec3f{0, 0, 1}));
  EXPECT_EQ(stats.polygons, 1u);
  // With wedges (the default): each distinct (vt, vn) a vertex's corners name, `1/1`, `//2` and `1/1/1` alike, is a
  // vertex of its own (corners naming neither take the first): 3 + 2 + 2 + 3.
  Mesh w = readOk(p, &stats);
  EXPECT_EQ(w.positions.size(), 10u);
  EXPECT_EQ(w.triangles.size(), 5u);
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
  const std::string plain =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
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
    Status vertices(std::span<const Vec3d> p, std::span<const Vec3f>, std::span<const Rgba8>, uint8_t,
                    const ScalarChunk&) override {
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
    WriteOptions options;
    options.double_positions = dbl;
    ASSERT_TRUE(writePly(dir.file("o.ply"), m, options).isOk());
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
  EXPECT_EQ(writeMeshFile(dir.file("o.xyz"), m).code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(writeMeshFile(dir.file("o.stl.gz"), m).code(), ErrorCode::kInvalidArgument);
}

}  // namespace
// ---- nothing dropped silently ------------------------------------------------------------------------------

std::string droppedText(const ReadStats& stats) { return describeDropped(stats.dropped); }

// Counts what a reader delivers, keeping nothing (for the large scans).
class CountingSink : public MeshSink {
 public:
  Status vertices(std::span<const Vec3d> p, std::span<const Vec3f>, std::span<const Rgba8>, uint8_t,
                  const ScalarChunk&) override {
    return vertices_ += p.size(), Status::ok();
  }
  Status triangles(std::span<const Triangle> t) override { return triangles_ += t.size(), Status::ok(); }
  Status vertexNormals(uint64_t, std::span<const Vec3f>) override { return Status::ok(); }
  uint64_t vertices_ = 0, triangles_ = 0;
};

TEST(Readers, PlyListsEverySkippedPropertyAndElement) {
  TempDir dir;
  const std::string p = dir.file("a.ply");
  writeBytes(p,
             "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float confidence\n"
             "property float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
             "property list uchar float texcoord\nelement face 1\nproperty uchar flags\n"
             "property list uchar int vertex_indices\nproperty float quality\nelement camera 1\nproperty float f\n"
             "element empty 0\nproperty float g\nend_header\n"
             "0 0.5 0 0 1 2 3 2 0.1 0.2\n1 0.5 0 0 1 2 3 0\n7 3 0 1 1 0.25\n1.5\n");
  ReadStats stats;
  Mesh m = readOk(p, &stats);
  EXPECT_EQ(m.triangles.size(), 1u);
  // Kept roles (x, y, z, colors, indices, vertex scalars) are not listed; an element with no records drops nothing.
  EXPECT_EQ(droppedText(stats), "vertex.texcoord x 2, face.flags x 1, face.quality x 1, element camera x 1");
  ASSERT_EQ(m.scalar_channels, (std::vector<ScalarChannel>{{"confidence", ScalarType::kFloat32}}));
  EXPECT_EQ(m.scalars, (ScalarValues{std::bit_cast<uint32_t>(0.5f), std::bit_cast<uint32_t>(0.5f)}));
}

// Vertex scalars of every type come back bit for bit from ASCII (the text rounded once, at the property's type)
// and from binary of both byte orders (the bytes as they are: NaN payloads, -0, subnormals); an integer out of its
// type's range is an error that names the line.
TEST(Readers, PlyKeepsVertexScalarsAtTheirTypeBitForBit) {
  TempDir dir;
  const std::string header_props =
      "property float x\nproperty float y\nproperty float z\nproperty char s1\nproperty uchar s2\n"
      "property short s3\nproperty ushort s4\nproperty int s5\nproperty uint s6\nproperty float s7\n"
      "property double s8\n";
  const std::string ascii_path = dir.file("a.ply");
  writeBytes(ascii_path, "ply\nformat ascii 1.0\nelement vertex 3\n" + header_props +
                             "end_header\n"
                             "0 0 0 -128 255 -32768 65535 -2147483648 4294967295 0.850855 0.1\n"
                             "1 0 0 127 0 32767 0 2147483647 0 -0 -0\n"
                             "0 1 0 0 7 -1 1 -1 1 1e-45 1e-320\n");
  Mesh a = readOk(ascii_path);
  ASSERT_EQ(a.scalar_channels.size(), 8u);
  EXPECT_EQ(a.scalar_channels[7], (ScalarChannel{"s8", ScalarType::kFloat64}));
  const auto d = [](double v) {
    const uint64_t b = std::bit_cast<uint64_t>(v);
    return std::array<uint32_t, 2>{uint32_t(b), uint32_t(b >> 32)};
  };
  const ScalarValues want = {0x80u,
                             255u,
                             0x8000u,
                             65535u,
                             0x80000000u,
                             0xFFFFFFFFu,
                             std::bit_cast<uint32_t>(0.850855f),
                             d(0.1)[0],
                             d(0.1)[1],
                             127u,
                             0u,
                             32767u,
                             0u,
                             0x7FFFFFFFu,
                             0u,
                             0x80000000u,
                             d(-0.0)[0],
                             d(-0.0)[1],
                             0u,
                             7u,
                             0xFFFFu,
                             1u,
                             0xFFFFFFFFu,
                             1u,
                             std::bit_cast<uint32_t>(1e-45f),
                             d(1e-320)[0],
                             d(1e-320)[1]};
  EXPECT_EQ(a.scalars, want);
  // Binary, both byte orders, with a signalling NaN's payload in the float and the double.
  for (bool big : {false, true}) {
    std::string s = std::string("ply\nformat ") + (big ? "binary_big_endian" : "binary_little_endian") +
                    " 1.0\nelement vertex 1\n" + header_props + "end_header\n";
    auto put = [&](auto v) { s += bin(v, big); };
    put(0.f), put(1.f), put(2.f);
    put(int8_t(-5)), put(uint8_t(200)), put(int16_t(-300)), put(uint16_t(60000)), put(int32_t(-70000)),
        put(uint32_t(3000000000u)), put(std::bit_cast<float>(0x7F800123u)),
        put(std::bit_cast<double>(0xFFF0000000000ABCull));
    const std::string path = dir.file(big ? "b.ply" : "l.ply");
    writeBytes(path, s);
    Mesh m = readOk(path);
    EXPECT_EQ(m.scalars, (ScalarValues{0xFBu, 200u, uint32_t(uint16_t(-300)), 60000u, uint32_t(-70000), 3000000000u,
                                       0x7F800123u, 0xABCu, 0xFFF00000u}))
        << (big ? "big endian" : "little endian");
  }
  writeBytes(ascii_path,
             "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
             "property float z\nproperty uchar q\nend_header\n0 0 0 256\n");
  ReadStats stats;
  auto bad = readMeshFile(ascii_path, &stats);
  ASSERT_FALSE(bad.isOk());
  EXPECT_NE(bad.status().message().find("property 'q'"), std::string::npos) << bad.status().toString();
  EXPECT_NE(bad.status().message().find("a.ply:9:"), std::string::npos) << bad.status().toString();
}

TEST(Readers, ObjListsTextureCoordinatesMaterialsAndOtherRecords) {
  TempDir dir;
  const std::string p = dir.file("m.obj");
  writeBytes(p,
             "# comment\nmtllib x.mtl\no thing\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0 0.5\nvt 0 0\nvt 1 0\nvt 1 1\n"
             "vn 0 0 1\nvn 0 0 -1\nvn 1 0 0\ns off\nusemtl a\nf 1/1/1 2/2/1 3/3/1\nusemtl b\ns 1\n"
             "f 1/1/2 3/3/2 4/1/2\n");
  ReadStats stats;
  Mesh m = readOk(p, &stats);
  EXPECT_EQ(m.triangles.size(), 2u);
  // "s off" states nothing; vn 3 is named by no face; vertices 1 and 3 have normal 1, then a corner names 2.
  // Texture coordinates and normals per corner are kept (wedges: vertices 1 and 3 get a second, for normal 2).
  // Two materials: the library is kept, no material.
  EXPECT_EQ(droppedText(stats),
            "obj o x 1, obj s x 1, obj usemtl (several materials or faces without one: none is "
            "kept) x 2, obj vn unused x 1, obj v w x 1");
  EXPECT_EQ(stats.materials.library, "x.mtl");
  EXPECT_EQ(stats.materials.material, "");
  EXPECT_EQ(m.positions.size(), 6u);
  // Without them (ReadOptions off: a codec that simplifies), `vt` and the second normals are listed.
  {
    Mesh off;
    MeshCollector sink(off);
    ReadOptions no_uv;
    no_uv.texture_coordinates = false;
    no_uv.corner_normals = false;
    auto read = readMesh(p, sink, no_uv);
    ASSERT_TRUE(read.isOk()) << read.status().toString();
    EXPECT_EQ(droppedText(*read),
              "obj o x 1, obj vt x 3, obj s x 1, obj usemtl (several materials or faces without one: none is "
              "kept) x 2, obj vn unused x 1, obj vn per corner x 2, obj v w x 1");
    EXPECT_TRUE(off.scalar_channels.empty());
  }

  // A plain OBJ drops nothing.
  writeBytes(p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n");
  readOk(p, &stats);
  EXPECT_TRUE(stats.dropped.empty()) << droppedText(stats);

  // Distinct keywords are capped: a hostile file cannot grow the list without bound.
  std::string many = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  for (int i = 0; i < 1000; ++i) many += "kw" + std::to_string(i) + " 1\n";
  writeBytes(p, many);
  readOk(p, &stats);
  ASSERT_EQ(stats.dropped.size(), 33u);
  EXPECT_EQ(stats.dropped.back().name, "obj records of other kinds");
  EXPECT_EQ(stats.dropped.back().count, 968u);
}

TEST(Readers, OffListsFaceColorsAndStlFacetAttributes) {
  TempDir dir;
  const std::string p = dir.file("m.off");
  writeBytes(p, "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0 9\n3 0 1 2\n4 0 1 2 3 255 0 0\n");
  ReadStats stats;
  readOk(p, &stats);
  EXPECT_EQ(droppedText(stats), "off vertex extra values x 1, off face colors x 1");
  writeBytes(p, "COFF 3 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0\n0 1 0 0 0 255\n3 0 1 2\n");
  readOk(p, &stats);
  EXPECT_TRUE(stats.dropped.empty()) << droppedText(stats);

  const std::string b = dir.file("b.stl");
  std::string s(80, ' ');
  s += bin<uint32_t>(2);
  const float tris[2][9] = {{0, 0, 0, 1, 0, 0, 0, 1, 0}, {1, 0, 0, 1, 1, 0, 0, 1, 0}};
  for (int i = 0; i < 2; ++i) {
    s += std::string(12, '\0');
    for (float c : tris[i]) s += bin<float>(c);
    s += bin<uint16_t>(i == 0 ? 0x7C00 : 0);  // a VisCAM color on the first facet
  }
  writeBytes(b, s);
  readOk(b, &stats);
  EXPECT_EQ(droppedText(stats), "stl facet attribute x 1");
}

// The real scans: bun_zipper's confidence and intensity, lato000's camera element and vertex and face flags and
// quality, horse's confidence.
TEST(Readers, ScansListWhatTheyDrop) {
  const std::string data = testing::sharedDataDir();
  if (!std::filesystem::exists(data + "/lato000.ply.zst")) GTEST_SKIP() << "no " << data;
  const std::pair<const char*, const char*> cases[] = {
      {"bun_zipper.ply.zst", ""},
      {"lato000.ply.zst", "element camera x 1, face.flags x 86766, face.quality x 86766"},
      {"horse.ply.zst", ""},
      {"igea.ply.zst", ""}};
  for (const auto& [name, expected] : cases) {
    CountingSink sink;
    auto stats = readMesh(data + "/" + name, sink);
    ASSERT_TRUE(stats.isOk()) << stats.status().toString();
    EXPECT_EQ(droppedText(*stats), expected) << name;
  }
}

// ---- declared counts and limits ------------------------------------------------------------------------------

// A binary STL whose header declares fewer triangles than the file holds would lose the rest without a word.
TEST(StlReader, BinaryDataPastTheDeclaredCountIsMalformed) {
  TempDir dir;
  const std::string b = dir.file("b.stl");
  std::string s(80, ' ');
  s += bin<uint32_t>(1);
  for (int i = 0; i < 3; ++i) {
    s += std::string(12, '\0');
    for (float c : {0.f, 0.f, float(i), 1.f, 0.f, float(i), 0.f, 1.f, float(i)}) s += bin<float>(c);
    s += std::string(2, '\0');
  }
  writeBytes(b, s);
  auto r = readMeshFile(b);
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().code(), ErrorCode::kMalformed);
  EXPECT_EQ(r.status().message(),
            b + ": byte 134: binary STL declares 1 triangles, which end at byte 134, but the data goes on to byte "
                "234 (100 more bytes, 2 triangles and 0 bytes): the triangle count in the header is wrong");
  s.resize(s.size() - 7);
  writeBytes(b, s);
  r = readMeshFile(b);
  ASSERT_FALSE(r.isOk());
  EXPECT_NE(r.status().message().find("93 more bytes, 1 triangles and 43 bytes"), std::string::npos)
      << r.status().toString();
  // Compressed without a content size in the frame (streamed): still caught, at its decompressed offset.
  ZSTD_CCtx* cctx = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_contentSizeFlag, 0);
  std::string packed(ZSTD_compressBound(s.size()) + 64, '\0');
  ZSTD_outBuffer out{packed.data(), packed.size(), 0};
  ZSTD_inBuffer in{s.data(), s.size(), 0};
  ASSERT_EQ(ZSTD_compressStream2(cctx, &out, &in, ZSTD_e_end), 0u);
  ZSTD_freeCCtx(cctx);
  packed.resize(out.pos);
  writeBytes(b + ".zst", packed);
  r = readMeshFile(b + ".zst");
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().message(), b + ".zst: byte 134 of the decompressed data: binary STL declares 1 triangles, "
                                      "which end at byte 134, but the data goes on: the triangle count in the "
                                      "header is wrong");
}

// The 16 MiB line limit of the text readers holds for every line, also one the buffer could hold and the last one.
TEST(Readers, TextLinesLongerThan16MiBFailNamingTheLine) {
  TempDir dir;
  const std::string p = dir.file("long.obj");
  const std::string long_comment = "#" + std::string(Scanner::kMaxLine, 'x');  // one byte past the limit
  writeBytes(p, "v 0 0 0\n" + long_comment + "\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  auto r = readMeshFile(p);
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().code(), ErrorCode::kLimitExceeded);
  EXPECT_EQ(r.status().message(), p + ":2: line longer than 16 MiB (the limit for text formats)");
  writeBytes(p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n" + long_comment);  // the last line, unterminated
  r = readMeshFile(p);
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().message(), p + ":5: line longer than 16 MiB (the limit for text formats)");
  writeBytes(p, "v 0 0 0\n" + long_comment.substr(1) + "\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");  // at the limit: fine
  ReadStats stats;
  readOk(p, &stats);
  EXPECT_EQ(droppedText(stats), "obj records of other kinds x 1");  // a long keyword is not kept as a name
}

}  // namespace scanpress
