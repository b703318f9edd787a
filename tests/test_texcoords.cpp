// Texture coordinates (issue 22 part 1): OBJ `vt` named by faces become scalar channels u and v, with vertices split
// into wedges at texture seams (jobs/mesh_io/texcoords.h). Checked against the file itself, read by a parser of
// this test's own: every face corner comes back with its position and its texture coordinates bit for bit, through
// every codec that carries scalars, one tile or many; the OBJ writer joins the wedges' positions again (as many `v`
// lines as the input); PLY's u and v are written as `vt` and glTF's TEXCOORD_0; pm drops them and says so.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "engine/quantize.h"
#include "jobs/commands.h"
#include "jobs/container_file.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs/mesh_io/texcoords.h"
#include "jobs/pipeline.h"
#include "jobs/report.h"
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

// uvSphereObj(lat, lon) written to `dir` and read back as in the file (wedges, texture coordinates as channels).
Mesh uvSphere(const TempDir& dir, int lat, int lon) {
  testing::writeBytes(dir.file("s.obj"), uvSphereObj(lat, lon));
  auto m = readMeshFile(dir.file("s.obj"), nullptr, ReadOptions::asInFile());
  EXPECT_TRUE(m.isOk()) << m.status().toString();
  return m.isOk() ? *std::move(m) : Mesh();
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
  EXPECT_EQ(describeDropped(stats.dropped), "obj vt unused x 2");
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
  for (const Bad& b : {Bad{"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n", "m.obj:5:"},
                       Bad{"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/0 3/1\n", "m.obj:5:"},
                       Bad{"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/q 3/1\n", "m.obj:5:"}}) {
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
  // Records that are not finite numbers as float read as (0, 0), and are listed; so are corners without `vt` (one
  // naming neither takes its vertex's first wedge); normals and coordinates per corner together.
  testing::writeBytes(path,
                      "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 x\nvt 1e39 0\nvt 0.5 0.5\nvn 0 0 1\nvn 1 0 0\n"
                      "f 1/1/1 2/2/1 3/3/1\nf 1/3/2 3 2/2/2\n");
  auto odd = readMeshFile(path, &stats);
  ASSERT_TRUE(odd.isOk()) << odd.status().toString();
  EXPECT_EQ(describeDropped(stats.dropped), "obj vt malformed (read as 0 0) x 2, obj f corners without vt x 1");
  // Vertex 1: (vt 1, vn 1) and (vt 3, vn 2); vertex 2: (vt 2, vn 1) and (vt 2, vn 2); vertex 3 once (its second
  // corner names neither).
  EXPECT_EQ(odd->positions.size(), 5u);
  ASSERT_EQ(odd->normals.size(), 5u);
  EXPECT_EQ(odd->normals[0], (Vec3f{0, 0, 1}));
  EXPECT_EQ(odd->normals[1], (Vec3f{1, 0, 0}));
  EXPECT_EQ(odd->scalars[2], std::bit_cast<uint32_t>(0.5f));
  EXPECT_EQ(odd->triangles[1], (Triangle{1, 4, 3}));
  // Texture coordinates off and normals per corner on (--no-scalars): a `vt` field naming nothing is ignored by
  // both reads, the corners' normals still split.
  testing::writeBytes(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvn 1 0 0\nf 1//1 2//1 3//1\nf 1/7/2 2/7/2 3/7/2\n");
  Mesh split;
  MeshCollector sink(split);
  ReadOptions normals_only;
  normals_only.texture_coordinates = false;
  auto read = readMesh(path, sink, normals_only);
  ASSERT_TRUE(read.isOk()) << read.status().toString();
  sink.finish();
  EXPECT_EQ(split.positions.size(), 6u);
  EXPECT_TRUE(split.scalar_channels.empty());
  ASSERT_EQ(r->positions.size(), 4u);
  EXPECT_EQ(r->scalars, (ScalarValues{std::bit_cast<uint32_t>(0.25f), std::bit_cast<uint32_t>(0.5f),
                                      std::bit_cast<uint32_t>(1.f), std::bit_cast<uint32_t>(1.f),
                                      std::bit_cast<uint32_t>(1.f), std::bit_cast<uint32_t>(1.f), 0, 0}));
}

// The same sphere as a PLY with a `texcoord` list per face (MeshLab's and photogrammetry tools' way), ASCII and
// binary: read, it is the OBJ's mesh exactly (the same wedges in the same order); an odd list fails naming the face;
// a float64 list, which float channels would round, is listed dropped.
TEST(Texcoords, PlyFaceTexcoordListsAreWedges) {
  TempDir dir;
  const std::string obj = dir.file("s.obj");
  testing::writeBytes(obj, uvSphereObj(6, 8));
  const ObjText text = parseObj(obj);
  auto want = readMeshFile(obj);
  ASSERT_TRUE(want.isOk());
  auto header = [&](const char* format, const char* uv_type) {
    std::ostringstream h;
    h << "ply\nformat " << format << " 1.0\nelement vertex " << text.v.size()
      << "\nproperty double x\nproperty double y\nproperty double z\nelement face " << text.f.size()
      << "\nproperty list uchar int vertex_indices\nproperty list uchar " << uv_type << " texcoord\nend_header\n";
    return h.str();
  };
  std::ostringstream ascii;
  ascii.precision(17);
  ascii << header("ascii", "float");
  std::string binary = header("binary_little_endian", "float");
  auto put = [&](const auto& value) { binary.append(reinterpret_cast<const char*>(&value), sizeof value); };
  for (const auto& p : text.v) {
    ascii << p[0] << ' ' << p[1] << ' ' << p[2] << '\n';
    for (double c : p) put(c);
  }
  for (const auto& f : text.f) {
    ascii << "3";
    put(uint8_t(3));
    for (const auto& c : f) ascii << ' ' << c.first, put(int32_t(c.first));
    ascii << " 6";
    put(uint8_t(6));
    for (const auto& c : f)
      for (float x : text.vt[size_t(c.second)]) ascii << ' ' << double(x), put(x);
    ascii << '\n';
  }
  for (const auto& [name, bytes] : {std::pair{"a.ply", ascii.str()}, std::pair{"b.ply", binary}}) {
    SCOPED_TRACE(name);
    testing::writeBytes(dir.file(name), bytes);
    ReadStats stats;
    auto got = readMeshFile(dir.file(name), &stats);
    ASSERT_TRUE(got.isOk()) << got.status().toString();
    EXPECT_TRUE(stats.dropped.empty()) << describeDropped(stats.dropped);
    EXPECT_EQ(stats.source_vertices, text.v.size());
    EXPECT_EQ(got->positions, want->positions);
    EXPECT_EQ(got->triangles, want->triangles);
    EXPECT_EQ(got->scalar_channels, want->scalar_channels);
    EXPECT_EQ(got->scalars, want->scalars);
  }
  // Through encode and decode (edgebreaker, many tiles) to OBJ: the file's corners.
  EncodeSettings s;
  s.input = dir.file("b.ply");
  s.output = dir.file("b.spz");
  s.codec = "edgebreaker";
  s.bits = 20;
  s.tile_triangles = 1024;
  ASSERT_TRUE(encodeFile(s).isOk());
  DecodeSettings d;
  d.input = s.output;
  d.output = dir.file("b.obj");
  ASSERT_TRUE(decodeFile(d).isOk());
  EXPECT_TRUE(cornerFaces(parseObj(d.output), text) == cornerFaces(text, text));

  // Four values for a triangle's corners: an error naming the face (line 14 of the ASCII file: the first face).
  std::string odd = ascii.str();
  const size_t first_face = odd.find("\n3 ") + 1;
  odd.replace(odd.find(" 6 ", first_face), 3, " 4 ");
  testing::writeBytes(dir.file("odd.ply"), odd);
  auto bad = readMeshFile(dir.file("odd.ply"));
  ASSERT_FALSE(bad.isOk());
  EXPECT_NE(bad.status().message().find("face 0 has 4 texture coordinate values for 3 corners"), std::string::npos)
      << bad.status().toString();
  // float64 lists: listed dropped, vertices as in the file.
  std::string f64 = header("ascii", "double") + ascii.str().substr(header("ascii", "float").size());
  testing::writeBytes(dir.file("d.ply"), f64);
  ReadStats stats;
  auto d64 = readMeshFile(dir.file("d.ply"), &stats);
  ASSERT_TRUE(d64.isOk()) << d64.status().toString();
  EXPECT_EQ(describeDropped(stats.dropped), "face.texcoord x " + std::to_string(text.f.size()));
  EXPECT_EQ(d64->positions.size(), text.v.size());
  // Vertices with a channel named u of their own: the lists are listed dropped (two channels named u would not be
  // a valid container).
  std::string with_u = ascii.str();
  with_u.replace(with_u.find("property double z\n"), 18, "property double z\nproperty uchar u\n");
  for (size_t at = with_u.find("end_header\n") + 11, row = 0; row < text.v.size(); ++row) {
    at = with_u.find('\n', at);
    with_u.insert(at, " 7");
    at += 3;
  }
  testing::writeBytes(dir.file("u.ply"), with_u);
  auto own_u = readMeshFile(dir.file("u.ply"), &stats);
  ASSERT_TRUE(own_u.isOk()) << own_u.status().toString();
  EXPECT_EQ(describeDropped(stats.dropped), "face.texcoord x " + std::to_string(text.f.size()));
  EXPECT_EQ(own_u->scalar_channels, (std::vector<ScalarChannel>{{"u", ScalarType::kUint8}}));
}

// Decodes the container `spz` to `out` and reads that file back.
Result<Mesh> decodeAndRead(const std::string& spz, const std::string& out) {
  DecodeSettings d;
  d.input = spz;
  d.output = out;
  auto dec = decodeFile(d);
  if (!dec.isOk()) return dec.status();
  return readMeshFile(out);
}

EncodeSettings uvSettingsFor(const std::string& in, const std::string& out, const std::string& codec) {
  EncodeSettings s = testing::encodeSettings(in, out, codec);
  s.bits = 20;
  return s;
}

// The ways of encoding that carry texture coordinates: every codec that carries scalars, one tile and many, in
// memory and out of core.
struct RunCase {
  const char* codec;
  uint64_t tile_triangles;
  uint64_t memory_budget;
  std::string name() const {
    return std::string(codec) + ", " + std::to_string(tile_triangles) + " triangles per tile" +
           (memory_budget ? ", out of core" : "");
  }
  EncodeSettings settings(const std::string& in, const std::string& out) const {
    EncodeSettings s = uvSettingsFor(in, out, codec);
    s.tile_triangles = tile_triangles;
    s.memory_budget = memory_budget;
    return s;
  }
};
const RunCase kRunCases[] = {
    {"edgebreaker", 1u << 20, 0}, {"edgebreaker", 300, 0}, {"kdtree", 300, 0},
    {"octree", 1u << 20, 0},      {"store", 300, 0},       {"kdtree", 300, uint64_t(96) << 10}};

// Decodes `spz` to `obj` and checks its faces corner by corner against `want`'s, with as many `v` lines.
DecodeResult expectDecodedCorners(const std::string& spz, const std::string& obj, const ObjText& want) {
  DecodeSettings d;
  d.input = spz;
  d.output = obj;
  auto dec = decodeFile(d);
  EXPECT_TRUE(dec.isOk()) << dec.status().toString();
  if (!dec.isOk()) return {};
  const ObjText got = parseObj(d.output);
  EXPECT_EQ(got.v.size(), want.v.size());
  EXPECT_TRUE(cornerFaces(got, want) == cornerFaces(want, want));
  return *dec;
}

// Through encode and decode, every codec that carries scalars, one tile and many (welded across tiles), in memory
// and out of core: the decoded OBJ's faces are the input's, corner by corner (positions to the grid, texture
// coordinates bit for bit), with as many `v` lines as the input.
TEST(Texcoords, SeamsSurviveEncodeAndDecode) {
  TempDir dir;
  const std::string in = dir.file("sphere.obj");
  testing::writeBytes(in, uvSphereObj(24, 48));
  const ObjText want = parseObj(in);
  for (const RunCase& c : kRunCases) {
    SCOPED_TRACE(c.name());
    const EncodeSettings s = c.settings(in, dir.file("s.spz"));
    auto enc = encodeFile(s);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    EXPECT_EQ(describeDropped(enc->read.dropped), "obj vt unused x 2");
    EXPECT_EQ(c.memory_budget != 0, enc->out_of_core);
    ASSERT_TRUE(findTexcoords(enc->layout.scalars).has_value());
    if (c.tile_triangles < 1000) {
      EXPECT_GT(enc->tiles.size(), 4u);
    }
    const DecodeResult dec = expectDecodedCorners(s.output, dir.file("out.obj"), want);
    EXPECT_TRUE(dec.dropped.empty()) << describeDropped(dec.dropped);
  }
}

// `--uv-bits`: the same corners come back with their texture coordinates snapped to multiples of 2^-bits (and so
// within half of one of the file's), through every codec that carries scalars, one tile and many, in memory and
// out of core; the container is version 3 and says the channels' bits.
TEST(Texcoords, UvBitsSnapEveryCornerThroughEncodeAndDecode) {
  TempDir dir;
  const std::string in = dir.file("sphere.obj");
  testing::writeBytes(in, uvSphereObj(24, 48));
  const ObjText file = parseObj(in);
  for (int bits : {4, 10}) {
    ObjText want = file;
    const ScalarChannel channel{"u", ScalarType::kFloat32, uint8_t(bits)};
    for (auto& t : want.vt)
      for (float& x : t) {
        uint32_t w[1] = {std::bit_cast<uint32_t>(x)};
        ASSERT_TRUE(snapScalar(channel, w));
        const float snapped = std::bit_cast<float>(w[0]);
        EXPECT_LE(std::fabs(snapped - x), std::ldexp(1.0, -bits - 1) + 1e-7);
        x = snapped;
      }
    for (const RunCase& c : kRunCases) {
      SCOPED_TRACE(c.name() + ", " + std::to_string(bits) + " bits");
      EncodeSettings s = c.settings(in, dir.file("s.spz"));
      s.uv_bits = bits;
      auto enc = encodeFile(s);
      ASSERT_TRUE(enc.isOk()) << enc.status().toString();
      EXPECT_EQ(c.memory_budget != 0, enc->out_of_core);
      const auto tc = findTexcoords(enc->layout.scalars);
      ASSERT_TRUE(tc.has_value());
      EXPECT_EQ(enc->layout.scalars[tc->u].bits, bits);
      EXPECT_EQ(enc->layout.scalars[tc->v].bits, bits);
      auto file_header = ContainerFile::open(s.output);
      ASSERT_TRUE(file_header.isOk());
      EXPECT_EQ(file_header->header().version, 3u);
      expectDecodedCorners(s.output, dir.file("out.obj"), want);
    }
  }
}

// A texture coordinate beyond what --uv-bits can keep (2^(31 - bits) in magnitude) fails the encode with the
// vertex, channel and value, and leaves no output; without --uv-bits it is kept as it is.
TEST(Texcoords, UvBitsRefuseCoordinatesBeyondTheirRange) {
  TempDir dir;
  const std::string in = dir.file("far.obj");
  testing::writeBytes(in, "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1000000 0\nvt 0 1\nf 1/1 2/2 3/3\n");
  EncodeSettings s = uvSettingsFor(in, dir.file("far.spz"), "edgebreaker");
  s.uv_bits = 12;
  auto enc = encodeFile(s);
  ASSERT_FALSE(enc.isOk());
  EXPECT_EQ(enc.status().code(), ErrorCode::kInvalidArgument);
  EXPECT_NE(
      enc.status().message().find("vertex 1 (counting texture seams' wedges): u = 1000000 cannot be kept at 12 bits"),
      std::string::npos)
      << enc.status().toString();
  EXPECT_NE(enc.status().message().find("far.obj"), std::string::npos) << enc.status().toString();
  EXPECT_FALSE(std::filesystem::exists(s.output));
  s.uv_bits = 0;
  ASSERT_TRUE(encodeFile(s).isOk());
  s.uv_bits = kMaxScalarBits + 1;
  EXPECT_FALSE(encodeFile(s).isOk());
}

// OBJ materials: the `mtllib` line and a single `usemtl` go through the container (version 3) into decoded OBJ
// files, in memory and streamed alike; other formats list them dropped. A file naming several materials, or with
// faces before its first `usemtl`, keeps its libraries but no material, and says so. A PLY's `comment TextureFile`
// goes into decoded PLY files likewise.
TEST(Materials, MtllibAndOneUsemtlAreKept) {
  TempDir dir;
  const std::string in = dir.file("sphere.obj");
  testing::writeBytes(in, uvSphereObj(12, 24));
  EncodeSettings s = uvSettingsFor(in, dir.file("m.spz"), "kdtree");
  s.keep_scalars = false;  // (a streamed decode writes no texture coordinates)
  s.tile_triangles = 200;
  auto enc = encodeFile(s);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  EXPECT_EQ(enc->read.materials.library, "sphere.mtl");
  EXPECT_EQ(enc->read.materials.material, "skin");
  EXPECT_EQ(describeDropped(enc->read.dropped), "");
  auto file = ContainerFile::open(s.output);
  ASSERT_TRUE(file.isOk());
  EXPECT_EQ(file->header().version, 3u);
  DecodeSettings d;
  d.input = s.output;
  d.output = dir.file("memory.obj");
  auto dec = decodeFile(d);
  ASSERT_TRUE(dec.isOk()) << dec.status().toString();
  EXPECT_FALSE(dec->streamed);
  EXPECT_TRUE(dec->dropped.empty()) << describeDropped(dec->dropped);
  const std::string text = testing::readText(d.output);
  EXPECT_NE(text.find("\nmtllib sphere.mtl\nusemtl skin\nv "), std::string::npos) << text.substr(0, 200);
  d.output = dir.file("streamed.obj");
  d.memory_budget = 64 << 10;
  d.scratch_dir = dir.file("scratch");
  std::filesystem::create_directories(d.scratch_dir);
  dec = decodeFile(d);
  ASSERT_TRUE(dec.isOk()) << dec.status().toString();
  EXPECT_TRUE(dec->streamed);
  EXPECT_TRUE(testing::readText(d.output) == text);
  d.memory_budget = 0;
  d.output = dir.file("m.ply");
  dec = decodeFile(d);
  ASSERT_TRUE(dec.isOk());
  EXPECT_EQ(describeDropped(dec->dropped), "obj mtllib sphere.mtl x 1, obj usemtl skin x 1");

  const std::string head = "mtllib a.mtl\nmtllib b.mtl a.mtl\nmtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n";
  struct Case {
    std::string faces, material, dropped;
  };
  for (const Case& c : {Case{"usemtl red\nf 1 2 3\nusemtl red\nf 2 4 3\n", "red", ""},
                        Case{"usemtl red\nf 1 2 3\nusemtl blue\nf 2 4 3\n", "",
                             "obj usemtl (several materials or faces without one: none is kept) x 2"},
                        Case{"f 1 2 3\nusemtl red\nf 2 4 3\n", "",
                             "obj usemtl (several materials or faces without one: none is kept) x 1"}}) {
    SCOPED_TRACE(c.faces);
    testing::writeBytes(dir.file("q.obj"), head + c.faces);
    ReadStats stats;
    ASSERT_TRUE(readMeshFile(dir.file("q.obj"), &stats).isOk());
    EXPECT_EQ(stats.materials.library, "a.mtl b.mtl");
    EXPECT_EQ(stats.materials.material, c.material);
    EXPECT_EQ(describeDropped(stats.dropped), c.dropped);
  }
  // PLY's `comment TextureFile`: kept and written back to PLY output; listed dropped for OBJ output, and when a
  // header names several.
  {
    auto sphere = readMeshFile(in);
    ASSERT_TRUE(sphere.isOk());
    ASSERT_TRUE(writePly(dir.file("t.ply"), *sphere).isOk());
    std::string ply = testing::readText(dir.file("t.ply"));
    const std::string with = "comment written by scanpress\ncomment TextureFile bark 2.jpg\n";
    ply.replace(ply.find("comment written by scanpress\n"), 29, with);
    testing::writeBytes(dir.file("t.ply"), ply);
    EncodeSettings t = uvSettingsFor(dir.file("t.ply"), dir.file("t.spz"), "edgebreaker");
    auto e = encodeFile(t);
    ASSERT_TRUE(e.isOk()) << e.status().toString();
    EXPECT_EQ(e->read.materials.texture, "bark 2.jpg");
    EXPECT_TRUE(e->read.dropped.empty()) << describeDropped(e->read.dropped);
    DecodeSettings td;
    td.input = t.output;
    td.output = dir.file("back.ply");
    auto back = decodeFile(td);
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_TRUE(back->dropped.empty()) << describeDropped(back->dropped);
    EXPECT_NE(testing::readText(td.output).find(with), std::string::npos);
    td.output = dir.file("back.obj");
    back = decodeFile(td);
    ASSERT_TRUE(back.isOk());
    EXPECT_EQ(describeDropped(back->dropped), "ply comment TextureFile bark 2.jpg x 1");
    // pm keeps the texture coordinates and so their image (v5); prm keeps no texture coordinates, so not their
    // image either; a nameless comment is no texture.
    t.codec = "pm";
    e = encodeFile(t);
    ASSERT_TRUE(e.isOk()) << e.status().toString();
    EXPECT_TRUE(e->read.dropped.empty()) << describeDropped(e->read.dropped);
    EXPECT_EQ(ContainerFile::open(t.output)->header().materials.texture, "bark 2.jpg");
    t.codec = "prm";
    e = encodeFile(t);
    ASSERT_TRUE(e.isOk()) << e.status().toString();
    const std::string unkept = "ply comment TextureFile (its texture coordinates are not kept) x 1";
    EXPECT_NE(describeDropped(e->read.dropped).find(unkept), std::string::npos) << describeDropped(e->read.dropped);
    EXPECT_EQ(ContainerFile::open(t.output)->header().materials.texture, "");
    std::string blank = ply;
    blank.replace(blank.find(with), with.size(), "comment written by scanpress\ncomment TextureFile  \t\n");
    testing::writeBytes(dir.file("blank.ply"), blank);
    ReadStats blank_stats;
    ASSERT_TRUE(readMeshFile(dir.file("blank.ply"), &blank_stats).isOk());
    EXPECT_EQ(blank_stats.materials.texture, "");
    EXPECT_TRUE(blank_stats.dropped.empty()) << describeDropped(blank_stats.dropped);
    ply.replace(ply.find(with), with.size(), with + "comment TextureFile leaf.jpg\n");
    testing::writeBytes(dir.file("t.ply"), ply);
    ReadStats stats;
    ASSERT_TRUE(readMeshFile(dir.file("t.ply"), &stats).isOk());
    EXPECT_EQ(stats.materials.texture, "");
    EXPECT_EQ(describeDropped(stats.dropped), "comment TextureFile (several textures: none is kept) x 2");
  }
  // Names that are not UTF-8 (Latin-1 here) are listed, not kept: the reports are JSON.
  testing::writeBytes(dir.file("latin.obj"), "mtllib caf\xE9.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl Ma\xDF\nf 1 2 3\n");
  ReadStats stats;
  ASSERT_TRUE(readMeshFile(dir.file("latin.obj"), &stats).isOk());
  EXPECT_EQ(stats.materials.library, "");
  EXPECT_EQ(stats.materials.material, "");
  EXPECT_EQ(describeDropped(stats.dropped),
            "obj usemtl (over 1024 bytes, control characters or not UTF-8: not kept) x 1, obj mtllib (over 1024 "
            "bytes, control characters or not UTF-8: not kept) x 1");
}

// pm (v5) keeps texture seams as wedges through its simplification: an OBJ's `vt` and a PLY's u, v (a seam as
// points at one position with other u, v) are kept, with nothing dropped or merged, under --strict too; --no-scalars
// drops them on request. --codec auto keeps them whichever codec it chooses. PLY's u and v are the same channels:
// an OBJ output writes them as `vt`, and lists only the others.
TEST(Texcoords, KeptBySimplifyingCodecsAndWrittenFromPly) {
  TempDir dir;
  const std::string in = dir.file("sphere.obj");
  testing::writeBytes(in, uvSphereObj(12, 24));
  for (const bool pm : {true, false}) {
    EncodeSettings s = uvSettingsFor(in, dir.file("p.spz"), pm ? "pm" : "kdtree");
    s.keep_scalars = pm;
    auto enc = encodeFile(s);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    EXPECT_EQ(findTexcoords(enc->layout.scalars).has_value(), pm);
    if (pm) {
      EXPECT_EQ(describeDropped(enc->read.dropped), "obj vt unused x 2");  // the file's own, for every codec
      EXPECT_GT(enc->read.vertices, enc->read.source_vertices) << "the seam's wedges";
    } else {
      EXPECT_EQ(enc->read.source_vertices, enc->read.vertices);
      const std::string dropped = describeDropped(enc->dropped_on_request);
      EXPECT_NE(dropped.find("obj vt x 325"), std::string::npos) << dropped;
    }
  }
  // pm simplified to 30% of the faces and decoded to OBJ: no triangle spans the seam (u from 0 to 1).
  {
    EncodeSettings a = uvSettingsFor(in, dir.file("lossy.spz"), "pm");
    a.codec_options.pm.ratio = 0.3;
    ASSERT_TRUE(encodeFile(a).isOk());
    auto back = decodeAndRead(a.output, dir.file("lossy.obj"));
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    const auto tc = findTexcoords(back->scalar_channels);
    ASSERT_TRUE(tc.has_value());
    const size_t stride = back->scalars.size() / back->positions.size();
    ASSERT_GT(back->triangles.size(), 50u);
    for (const Triangle& t : back->triangles) {
      float lo = 2, hi = -1;
      for (uint32_t v : t) {
        const float u = std::bit_cast<float>(back->scalars[v * stride + tc->u_word]);
        lo = std::min(lo, u), hi = std::max(hi, u);
      }
      EXPECT_LT(hi - lo, 0.5f) << "a triangle across the seam";
    }
  }
  // --codec auto under a loose target keeps the texture coordinates, whichever codec wins.
  {
    EncodeSettings a = uvSettingsFor(in, dir.file("auto.spz"), "auto");
    testing::setRmsTarget(a, 1e-3);
    auto chosen = encodeFile(a);
    ASSERT_TRUE(chosen.isOk()) << chosen.status().toString();
    EXPECT_TRUE(findTexcoords(chosen->layout.scalars).has_value()) << chosen->codec;
    EXPECT_EQ(describeDropped(chosen->read.dropped), "obj vt unused x 2");
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
  // Its seam is points at one position with other u, v (and other confidences): pm keeps every point, lossless and
  // under --strict.
  EncodeSettings p = uvSettingsFor(ply, dir.file("seam.spz"), "pm");
  p.strict = true;
  auto kept = encodeFile(p);
  ASSERT_TRUE(kept.isOk()) << kept.status().toString();
  EXPECT_EQ(kept->failed_tiles, 0u);
  EXPECT_EQ(kept->layout.scalars.size(), 3u);
  EXPECT_TRUE(kept->read.dropped.empty()) << describeDropped(kept->read.dropped);
  {
    auto back = decodeAndRead(p.output, dir.file("seam.ply"));
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    // Corner for corner: the same rows at the same (quantized) corners as an edgebreaker round trip, lossless too.
    EncodeSettings e = uvSettingsFor(ply, dir.file("eb.spz"), "edgebreaker");
    ASSERT_TRUE(encodeFile(e).isOk());
    auto want = decodeAndRead(e.output, dir.file("eb.ply"));
    ASSERT_TRUE(want.isOk()) << want.status().toString();
    auto corners = [](const Mesh& x) {
      const size_t stride = x.scalars.size() / x.positions.size();
      std::vector<std::array<std::pair<Vec3d, std::vector<uint32_t>>, 3>> out;
      for (const Triangle& t : x.triangles) {
        std::array<std::pair<Vec3d, std::vector<uint32_t>>, 3> c;
        for (int k = 0; k < 3; ++k)
          c[size_t(k)] = {x.positions[t[size_t(k)]],
                          std::vector<uint32_t>(x.scalars.begin() + ptrdiff_t(t[size_t(k)] * stride),
                                                x.scalars.begin() + ptrdiff_t((t[size_t(k)] + 1) * stride))};
        std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
        out.push_back(c);
      }
      std::sort(out.begin(), out.end());
      return out;
    };
    EXPECT_TRUE(corners(*back) == corners(*want));
  }
  p.codec = "auto";
  p.strict = false;
  p.output = dir.file("auto.spz");
  testing::setRmsTarget(p, 1e-3);
  auto chosen = encodeFile(p);
  ASSERT_TRUE(chosen.isOk()) << chosen.status().toString();
  EXPECT_EQ(chosen->layout.scalars.size(), 3u);
  EncodeSettings s = uvSettingsFor(ply, dir.file("q.spz"), "edgebreaker");
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
  // Under a memory budget the decode streams; OBJ output with texture coordinates is built in memory: refused, with
  // the way out (PLY streams them: StreamDecodeScalars.ChannelsAndLosslessNormalsSameBytesAsInMemory).
  d.output = dir.file("r.obj");
  d.memory_budget = 1;
  dec = decodeFile(d);
  ASSERT_FALSE(dec.isOk());
  EXPECT_EQ(dec.status().code(), ErrorCode::kUnsupported);
  EXPECT_NE(dec.status().message().find("texture coordinates"), std::string::npos) << dec.status().toString();
  EXPECT_FALSE(std::filesystem::exists(d.output));
}

// Fandisk (a CAD part with sharp edges) with a normal per corner: the mean of the normals of the vertex's faces
// within 30 degrees of the corner's face (smooth across gentle edges, split at sharp ones), one `vn` record per
// corner. The reader splits each vertex into one wedge per distinct normal; through kdtree, octree and edgebreaker
// (one tile and many) every decoded corner has its own normal to the octahedral precision, so no normal is
// averaged across a crease; pm (v5) too, whose simplifier moves a corner only to a wedge on its own side.
TEST(CornerNormals, FandiskCreasesSurviveEncodeAndDecode) {
  const std::string fandisk = testing::sharedDataDir() + "/fandisk.obj";
  if (!std::filesystem::exists(fandisk)) GTEST_SKIP() << "shared data not found: " << fandisk;
  auto base = readMeshFile(fandisk);
  ASSERT_TRUE(base.isOk());
  const Mesh& m = *base;
  const auto split = testing::cornerNormalsSplitAt(m, 30);
  std::ostringstream obj;
  obj.precision(9);
  for (const Vec3d& p : m.positions) obj << "v " << p[0] << ' ' << p[1] << ' ' << p[2] << '\n';
  std::vector<std::array<float, 3>> corner_normal;  // per corner, as the file has it (float)
  for (const auto& c : split) {
    std::ostringstream line;
    line.precision(9);
    line << float(c[0]) << ' ' << float(c[1]) << ' ' << float(c[2]);
    obj << "vn " << line.str() << '\n';
    // What the reader keeps: the printed digits, read back as float.
    std::array<float, 3> back;
    std::istringstream(line.str()) >> back[0] >> back[1] >> back[2];
    corner_normal.push_back(back);
  }
  for (size_t f = 0; f < m.triangles.size(); ++f) {
    obj << 'f';
    for (int k = 0; k < 3; ++k) obj << ' ' << m.triangles[f][size_t(k)] + 1 << "//" << 3 * f + size_t(k) + 1;
    obj << '\n';
  }
  TempDir dir;
  const std::string in = dir.file("fandisk-creased.obj");
  testing::writeBytes(in, obj.str());

  // The reader: one vertex per distinct normal of its corners.
  ReadStats stats;
  auto read = readMeshFile(in, &stats);
  ASSERT_TRUE(read.isOk()) << read.status().toString();
  std::vector<std::set<std::array<float, 3>>> distinct(m.positions.size());
  for (size_t f = 0; f < m.triangles.size(); ++f)
    for (int k = 0; k < 3; ++k) distinct[m.triangles[f][size_t(k)]].insert(corner_normal[3 * f + size_t(k)]);
  size_t wedges = 0;
  for (const auto& d : distinct) wedges += std::max<size_t>(1, d.size());
  EXPECT_EQ(read->positions.size(), wedges);
  EXPECT_GT(wedges, m.positions.size() + 500) << "fandisk's sharp edges split over 500 vertices";
  EXPECT_TRUE(stats.dropped.empty()) << describeDropped(stats.dropped);

  // Each decoded corner's normal against the file's: within 0.2 degrees (12-bit octahedral normals: about 0.06);
  // `exact` (lossless normals): bit for bit.
  auto checkCorners = [&](const std::string& path, bool exact) {
    auto out = readMeshFile(path);
    ASSERT_TRUE(out.isOk());
    ASSERT_EQ(out->triangles.size(), m.triangles.size());
    ASSERT_EQ(out->normals.size(), out->positions.size());
    // Decoded vertices matched to the nearest of the file's positions (fandisk's are over 1e-3 apart, the 20-bit
    // grid's error below 2e-5), triangles to the file's faces by those corners.
    std::map<long long, std::vector<uint32_t>> by_x;
    for (uint32_t v = 0; v < m.positions.size(); ++v) by_x[std::llround(m.positions[v][0] * 100)].push_back(v);
    auto nearest = [&](const Vec3d& p) {
      uint32_t best = UINT32_MAX;
      double best_d = 1e-8;
      for (long long x = std::llround(p[0] * 100) - 1; x <= std::llround(p[0] * 100) + 1; ++x)
        if (const auto it = by_x.find(x); it != by_x.end())
          for (uint32_t v : it->second) {
            double d = 0;
            for (int k = 0; k < 3; ++k)
              d += (p[size_t(k)] - m.positions[v][size_t(k)]) * (p[size_t(k)] - m.positions[v][size_t(k)]);
            if (d < best_d) best_d = d, best = v;
          }
      return best;
    };
    auto rotated = [](std::array<uint32_t, 3> t) {
      std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());
      return t;
    };
    std::map<std::array<uint32_t, 3>, size_t> face_of;
    for (size_t f = 0; f < m.triangles.size(); ++f) face_of[rotated(m.triangles[f])] = f;
    size_t matched = 0, creased = 0, inexact = 0;
    double worst = 0;
    for (const Triangle& t : out->triangles) {
      const std::array<uint32_t, 3> ids{nearest(out->positions[t[0]]), nearest(out->positions[t[1]]),
                                        nearest(out->positions[t[2]])};
      const auto it = face_of.find(rotated(ids));
      if (it == face_of.end()) continue;
      ++matched;
      for (int k = 0; k < 3; ++k) {
        const Triangle& ft = m.triangles[it->second];
        const int j = int(std::find(ft.begin(), ft.end(), ids[size_t(k)]) - ft.begin());
        const Vec3f& got = out->normals[t[size_t(k)]];
        const std::array<float, 3>& want = corner_normal[3 * it->second + size_t(j)];
        inexact += std::memcmp(got.data(), want.data(), sizeof got) != 0;
        const double dot = double(got[0]) * want[0] + double(got[1]) * want[1] + double(got[2]) * want[2];
        worst = std::max(worst, std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / M_PI);
        creased += distinct[ids[size_t(k)]].size() > 1;
      }
    }
    EXPECT_EQ(matched, m.triangles.size()) << "triangles matched to the file's by their corners";
    EXPECT_GT(creased, 1000u);
    EXPECT_LT(worst, 0.2) << "degrees";
    if (exact) {
      EXPECT_EQ(inexact, 0u) << "corners whose normal is not the file's bit for bit";
    }
  };
  const std::pair<const char*, uint64_t> runs[] = {
      {"kdtree", uint64_t(1) << 20}, {"octree", 2000}, {"edgebreaker", 2000}, {"pm", uint64_t(1) << 20}, {"pm", 2000}};
  for (const auto& [codec, tile_triangles] : runs) {
    SCOPED_TRACE(std::string(codec) + ", " + std::to_string(tile_triangles) + " triangles per tile");
    EncodeSettings s = uvSettingsFor(in, dir.file("f.spz"), codec);
    s.tile_triangles = tile_triangles;
    s.normal_bits = 12;
    auto enc = encodeFile(s);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    EXPECT_TRUE(enc->read.dropped.empty()) << describeDropped(enc->read.dropped);
    DecodeSettings d;
    d.input = s.output;
    d.output = dir.file("f.ply");
    ASSERT_TRUE(decodeFile(d).isOk());
    checkCorners(d.output, false);
  }
  // --lossless-normals: every corner's normal bit for bit, in PLY and OBJ output, one tile and many.
  for (const auto& [codec, tile_triangles] :
       {std::pair{"kdtree", uint64_t(1) << 20}, std::pair{"edgebreaker", uint64_t(2000)},
        std::pair{"pm", uint64_t(2000)}}) {
    SCOPED_TRACE(std::string(codec) + ", " + std::to_string(tile_triangles) + " triangles per tile, lossless");
    EncodeSettings s = uvSettingsFor(in, dir.file("l.spz"), codec);
    s.tile_triangles = tile_triangles;
    s.lossless_normals = true;
    auto enc = encodeFile(s);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    EXPECT_FALSE(enc->layout.hasNormals());
    EXPECT_TRUE(losslessNormalsWord(enc->layout.scalars).has_value());
    for (const char* ext : {".ply", ".obj"}) {
      DecodeSettings d;
      d.input = s.output;
      d.output = dir.file(std::string("l") + ext);
      auto dec = decodeFile(d);
      ASSERT_TRUE(dec.isOk()) << dec.status().toString();
      EXPECT_TRUE(dec->dropped.empty()) << describeDropped(dec->dropped);
      checkCorners(d.output, true);
    }
  }
  // prm makes new vertices (their normals would be resampled): refused, nothing written.
  EncodeSettings s = uvSettingsFor(in, dir.file("r.spz"), "prm");
  s.lossless_normals = true;
  auto enc = encodeFile(s);
  ASSERT_FALSE(enc.isOk());
  EXPECT_NE(enc.status().message().find("--lossless-normals needs a codec that keeps the scan's vertices"),
            std::string::npos)
      << enc.status().toString();
  EXPECT_FALSE(std::filesystem::exists(s.output));
}

// Lossless normals of a PLY, of the finite float bit patterns a scanner may write (non-unit, zero, negative zero,
// subnormal, huge; the reader refuses NaN and infinities), through every codec that carries scalars, one tile and
// many: decoded PLY normals are the file's bit for bit (matched by grid position and the other attributes), with
// the scan's own scalar channels beside them, and --no-scalars keeps them; STL output lists them dropped.
TEST(LosslessNormals, EveryBitPatternComesBack) {
  TempDir dir;
  Mesh m = uvSphere(dir, 16, 32);
  ASSERT_FALSE(m.positions.empty());
  m.scalar_channels = {{"confidence", ScalarType::kUint8}};
  m.scalars.clear();
  const float specials[] = {0.0f, -0.0f, 1e-42f, -3e38f, std::numeric_limits<float>::max(), 7.25f};
  m.normals.resize(m.positions.size());
  for (size_t v = 0; v < m.positions.size(); ++v) {
    const Vec3d& p = m.positions[v];
    m.normals[v] = {float(p[0] * 1.0000001), float(p[1]), float(p[2] + 1e-7 * double(v))};
    if (v % 11 == 5) m.normals[v][v % 3] = specials[(v / 11) % std::size(specials)];
    m.scalars.push_back(uint32_t(v % 200));
  }
  const std::string in = dir.file("n.ply");
  ASSERT_TRUE(writePly(in, m).isOk());
  // Vertices by grid cell and confidence (unique here), with their normals' bits.
  const auto keyed = [](const Mesh& mesh, const Grid& grid) {
    std::map<std::pair<Vec3u, uint32_t>, std::array<uint32_t, 3>> out;
    for (size_t v = 0; v < mesh.positions.size(); ++v)
      out[{grid.quantize(mesh.positions[v]), mesh.scalars.empty() ? 0 : mesh.scalars[v]}] = {
          std::bit_cast<uint32_t>(mesh.normals[v][0]), std::bit_cast<uint32_t>(mesh.normals[v][1]),
          std::bit_cast<uint32_t>(mesh.normals[v][2])};
    return out;
  };
  for (const RunCase& c : kRunCases) {
    SCOPED_TRACE(c.name());
    EncodeSettings s = c.settings(in, dir.file("n.spz"));
    s.lossless_normals = true;
    auto enc = encodeFile(s);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    EXPECT_EQ(c.memory_budget != 0, enc->out_of_core);
    DecodeSettings d;
    d.input = s.output;
    d.output = dir.file("back.ply");
    auto dec = decodeFile(d);
    ASSERT_TRUE(dec.isOk()) << dec.status().toString();
    auto back = readMeshFile(d.output);
    ASSERT_TRUE(back.isOk());
    EXPECT_EQ(back->scalar_channels, m.scalar_channels);
    EXPECT_TRUE(keyed(*back, enc->grid) == keyed(m, enc->grid));
  }
  EncodeSettings s = kRunCases[0].settings(in, dir.file("bare.spz"));
  s.lossless_normals = true;
  s.keep_scalars = false;
  auto enc = encodeFile(s);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  DecodeSettings d;
  d.input = s.output;
  d.output = dir.file("bare.ply");
  ASSERT_TRUE(decodeFile(d).isOk());
  auto bare = readMeshFile(d.output);
  ASSERT_TRUE(bare.isOk());
  EXPECT_TRUE(bare->scalar_channels.empty());
  Mesh without = m;
  without.scalars.clear();
  EXPECT_TRUE(keyed(*bare, enc->grid) == keyed(without, enc->grid));
  d.output = dir.file("bare.stl");
  auto stl = decodeFile(d);
  ASSERT_TRUE(stl.isOk());
  EXPECT_NE(describeDropped(stl->dropped).find("vertex.nx"), std::string::npos) << describeDropped(stl->dropped);
  // The container says so: normals, lossless.
  auto file = ContainerFile::open(s.output);
  ASSERT_TRUE(file.isOk());
  EXPECT_EQ(nlohmann::json::parse(containerInfoJson(*file))["attributes"]["lossless_normals"], true);

  // pm keeps them too: per grid cell, the first input vertex's normal and confidence (pm welds by position; the
  // sphere's seam has twins), bit for bit. Under --codec auto with a target, pm and edgebreaker both compete and
  // either keeps them: every decoded vertex's row (confidence, normal bits) is an input vertex's.
  const auto rowOf = [](const Mesh& mesh, size_t v) {
    return std::array{mesh.scalars[v], std::bit_cast<uint32_t>(mesh.normals[v][0]),
                      std::bit_cast<uint32_t>(mesh.normals[v][1]), std::bit_cast<uint32_t>(mesh.normals[v][2])};
  };
  std::set<std::array<uint32_t, 4>> input_rows;
  for (size_t v = 0; v < m.positions.size(); ++v) input_rows.insert(rowOf(m, v));
  for (const bool target : {false, true}) {
    SCOPED_TRACE(target);
    EncodeSettings a = kRunCases[0].settings(in, dir.file("pm.spz"));
    a.codec = target ? "auto" : "pm";
    a.lossless_normals = true;
    if (target) testing::setRmsTarget(a, 1e-3);
    auto chosen = encodeFile(a);
    ASSERT_TRUE(chosen.isOk()) << chosen.status().toString();
    ASSERT_TRUE(losslessNormalsWord(chosen->layout.scalars).has_value());
    auto back = testing::decodeAndReadBack(a.output, dir.file("pm.ply"));
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    ASSERT_EQ(back->normals.size(), back->positions.size());
    ASSERT_EQ(back->scalars.size(), back->positions.size());
    std::map<Vec3u, std::array<uint32_t, 4>> first;
    for (size_t v = 0; v < m.positions.size(); ++v) first.emplace(chosen->grid.quantize(m.positions[v]), rowOf(m, v));
    if (!target) {
      EXPECT_EQ(back->positions.size(), first.size());
    }
    for (size_t v = 0; v < back->positions.size(); ++v) {
      if (target) {
        EXPECT_TRUE(input_rows.count(rowOf(*back, v))) << chosen->codec << " vertex " << v;
      } else {
        const auto it = first.find(chosen->grid.quantize(back->positions[v]));
        ASSERT_NE(it, first.end()) << v;
        EXPECT_EQ(it->second, rowOf(*back, v)) << v;
      }
    }
  }

  // A PLY whose normals are double: refused (they would be rounded to float).
  testing::writeBytes(dir.file("double.ply"),
                      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                      "property float z\nproperty double nx\nproperty double ny\nproperty double nz\n"
                      "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                      "0 0 0 0 0 0.1000000000000001\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n");
  s = kRunCases[0].settings(dir.file("double.ply"), dir.file("double.spz"));
  s.lossless_normals = true;
  enc = encodeFile(s);
  ASSERT_FALSE(enc.isOk());
  EXPECT_NE(enc.status().message().find("this PLY's are double"), std::string::npos) << enc.status().toString();
}

// Levels and welds that derive attributes from their triangles (kdtree's and octree's root level; tiles welded by
// position at a coarse level) give lossless normals a unit normal, as they give octahedral ones, never a zero one:
// every decoded normal at every level is finite and of unit length, one tile and many.
TEST(LosslessNormals, DerivedLevelsGetUnitNormals) {
  TempDir dir;
  Mesh m = uvSphere(dir, 24, 48);
  ASSERT_FALSE(m.positions.empty());
  m.normals.clear();
  for (const Vec3d& p : m.positions) m.normals.push_back({float(p[0]), float(p[1]), float(p[2])});
  const std::string in = dir.file("n.ply");
  ASSERT_TRUE(writePly(in, m).isOk());
  for (const char* codec : {"kdtree", "octree"})
    for (uint64_t tile_triangles : {uint64_t(1) << 20, uint64_t(300)}) {
      SCOPED_TRACE(std::string(codec) + ", " + std::to_string(tile_triangles) + " triangles per tile");
      EncodeSettings s = kRunCases[0].settings(in, dir.file("n.spz"));
      s.codec = codec;
      s.tile_triangles = tile_triangles;
      s.lossless_normals = true;
      auto enc = encodeFile(s);
      ASSERT_TRUE(enc.isOk()) << enc.status().toString();
      ASSERT_EQ(enc->tiles.size() > 1, tile_triangles < 1000);
      for (uint32_t level = 0; level <= uint32_t(enc->grid.bits); level += 2) {
        SCOPED_TRACE("level " + std::to_string(level));
        DecodeSettings d;
        d.input = s.output;
        d.output = dir.file("back.ply");
        d.level = level;
        auto dec = decodeFile(d);
        ASSERT_TRUE(dec.isOk()) << dec.status().toString();
        auto back = readMeshFile(d.output);
        ASSERT_TRUE(back.isOk()) << back.status().toString();
        ASSERT_EQ(back->normals.size(), back->positions.size());
        ASSERT_FALSE(back->positions.empty());
        for (size_t v = 0; v < back->normals.size(); ++v) {
          const Vec3f& n = back->normals[v];
          const double len = std::sqrt(double(n[0]) * n[0] + double(n[1]) * n[1] + double(n[2]) * n[2]);
          ASSERT_NEAR(len, 1.0, 1e-5) << "vertex " << v << " of " << back->normals.size();
        }
      }
    }
}

}  // namespace
}  // namespace scanpress
