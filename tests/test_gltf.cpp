// glTF output with compression and one node per tile (issue 24 part 1): every file passes the Khronos validator
// with no errors or warnings (it cannot look inside the compressed streams: an info says so), and read back through
// the libraries' own decoders (meshoptimizer's meshopt_decode*, Draco's Decoder), independent of our writer, it
// holds the triangles, normals and colors of the uncompressed decode, in world units (node transforms applied).
#include <gtest/gtest.h>

#include <draco/compression/decode.h>
#include <meshoptimizer.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <map>
#include <string>
#include <vector>

#include "engine/mesh.h"
#include "engine/shapes.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/gltf_writer.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs_util.h"

namespace scanpress {
namespace {

using nlohmann::json;
using testing::positionTriangles;
using testing::unbase64;

// The file's document and buffer 0 (the GLB's BIN chunk, or the .gltf's data URI).
void load(const std::string& path, json& doc, std::vector<uint8_t>& bin) {
  const auto bytes = testing::readBytes(path);
  if (bytes.size() >= 20 && std::memcmp(bytes.data(), "glTF", 4) == 0) {
    uint32_t json_len = 0, bin_len = 0;
    std::memcpy(&json_len, bytes.data() + 12, 4);
    doc = json::parse(std::string(bytes.begin() + 20, bytes.begin() + 20 + json_len));
    const size_t at = 20 + json_len;
    if (at + 8 <= bytes.size()) {
      std::memcpy(&bin_len, bytes.data() + at, 4);
      bin.assign(bytes.begin() + at + 8, bytes.begin() + at + 8 + bin_len);
    }
  } else {
    doc = json::parse(std::string(bytes.begin(), bytes.end()));
    const std::string uri = doc["buffers"][0].value("uri", "");
    bin = unbase64(uri.substr(uri.find(',') + 1));
  }
}

// The bytes of accessor `a` as `count` elements of `stride` bytes (meshopt views decoded with meshoptimizer).
std::vector<uint8_t> accessorBytes(const json& doc, const std::vector<uint8_t>& bin, const json& a, size_t elem) {
  const json& v = doc["bufferViews"][a["bufferView"].get<int>()];
  const size_t count = a["count"], stride = v.value("byteStride", elem);
  std::vector<uint8_t> raw;
  if (v.contains("extensions") && v["extensions"].contains("EXT_meshopt_compression")) {
    const json& m = v["extensions"]["EXT_meshopt_compression"];
    const uint8_t* src = bin.data() + m["byteOffset"].get<size_t>();
    const size_t n = m["byteLength"], mcount = m["count"], mstride = m["byteStride"];
    raw.resize(mcount * mstride);
    const int rc = m["mode"] == "TRIANGLES" ? meshopt_decodeIndexBuffer(raw.data(), mcount, mstride, src, n)
                                            : meshopt_decodeVertexBuffer(raw.data(), mcount, mstride, src, n);
    EXPECT_EQ(rc, 0) << "meshopt could not decode a view";
  } else {
    const size_t off = v.value("byteOffset", size_t(0));
    raw.assign(bin.begin() + off, bin.begin() + off + v["byteLength"].get<size_t>());
  }
  std::vector<uint8_t> out(count * elem);
  for (size_t i = 0; i < count; ++i) std::memcpy(&out[i * elem], &raw[i * stride + a.value("byteOffset", 0)], elem);
  return out;
}

template <typename T>
T at(const std::vector<uint8_t>& b, size_t i) {
  T v;
  std::memcpy(&v, b.data() + i * sizeof(T), sizeof(T));
  return v;
}

// Every node's mesh in world units, appended into one mesh (tile nodes repeat their border vertices).
// `uvs`: TEXCOORD_0 per vertex, when given (and present).
Mesh readBack(const std::string& path, std::vector<std::string>* node_names = nullptr,
              std::vector<std::array<float, 2>>* uvs = nullptr) {
  json doc;
  std::vector<uint8_t> bin;
  load(path, doc, bin);
  Mesh out;
  for (const json& node : doc["nodes"]) {
    if (node_names) node_names->push_back(node.value("name", ""));
    Vec3d t{0, 0, 0}, s{1, 1, 1};
    for (int k = 0; k < 3 && node.contains("translation"); ++k) t[k] = node["translation"][k];
    for (int k = 0; k < 3 && node.contains("scale"); ++k) s[k] = node["scale"][k];
    const json& prim = doc["meshes"][node["mesh"].get<int>()]["primitives"][0];
    const json& pa = doc["accessors"][prim["attributes"]["POSITION"].get<int>()];
    const bool quantized = pa["componentType"] == 5123;
    const uint32_t base = static_cast<uint32_t>(out.positions.size());
    if (prim.contains("extensions") && prim["extensions"].contains("KHR_draco_mesh_compression")) {
      const json& ext = prim["extensions"]["KHR_draco_mesh_compression"];
      const json& v = doc["bufferViews"][ext["bufferView"].get<int>()];
      draco::DecoderBuffer in;
      in.Init(reinterpret_cast<const char*>(bin.data()) + v.value("byteOffset", 0), v["byteLength"].get<size_t>());
      draco::Decoder dec;
      auto r = dec.DecodeMeshFromBuffer(&in);
      EXPECT_TRUE(r.ok());
      if (!r.ok()) return out;
      const draco::Mesh& d = *r.value();
      EXPECT_EQ(pa["count"].get<uint32_t>(), d.num_points());
      auto attr = [&](const char* name) {
        return ext["attributes"].contains(name) ? d.GetAttributeByUniqueId(ext["attributes"][name].get<uint32_t>())
                                                : nullptr;
      };
      const draco::PointAttribute *p = attr("POSITION"), *n = attr("NORMAL"), *c = attr("COLOR_0"),
                                  *tc = attr("TEXCOORD_0");
      for (uint32_t i = 0; i < d.num_points(); ++i) {
        double q[3];
        if (quantized) {
          uint16_t u[3];
          p->GetMappedValue(draco::PointIndex(i), u);
          for (int k = 0; k < 3; ++k) q[k] = u[k];
        } else {
          float f[3];
          p->GetMappedValue(draco::PointIndex(i), f);
          for (int k = 0; k < 3; ++k) q[k] = f[k];
        }
        out.positions.push_back({t[0] + s[0] * q[0], t[1] + s[1] * q[1], t[2] + s[2] * q[2]});
        if (n) {
          int16_t v16[3];
          n->GetMappedValue(draco::PointIndex(i), v16);
          out.normals.push_back({v16[0] / 32767.f, v16[1] / 32767.f, v16[2] / 32767.f});
        }
        if (c) {
          uint8_t rgba[4];
          c->GetMappedValue(draco::PointIndex(i), rgba);
          out.colors.push_back({rgba[0], rgba[1], rgba[2], rgba[3]});
        }
        if (tc && uvs) {
          std::array<float, 2> uv;
          tc->GetMappedValue(draco::PointIndex(i), uv.data());
          uvs->push_back(uv);
        }
      }
      for (uint32_t f = 0; f < d.num_faces(); ++f) {
        const auto& face = d.face(draco::FaceIndex(f));
        out.triangles.push_back({base + face[0].value(), base + face[1].value(), base + face[2].value()});
      }
      continue;
    }
    const size_t n = pa["count"];
    const auto pos = accessorBytes(doc, bin, pa, quantized ? 6 : 12);
    for (size_t i = 0; i < n; ++i) {
      Vec3d w;
      for (int k = 0; k < 3; ++k)
        w[k] = t[k] + s[k] * (quantized ? double(at<uint16_t>(pos, 3 * i + k)) : double(at<float>(pos, 3 * i + k)));
      out.positions.push_back(w);
    }
    if (prim["attributes"].contains("NORMAL")) {
      const json& na = doc["accessors"][prim["attributes"]["NORMAL"].get<int>()];
      const bool shorts = na["componentType"] == 5122;
      const auto nb = accessorBytes(doc, bin, na, shorts ? 6 : 12);
      for (size_t i = 0; i < n; ++i) {
        std::array<float, 3> v;
        for (int k = 0; k < 3; ++k) v[k] = shorts ? at<int16_t>(nb, 3 * i + k) / 32767.f : at<float>(nb, 3 * i + k);
        out.normals.push_back(v);
      }
    }
    if (prim["attributes"].contains("COLOR_0")) {
      const auto cb = accessorBytes(doc, bin, doc["accessors"][prim["attributes"]["COLOR_0"].get<int>()], 4);
      for (size_t i = 0; i < n; ++i) out.colors.push_back({cb[4 * i], cb[4 * i + 1], cb[4 * i + 2], cb[4 * i + 3]});
    }
    if (prim["attributes"].contains("TEXCOORD_0") && uvs) {
      const auto tb = accessorBytes(doc, bin, doc["accessors"][prim["attributes"]["TEXCOORD_0"].get<int>()], 8);
      for (size_t i = 0; i < n; ++i) uvs->push_back({at<float>(tb, 2 * i), at<float>(tb, 2 * i + 1)});
    }
    const json& ia = doc["accessors"][prim["indices"].get<int>()];
    const auto ib = accessorBytes(doc, bin, ia, 4);
    for (size_t i = 0; i + 2 < ia["count"].get<size_t>(); i += 3)
      out.triangles.push_back({base + at<uint32_t>(ib, i), base + at<uint32_t>(ib, i + 1),
                               base + at<uint32_t>(ib, i + 2)});
  }
  return out;
}

TEST(Gltf, CompressedAndTiledOutputsValidateAndReadBackThroughThePeersDecoders) {
  testing::TempDir dir;
  // A sphere with normals and colors, several tiles, 14 bits: quantized positions (KHR_mesh_quantization).
  Mesh sphere = icosphere(5);
  for (const auto& p : sphere.positions) {
    sphere.normals.push_back({float(p[0]), float(p[1]), float(p[2])});
    sphere.colors.push_back({uint8_t(128 + 127 * p[0]), uint8_t(128 + 127 * p[1]), uint8_t(128 + 127 * p[2]), 255});
  }
  sphere.color_channels = 3;
  ASSERT_TRUE(writePly(dir.file("s.ply"), sphere).isOk());
  std::string out;
  const std::string spz = dir.file("s.spz");
  ASSERT_EQ(testing::runScanpress("encode '" + dir.file("s.ply") + "' '" + spz +
                                      "' --bits 14 --tile-triangles 4096 --quiet",
                                  &out),
            0)
      << out;
  ASSERT_EQ(testing::runScanpress("decode '" + spz + "' '" + dir.file("ref.ply") + "' --quiet", &out), 0) << out;
  auto ref = readMeshFile(dir.file("ref.ply"));
  ASSERT_TRUE(ref.isOk());
  ASSERT_FALSE(ref->normals.empty());
  ASSERT_FALSE(ref->colors.empty());
  const auto want = positionTriangles(*ref);
  // Normal and color per position, for comparing attributes wherever the vertices went.
  std::map<std::array<float, 3>, size_t> at_position;
  for (size_t i = 0; i < ref->positions.size(); ++i)
    at_position[{float(ref->positions[i][0]), float(ref->positions[i][1]), float(ref->positions[i][2])}] = i;
  for (const char* compression : {"none", "meshopt", "draco"})
    for (const char* nodes : {"one", "tiles"})
      for (const char* ext : {".glb", ".gltf"}) {
        const std::string name = std::string(compression) + "-" + nodes + ext;
        SCOPED_TRACE(name);
        ASSERT_EQ(testing::runScanpress("decode '" + spz + "' '" + dir.file(name) + "' --gltf-compression " +
                                            compression + " --gltf-nodes " + nodes + " --quiet",
                                        &out),
                  0)
            << out;
        std::vector<std::string> names;
        const Mesh back = readBack(dir.file(name), &names);
        EXPECT_EQ(positionTriangles(back), want);
        if (std::string(nodes) == "tiles") {
          EXPECT_GT(names.size(), 2u);
          EXPECT_EQ(names[0].rfind("tile ", 0), 0u) << names[0];
        }
        ASSERT_EQ(back.normals.size(), back.positions.size());
        ASSERT_EQ(back.colors.size(), back.positions.size());
        size_t checked = 0;
        for (size_t i = 0; i < back.positions.size(); ++i) {
          auto it = at_position.find({float(back.positions[i][0]), float(back.positions[i][1]),
                                      float(back.positions[i][2])});
          if (it == at_position.end()) continue;  // an unused vertex Draco dropped has no triangle to compare
          ++checked;
          for (int k = 0; k < 3; ++k) {
            EXPECT_NEAR(back.normals[i][k], ref->normals[it->second][k], 2e-4);
            EXPECT_EQ(back.colors[i][k], ref->colors[it->second][k]);
          }
        }
        EXPECT_GE(checked, ref->positions.size() * 9 / 10);
        const std::string result = testing::validateGltf(dir.file(name), dir.path());
        if (result.rfind("SKIP", 0) == 0) {
          std::printf("[  SKIPPED ] %s: %s not validated\n", result.c_str(), name.c_str());
          continue;
        }
        EXPECT_NE(result.find("errors=0 warnings=0"), std::string::npos) << result;
      }
  // Compressed is smaller; the options are for glTF only and checked.
  EXPECT_LT(testing::readBytes(dir.file("meshopt-one.glb")).size(),
            testing::readBytes(dir.file("none-one.glb")).size() / 2);
  EXPECT_LT(testing::readBytes(dir.file("draco-one.glb")).size(),
            testing::readBytes(dir.file("meshopt-one.glb")).size());
  EXPECT_EQ(testing::runScanpress("decode '" + spz + "' '" + dir.file("x.ply") + "' --gltf-compression draco", &out),
            1);
  EXPECT_NE(out.find("glTF output"), std::string::npos) << out;
  EXPECT_EQ(testing::runScanpress("decode '" + spz + "' '" + dir.file("x.glb") + "' --gltf-compression zip", &out), 1);
  EXPECT_NE(out.find("none, meshopt, draco"), std::string::npos) << out;
  EXPECT_EQ(testing::runScanpress("decode '" + spz + "' '" + dir.file("x.glb") + "' --gltf-nodes some", &out), 1);
  EXPECT_NE(out.find("--gltf-nodes"), std::string::npos) << out;
}

// Texture coordinates (texcoords.h) as TEXCOORD_0, flipped to glTF's top-left origin (1 - v), with every
// compression: valid, and read back through the peers' decoders every corner has its position and coordinates.
TEST(Gltf, TextureCoordinatesAsTexcoord0) {
  testing::TempDir dir;
  std::string obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\n";
  obj += "vt 0 0\nvt 0.5 0\nvt 0.5 1\nvt 0 1\nvt 0.75 0.25\nvt 1 0.25\nvt 1 0.75\nvt 0.75 0.75\n";
  obj += "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\nf 2/5 5/6 6/7\nf 2/5 6/7 3/8\n";  // a seam along vertices 2 and 3
  testing::writeBytes(dir.file("q.obj"), obj);
  auto mesh = readMeshFile(dir.file("q.obj"));
  ASSERT_TRUE(mesh.isOk()) << mesh.status().toString();
  ASSERT_EQ(mesh->positions.size(), 8u);
  // Corners as (position, texture coordinate), per triangle, sorted.
  using Corner = std::array<float, 5>;
  auto corners = [](const Mesh& m, const std::vector<std::array<float, 2>>& uv) {
    std::vector<std::array<Corner, 3>> faces;
    for (const Triangle& t : m.triangles) {
      std::array<Corner, 3> f;
      for (int k = 0; k < 3; ++k) {
        const Vec3d& p = m.positions[t[size_t(k)]];
        f[size_t(k)] = {float(p[0]), float(p[1]), float(p[2]), uv[t[size_t(k)]][0], uv[t[size_t(k)]][1]};
      }
      std::rotate(f.begin(), std::min_element(f.begin(), f.end()), f.end());
      faces.push_back(f);
    }
    std::sort(faces.begin(), faces.end());
    return faces;
  };
  std::vector<std::array<float, 2>> want_uv;
  for (size_t i = 0; i < mesh->positions.size(); ++i)
    want_uv.push_back({std::bit_cast<float>(mesh->scalars[2 * i]),
                       1.f - std::bit_cast<float>(mesh->scalars[2 * i + 1])});
  const auto want = corners(*mesh, want_uv);
  for (const GltfCompression c : {GltfCompression::kNone, GltfCompression::kMeshopt, GltfCompression::kDraco}) {
    SCOPED_TRACE(int(c));
    WriteOptions o;
    o.gltf_compression = c;
    const std::string path = dir.file("q.glb");
    ASSERT_TRUE(writeGltf(path, *mesh, o).isOk());
    const std::string v = testing::validateGltf(path, dir.path());
    if (v.rfind("SKIP", 0) != 0) {
      EXPECT_NE(v.find("errors=0 warnings=0"), std::string::npos) << v;
    }
    std::vector<std::array<float, 2>> uv;
    const Mesh back = readBack(path, nullptr, &uv);
    ASSERT_EQ(uv.size(), back.positions.size());
    EXPECT_TRUE(corners(back, uv) == want);
  }
}

}  // namespace
}  // namespace scanpress
