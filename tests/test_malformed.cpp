// Malformed and hostile inputs: each must fail with a clear error that names the file and the place (line for
// text, byte offset for binary), map to exit code 2, and never crash (this suite also runs under ASan+UBSan).
#include <gtest/gtest.h>

#include <zstd.h>

#include <cstring>
#include <limits>
#include <random>
#include <regex>

#include "jobs/mesh_io/mesh_reader.h"
#include "test_util.h"

namespace scanpress {
namespace {

template <typename T>
std::string le(T v) {
  return testing::bytesOf(v);
}

const std::string kPlyAsciiHead =
    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
const std::string kPlyBinHead =
    "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
    "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";

std::string binVerts(float bad = 0.f) {
  std::string s;
  for (int i = 0; i < 3; ++i) s += le<float>(i == 1 ? bad : 0.f) + le<float>(float(i)) + le<float>(0.f);
  return s;
}
std::string binFace(int a, int b, int c, uint8_t n = 3) {
  std::string s(1, static_cast<char>(n));
  for (int v : {a, b, c}) s += le<int32_t>(v);
  return s;
}
std::string stlBinary(uint32_t count, int facets, float bad = 0.f) {
  std::string s(80, 'x');
  s += le<uint32_t>(count);
  for (int f = 0; f < facets; ++f) {
    s += std::string(12, '\0');
    const float c[9] = {0, 0, 0, 1, 0, 0, 0, 1, bad};
    for (float v : c) s += le<float>(v);
    s += std::string(2, '\0');
  }
  return s;
}
std::string zstdOf(const std::string& plain) {
  std::string out(ZSTD_compressBound(plain.size()), '\0');
  out.resize(ZSTD_compress(out.data(), out.size(), plain.data(), plain.size(), 3));
  return out;
}

struct Case {
  const char* name;
  const char* file;
  std::string content;
  ErrorCode code;
  bool has_place = true;
};

std::vector<Case> cases() {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  const std::string good_ply_ascii = kPlyAsciiHead + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  return {
      {"ply_empty", "a.ply", "", ErrorCode::kMalformed},
      {"ply_bad_magic", "a.ply", "plx\nformat ascii 1.0\nend_header\n", ErrorCode::kMalformed},
      {"ply_no_format", "a.ply", "ply\nelement vertex 0\nproperty float x\nend_header\n", ErrorCode::kMalformed},
      {"ply_unknown_encoding", "a.ply", "ply\nformat binary_middle_endian 1.0\nend_header\n", ErrorCode::kMalformed},
      {"ply_bad_version", "a.ply", "ply\nformat ascii 2.0\nend_header\n", ErrorCode::kMalformed},
      {"ply_negative_count", "a.ply", "ply\nformat ascii 1.0\nelement vertex -3\nend_header\n", ErrorCode::kMalformed},
      {"ply_nonnumeric_count", "a.ply", "ply\nformat ascii 1.0\nelement vertex many\nend_header\n",
       ErrorCode::kMalformed},
      {"ply_property_before_element", "a.ply", "ply\nformat ascii 1.0\nproperty float x\nend_header\n",
       ErrorCode::kMalformed},
      {"ply_unknown_type", "a.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
       ErrorCode::kMalformed},
      {"ply_float_list_count", "a.ply",
       "ply\nformat ascii 1.0\nelement face 1\nproperty list float int vertex_indices\nend_header\n",
       ErrorCode::kMalformed},
      {"ply_header_without_end", "a.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n",
       ErrorCode::kMalformed},
      {"ply_no_vertex_element", "a.ply", "ply\nformat ascii 1.0\nelement thing 0\nend_header\n", ErrorCode::kMalformed},
      {"ply_vertex_without_z", "a.ply",
       "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
       ErrorCode::kMalformed},
      {"ply_face_without_indices", "a.ply",
       "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 0\nproperty int flags\nend_header\n",
       ErrorCode::kMalformed},
      {"ply_duplicate_element", "a.ply",
       "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nelement vertex 0\nend_header\n",
       ErrorCode::kMalformed},
      {"ply_ascii_truncated_vertices", "a.ply", kPlyAsciiHead + "0 0 0\n1 0", ErrorCode::kTruncated},
      {"ply_ascii_nonnumeric", "a.ply", kPlyAsciiHead + "0 0 0\n1 abc 0\n0 1 0\n3 0 1 2\n", ErrorCode::kMalformed},
      {"ply_ascii_nan", "a.ply", kPlyAsciiHead + "0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n", ErrorCode::kMalformed},
      {"ply_ascii_inf", "a.ply", kPlyAsciiHead + "0 0 0\n1 0 -inf\n0 1 0\n3 0 1 2\n", ErrorCode::kMalformed},
      {"ply_ascii_negative_index", "a.ply", kPlyAsciiHead + "0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n", ErrorCode::kMalformed},
      {"ply_ascii_face_two_vertices", "a.ply", kPlyAsciiHead + "0 0 0\n1 0 0\n0 1 0\n2 0 1\n", ErrorCode::kMalformed},
      {"ply_ascii_face_zero_vertices", "a.ply", kPlyAsciiHead + "0 0 0\n1 0 0\n0 1 0\n0\n", ErrorCode::kMalformed},
      {"ply_ascii_crlf_truncated_face", "a.ply",
       std::regex_replace(kPlyAsciiHead, std::regex("\n"), "\r\n") + "0 0 0\r\n1 0 0\r\n0 1 0\r\n3 0 1\r\n",
       ErrorCode::kTruncated},
      {"ply_binary_truncated_vertices", "a.ply", kPlyBinHead + binVerts().substr(0, 20), ErrorCode::kTruncated},
      {"ply_binary_truncated_face", "a.ply", kPlyBinHead + binVerts() + binFace(0, 1, 2).substr(0, 9),
       ErrorCode::kTruncated},
      {"ply_binary_nan", "a.ply", kPlyBinHead + binVerts(nan) + binFace(0, 1, 2), ErrorCode::kMalformed},
      {"ply_binary_index_out_of_range", "a.ply", kPlyBinHead + binVerts() + binFace(0, 1, 3), ErrorCode::kMalformed},
      {"ply_binary_huge_list", "a.ply",
       "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
       "property float z\nelement face 1\nproperty list int int vertex_indices\nend_header\n" +
           binVerts() + le<int32_t>(70000) + le<int32_t>(0),
       ErrorCode::kLimitExceeded},
      {"ply_huge_count_small_file", "a.ply",
       "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\n"
       "property float z\nend_header\n" +
           binVerts(),
       ErrorCode::kTruncated},
      {"ply_count_over_32_bits", "a.ply",
       "ply\nformat binary_little_endian 1.0\nelement vertex 99999999999\nproperty float x\nproperty float y\n"
       "property float z\nend_header\n",
       ErrorCode::kLimitExceeded},
      {"ply_zst_huge_count", "a.ply.zst",
       zstdOf("ply\nformat binary_little_endian 1.0\nelement vertex 2000000000\nproperty float x\n"
              "property float y\nproperty float z\nend_header\n" +
              binVerts()),
       ErrorCode::kTruncated},
      {"ply_tristrip_out_of_range", "a.ply",
       "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "element tristrips 1\nproperty list int int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2 5\n",
       ErrorCode::kMalformed},
      {"ply_face_before_vertex", "a.ply",
       "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\nelement vertex 3\n"
       "property float x\nproperty float y\nproperty float z\nend_header\n3 0 1 2\n0 0 0\n1 0 0\n0 1 0\n",
       ErrorCode::kUnsupported},
      {"obj_vertex_two_numbers", "a.obj", "v 1 2\n", ErrorCode::kMalformed},
      {"obj_vertex_nonnumeric", "a.obj", "v 1 x 3\n", ErrorCode::kMalformed},
      {"obj_vertex_nan", "a.obj", "v 1 nan 3\n", ErrorCode::kMalformed},
      {"obj_face_index_zero", "a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", ErrorCode::kMalformed},
      {"obj_face_index_past_end", "a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", ErrorCode::kMalformed},
      {"obj_face_negative_past_start", "a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n", ErrorCode::kMalformed},
      {"obj_face_two_corners", "a.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n", ErrorCode::kMalformed},
      {"obj_face_bad_normal", "a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//2 3//1\n",
       ErrorCode::kMalformed},
      {"obj_face_garbage_corner", "a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 two 3\n", ErrorCode::kMalformed},
      {"obj_vn_short", "a.obj", "vn 0 1\n", ErrorCode::kMalformed},
      {"stl_binary_truncated", "a.stl", stlBinary(10, 1), ErrorCode::kTruncated},
      {"stl_binary_nan", "a.stl", stlBinary(1, 1, inf), ErrorCode::kMalformed},
      {"stl_binary_short_header", "a.stl", std::string(50, 'x'), ErrorCode::kTruncated},
      {"stl_ascii_two_vertex_facet", "a.stl",
       "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\nendsolid s\n",
       ErrorCode::kMalformed},
      {"stl_ascii_short_vertex", "a.stl", "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0\n",
       ErrorCode::kMalformed},
      {"stl_ascii_ends_inside_solid", "a.stl",
       "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n",
       ErrorCode::kTruncated},
      {"stl_ascii_unknown_keyword", "a.stl", "solid s\nfacet normal 0 0 1\nbanana\n", ErrorCode::kMalformed},
      {"off_bad_header", "a.off", "OFF3\n3 1 0\n", ErrorCode::kMalformed},
      {"off_missing_counts", "a.off", "OFF\n", ErrorCode::kTruncated},
      {"off_short_vertex", "a.off", "OFF\n3 1 0\n0 0\n1 0 0\n0 1 0\n3 0 1 2\n", ErrorCode::kMalformed},
      {"off_index_out_of_range", "a.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", ErrorCode::kMalformed},
      {"off_face_two_vertices", "a.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n", ErrorCode::kMalformed},
      {"off_truncated_vertices", "a.off", "OFF\n3 1 0\n0 0 0\n", ErrorCode::kTruncated},
      {"off_huge_counts", "a.off", "OFF\n3000000000 1 0\n0 0 0\n", ErrorCode::kTruncated},
      {"zstd_corrupt", "a.ply.zst", zstdOf(good_ply_ascii).substr(0, 6) + std::string(40, '\x5a'),
       ErrorCode::kMalformed},
      {"zstd_truncated", "a.ply.zst", zstdOf(good_ply_ascii).substr(0, 30), ErrorCode::kTruncated},
      {"unknown_format", "a.bin", "\x01\x02garbage", ErrorCode::kUnsupported, false},
  };
}

TEST(Malformed, EveryCaseFailsCleanlyNamingFileAndPlace) {
  testing::TempDir dir;
  const auto all = cases();
  ASSERT_GE(all.size(), 40u);
  const std::regex place(R"(:\d+: |byte \d+)");
  for (const Case& c : all) {
    SCOPED_TRACE(c.name);
    const std::string path = dir.file(std::string(c.name) + "_" + c.file);
    testing::writeBytes(path, c.content);
    auto r = readMeshFile(path);
    ASSERT_FALSE(r.isOk()) << "accepted";
    const Status& s = r.status();
    EXPECT_EQ(s.code(), c.code) << s.toString();
    EXPECT_EQ(exitCodeFor(s.code()), 2) << s.toString();
    EXPECT_NE(s.message().find(path), std::string::npos) << "message does not name the file: " << s.message();
    if (c.has_place) {
      EXPECT_TRUE(std::regex_search(s.message(), place)) << "no line or offset: " << s.message();
    }
  }
}

// Random mutations of valid files in every format: any outcome but a crash or a hang is acceptable, and a
// success must still satisfy the reader's contract (indices in range).
TEST(Malformed, RandomMutationsNeverCrash) {
  testing::TempDir dir;
  const std::string ply_ascii = kPlyAsciiHead + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  const std::string ply_bin = kPlyBinHead + binVerts() + binFace(0, 1, 2);
  const std::string obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n";
  const std::string stl = stlBinary(1, 1);
  const std::string off = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  std::mt19937 rng(12345);
  int accepted = 0, rejected = 0;
  for (const auto& [name, base] : std::vector<std::pair<std::string, std::string>>{
           {"m.ply", ply_ascii}, {"b.ply", ply_bin}, {"m.obj", obj}, {"m.stl", stl}, {"m.off", off}}) {
    for (int i = 0; i < 300; ++i) {
      std::string s = base;
      const int edits = 1 + static_cast<int>(rng() % 4);
      for (int k = 0; k < edits; ++k) {
        const size_t at = rng() % s.size();
        switch (rng() % 3) {
          case 0: s[at] = static_cast<char>(rng()); break;
          case 1: s.erase(at, 1 + rng() % 8); break;
          default: s.insert(at, 1, "0123456789 -\n/.e"[rng() % 16]);
        }
        if (s.empty()) s = "x";
      }
      const std::string path = dir.file(name);
      testing::writeBytes(path, s);
      auto r = readMeshFile(path);
      if (r.isOk()) {
        ++accepted;
        for (const auto& t : r->triangles)
          for (uint32_t v : t) ASSERT_LT(v, r->positions.size());
      } else {
        ++rejected;
        EXPECT_FALSE(r.status().message().empty());
      }
    }
  }
  EXPECT_GT(rejected, 0);
}

}  // namespace
}  // namespace scanpress
