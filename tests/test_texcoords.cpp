// Texture coordinates (issue 22 part 1): OBJ `vt` named by faces become scalar channels u and v, with vertices split
// into wedges at texture seams (jobs/mesh_io/texcoords.h). Checked against the file itself, read by a parser of
// this test's own: every face corner comes back with its position and its texture coordinates bit for bit, through
// every codec that carries scalars, one tile or many; the OBJ writer joins the wedges' positions again (as many `v`
// lines as the input); PLY's u and v are written as `vt` and glTF's TEXCOORD_0; pm drops them and says so.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <filesystem>
#include <map>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "jobs/commands.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs/mesh_io/texcoords.h"
#include "jobs/pipeline.h"
#include "jobs_util.h"

namespace scanpress {
namespace {

using testing::TempDir;

// A UV sphere as OBJ: one `v` per position (single poles), texture coordinates (j / lon, 1 - i / lat) with a seam
// at longitude 0 (the seam's vertices have u = 0 and u = 1) and one coordinate per corner at the poles (each pole
// vertex gets `lon` wedges).
std::string uvSphereObj(int lat, int lon) {
  std::ostringstream o;
  o.precision(9);
  o << "mtllib sphere.mtl\nv 0 0 1\n";
  for (int i = 1; i < lat; ++i)
    for (int j = 0; j < lon; ++j) {
      const double th = M_PI * i / lat, ph = 2 * M_PI * j / lon;
      o << "v " << std::sin(th) * std::cos(ph) << ' ' << std::sin(th) * std::sin(ph) << ' ' << std::cos(th) << '\n';
    }
  o << "v 0 0 -1\n";
  const int vertices = 2 + (lat - 1) * lon;
  for (int i = 0; i <= lat; ++i)
    for (int j = 0; j <= lon; ++j) o << "vt " << double(j) / lon << ' ' << 1 - double(i) / lat << '\n';
  auto v = [&](int i, int j) { return i == 0 ? 1 : i == lat ? vertices : 2 + (i - 1) * lon + j % lon; };
  auto t = [&](int i, int j) { return i * (lon + 1) + j + 1; };
  o << "usemtl skin\n";
  for (int i = 0; i < lat; ++i)
    for (int j = 0; j < lon; ++j) {
      if (i > 0)
        o << "f " << v(i, j) << '/' << t(i, j) << ' ' << v(i, j + 1) << '/' << t(i, j + 1) << ' ' << v(i + 1, j + 1)
          << '/' << t(i + 1, j + 1) << '\n';
      if (i < lat - 1)
        o << "f " << v(i, j) << '/' << t(i, j) << ' ' << v(i + 1, j + 1) << '/' << t(i + 1, j + 1) << ' '
          << v(i + 1, j) << '/' << t(i + 1, j) << '\n';
    }
  return o.str();
}

// An OBJ as this test reads it: positions, texture coordinates (as float, what a reader keeps) and faces of
// (position index, vt index) corners.
struct ObjText {
  std::vector<std::array<double, 3>> v;
  std::vector<std::array<float, 2>> vt;
  std::vector<std::array<std::pair<int, int>, 3>> f;
};

ObjText parseObj(const std::string& path) {
  ObjText o;
  std::istringstream in(testing::readText(path));
  for (std::string line; std::getline(in, line);) {
    std::istringstream l(line);
    std::string word;
    l >> word;
    if (word == "v") {
      std::array<double, 3> p;
      l >> p[0] >> p[1] >> p[2];
      o.v.push_back(p);
    } else if (word == "vt") {
      double u, w;
      l >> u >> w;
      o.vt.push_back({float(u), float(w)});
    } else if (word == "f") {
      std::array<std::pair<int, int>, 3> face;
      for (auto& c : face) {
        std::string corner;
        l >> corner;
        const size_t s = corner.find('/');
        c = {std::stoi(corner.substr(0, s)) - 1, std::stoi(corner.substr(s + 1)) - 1};
      }
      o.f.push_back(face);
    }
  }
  return o;
}

// The file's faces as corners of (the index of the nearest position of `ref`, texture coordinate bits), each face
// rotated to start at its least corner, sorted. Positions farther than 1e-4 from all of ref's fail the test (the
// spheres' vertices are over 0.01 apart; the grids' cells below 1e-5).
using Corner = std::tuple<size_t, uint32_t, uint32_t>;
std::vector<std::array<Corner, 3>> cornerFaces(const ObjText& o, const ObjText& ref) {
  std::vector<size_t> nearest(o.v.size());
  for (size_t i = 0; i < o.v.size(); ++i) {
    double best = 1e300;
    for (size_t j = 0; j < ref.v.size(); ++j) {
      double d = 0;
      for (int a = 0; a < 3; ++a)
        d += (o.v[i][size_t(a)] - ref.v[j][size_t(a)]) * (o.v[i][size_t(a)] - ref.v[j][size_t(a)]);
      if (d < best) best = d, nearest[i] = j;
    }
    EXPECT_LT(std::sqrt(best), 1e-4) << "position " << i;
  }
  std::vector<std::array<Corner, 3>> faces;
  for (const auto& f : o.f) {
    std::array<Corner, 3> c;
    for (int k = 0; k < 3; ++k) {
      const auto& t = o.vt[size_t(f[size_t(k)].second)];
      c[size_t(k)] = {nearest[size_t(f[size_t(k)].first)], std::bit_cast<uint32_t>(t[0]),
                      std::bit_cast<uint32_t>(t[1])};
    }
    std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
    faces.push_back(c);
  }
  std::sort(faces.begin(), faces.end());
  return faces;
}

// The reader: a vertex per distinct coordinate of its corners, wedges right after their vertex at its position,
// faces naming the wedge of their corner's `vt`.
TEST(Texcoords, ObjReaderSplitsWedgesAtSeams) {
  TempDir dir;
  const std::string path = dir.file("s.obj");
  testing::writeBytes(path, uvSphereObj(6, 8));
  ReadStats stats;
  auto mesh = readMeshFile(path, &stats);
  ASSERT_TRUE(mesh.isOk()) << mesh.status().toString();
  const ObjText text = parseObj(path);
  ASSERT_EQ(mesh->scalar_channels,
            (std::vector<ScalarChannel>{{"u", ScalarType::kFloat32}, {"v", ScalarType::kFloat32}}));
  // 2 + 5 * 8 positions; wedges: the seam (5 rows, u = 1 beside u = 0) and the poles (8 corners each: 7 more).
  EXPECT_EQ(stats.source_vertices, 42u);
  EXPECT_EQ(mesh->positions.size(), 42u + 5 + 7 + 7);
  EXPECT_EQ(stats.vertices, mesh->positions.size());
  EXPECT_EQ(describeDropped(stats.dropped), "obj mtllib x 1, obj usemtl x 1, obj vt unused x 2");
  ASSERT_EQ(mesh->triangles.size(), text.f.size());
  for (size_t f = 0; f < text.f.size(); ++f)
    for (int k = 0; k < 3; ++k) {
      const uint32_t w = mesh->triangles[f][size_t(k)];
      const auto& [v, t] = text.f[f][size_t(k)];
      EXPECT_EQ(mesh->positions[w], (Vec3d{text.v[size_t(v)][0], text.v[size_t(v)][1], text.v[size_t(v)][2]}));
      EXPECT_EQ(mesh->scalars[2 * w], std::bit_cast<uint32_t>(text.vt[size_t(t)][0])) << "face " << f;
      EXPECT_EQ(mesh->scalars[2 * w + 1], std::bit_cast<uint32_t>(text.vt[size_t(t)][1])) << "face " << f;
    }
  // File order: each vertex's wedges follow it, at its position.
  for (size_t i = 1; i < mesh->positions.size(); ++i)
    if (mesh->positions[i] != mesh->positions[i - 1]) {
      for (size_t j = 0; j < i; ++j) EXPECT_NE(mesh->positions[j], mesh->positions[i]) << i;
    }
}

// Ugly OBJ texture coordinates: malformed records and indices fail naming the line; a relative index works; a `vt`
// third number is listed; a vertex no corner gives one gets (0, 0).
TEST(Texcoords, ObjReaderErrorsAndOddCases) {
  TempDir dir;
  const std::string path = dir.file("m.obj");
  struct Bad {
    const char* text;
    const char* message;
  };
  for (const Bad& b : {Bad{"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 x\nf 1/1 2/1 3/1\n", "m.obj:4:"},
                       Bad{"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n", "m.obj:5:"},
                       Bad{"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/0 3/1\n", "m.obj:5:"},
                       Bad{"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/q 3/1\n", "m.obj:5:"},
                       Bad{"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 nan\nf 1/1 2/1 3/1\n", "m.obj:4:"}}) {
    testing::writeBytes(path, b.text);
    auto r = readMeshFile(path);
    ASSERT_FALSE(r.isOk()) << b.text;
    EXPECT_EQ(r.status().code(), ErrorCode::kMalformed) << r.status().toString();
    EXPECT_NE(r.status().message().find(b.message), std::string::npos) << r.status().toString();
  }
  testing::writeBytes(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nvt 0.25 0.5 0.75\nvt 1 1\nf -4/-2 -3/-1 -2/-1\n");
  ReadStats stats;
  auto r = readMeshFile(path, &stats);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_EQ(describeDropped(stats.dropped), "obj vt w x 1");
  ASSERT_EQ(r->positions.size(), 4u);
  EXPECT_EQ(r->scalars, (ScalarValues{std::bit_cast<uint32_t>(0.25f), std::bit_cast<uint32_t>(0.5f),
                                      std::bit_cast<uint32_t>(1.f), std::bit_cast<uint32_t>(1.f),
                                      std::bit_cast<uint32_t>(1.f), std::bit_cast<uint32_t>(1.f), 0, 0}));
}

EncodeSettings settingsFor(const std::string& in, const std::string& out, const std::string& codec) {
  EncodeSettings s;
  s.input = in;
  s.output = out;
  s.codec = codec;
  s.threads = 2;
  s.bits = 20;
  return s;
}

// Through encode and decode, every codec that carries scalars, one tile and many (welded across tiles), in memory
// and out of core: the decoded OBJ's faces are the input's, corner by corner (positions to the grid, texture
// coordinates bit for bit), with as many `v` lines as the input.
TEST(Texcoords, SeamsSurviveEncodeAndDecode) {
  TempDir dir;
  const std::string in = dir.file("sphere.obj");
  testing::writeBytes(in, uvSphereObj(24, 48));
  const ObjText want = parseObj(in);
  struct Case {
    const char* codec;
    uint64_t tile_triangles;
    uint64_t memory_budget;
  };
  for (const Case& c : {Case{"edgebreaker", 1u << 20, 0}, Case{"edgebreaker", 300, 0}, Case{"kdtree", 300, 0},
                        Case{"octree", 1u << 20, 0}, Case{"store", 300, 0}, Case{"kdtree", 300, uint64_t(4) << 20}}) {
    SCOPED_TRACE(std::string(c.codec) + ", " + std::to_string(c.tile_triangles) + " triangles per tile" +
                 (c.memory_budget ? ", out of core" : ""));
    EncodeSettings s = settingsFor(in, dir.file("s.spz"), c.codec);
    s.tile_triangles = c.tile_triangles;
    s.memory_budget = c.memory_budget;
    auto enc = encodeFile(s);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    EXPECT_EQ(describeDropped(enc->read.dropped), "obj mtllib x 1, obj usemtl x 1, obj vt unused x 2");
    ASSERT_TRUE(findTexcoords(enc->layout.scalars).has_value());
    if (c.tile_triangles < 1000) {
      EXPECT_GT(enc->tiles.size(), 4u);
    }
    DecodeSettings d;
    d.input = s.output;
    d.output = dir.file("out.obj");
    auto dec = decodeFile(d);
    ASSERT_TRUE(dec.isOk()) << dec.status().toString();
    EXPECT_TRUE(dec->dropped.empty()) << describeDropped(dec->dropped);
    const ObjText got = parseObj(d.output);
    EXPECT_EQ(got.v.size(), want.v.size());
    EXPECT_TRUE(cornerFaces(got, want) == cornerFaces(want, want));
  }
}

// pm simplifies (it would open the seams): the vertices are read as they are and `vt` is listed dropped; --no-scalars
// likewise. PLY's u and v are the same channels: an OBJ output writes them as `vt`, and lists only the others.
TEST(Texcoords, DroppedBySimplifyingCodecsAndWrittenFromPly) {
  TempDir dir;
  const std::string in = dir.file("sphere.obj");
  testing::writeBytes(in, uvSphereObj(12, 24));
  for (const bool pm : {true, false}) {
    EncodeSettings s = settingsFor(in, dir.file("p.spz"), pm ? "pm" : "kdtree");
    s.keep_scalars = pm;
    auto enc = encodeFile(s);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    EXPECT_TRUE(enc->layout.scalars.empty());
    EXPECT_EQ(enc->read.source_vertices, enc->read.vertices);
    EXPECT_NE(describeDropped(enc->read.dropped).find("obj vt x 325"), std::string::npos)
        << describeDropped(enc->read.dropped);
  }

  // A PLY with u, v and a third channel, decoded to OBJ and to STL.
  auto sphere = readMeshFile(in);
  ASSERT_TRUE(sphere.isOk());
  Mesh m = *sphere;
  m.scalar_channels.push_back({"confidence", ScalarType::kUint8});
  ScalarValues words;
  for (size_t i = 0; i < m.positions.size(); ++i)
    words.insert(words.end(), {m.scalars[2 * i], m.scalars[2 * i + 1], uint32_t(i % 200)});
  m.scalars = words;
  const std::string ply = dir.file("s.ply");
  ASSERT_TRUE(writePly(ply, m).isOk());
  EncodeSettings s = settingsFor(ply, dir.file("q.spz"), "edgebreaker");
  ASSERT_TRUE(encodeFile(s).isOk());
  DecodeSettings d;
  d.input = s.output;
  d.output = dir.file("q.obj");
  auto dec = decodeFile(d);
  ASSERT_TRUE(dec.isOk()) << dec.status().toString();
  EXPECT_EQ(describeDropped(dec->dropped), "vertex.confidence x " + std::to_string(dec->vertices));
  const ObjText want = parseObj(in);
  EXPECT_TRUE(cornerFaces(parseObj(d.output), want) == cornerFaces(want, want));
  d.output = dir.file("q.stl");
  dec = decodeFile(d);
  ASSERT_TRUE(dec.isOk());
  const std::string n = std::to_string(dec->vertices);
  EXPECT_EQ(describeDropped(dec->dropped), "vertex.u x " + n + ", vertex.v x " + n + ", vertex.confidence x " + n);
  // Under a memory budget the decode streams and writes no scalars: refused for OBJ output, which would keep them.
  d.output = dir.file("r.obj");
  d.memory_budget = 1;
  dec = decodeFile(d);
  ASSERT_FALSE(dec.isOk());
  EXPECT_EQ(dec.status().code(), ErrorCode::kUnsupported);
  EXPECT_NE(dec.status().message().find("texture coordinates"), std::string::npos) << dec.status().toString();
  EXPECT_FALSE(std::filesystem::exists(d.output));
}

}  // namespace
}  // namespace scanpress
