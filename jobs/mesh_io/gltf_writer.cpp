#include "jobs/mesh_io/gltf_writer.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>
#include <vector>

#include "jobs/base64.h"
#include "jobs/file_io.h"

namespace scanpress {
namespace {

using nlohmann::json;

constexpr int kFloat = 5126, kUnsignedByte = 5121, kUnsignedInt = 5125;
constexpr int kArrayBuffer = 34962, kElementArrayBuffer = 34963;

template <typename T>
void put(std::vector<uint8_t>& out, T v) {
  uint8_t b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.insert(out.end(), b, b + sizeof(T));
}

}  // namespace

Status writeGltf(const std::string& path, const Mesh& mesh, const WriteOptions& /*options*/) {
  if (mesh.positions.size() > UINT32_MAX - 1 || mesh.triangles.size() > (UINT32_MAX - 1) / 3)
    return makeError(ErrorCode::kLimitExceeded, path + ": mesh too large for 32-bit glTF indices");
  const bool binary = path.size() >= 4 &&
                      (path.compare(path.size() - 4, 4, ".glb") == 0 || path.compare(path.size() - 4, 4, ".GLB") == 0);
  json doc;
  doc["asset"] = {{"version", "2.0"}, {"generator", "scanpress"}};
  doc["scene"] = 0;
  if (mesh.positions.empty()) {  // nothing to draw: a valid, empty scene
    doc["scenes"] = json::array({json::object()});
  } else {
    // The node's translation: the bounding box's center (doubles in JSON); positions relative to it in float.
    Vec3d lo{}, hi{};
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::numeric_limits<double>::infinity();
      hi[a] = -lo[a];
    }
    for (const auto& p : mesh.positions)
      for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
    const Vec3d center{(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2};
    std::vector<uint8_t> bin;
    json views = json::array(), accessors = json::array(), attributes = json::object();
    auto view = [&](size_t start, int target) {
      while (bin.size() % 4) bin.push_back(0);  // (start is already aligned: every view's size is a multiple of 4)
      views.push_back({{"buffer", 0}, {"byteOffset", start}, {"byteLength", bin.size() - start}, {"target", target}});
      return views.size() - 1;
    };
    // Positions, with their float bounds (required).
    size_t start = bin.size();
    std::array<float, 3> fmin{}, fmax{};
    for (int a = 0; a < 3; ++a) fmin[a] = std::numeric_limits<float>::max(), fmax[a] = -fmin[a];
    for (const auto& p : mesh.positions)
      for (int a = 0; a < 3; ++a) {
        const float f = static_cast<float>(p[a] - center[a]);
        put(bin, f);
        fmin[a] = std::min(fmin[a], f), fmax[a] = std::max(fmax[a], f);
      }
    accessors.push_back({{"bufferView", view(start, kArrayBuffer)},
                         {"componentType", kFloat},
                         {"count", mesh.positions.size()},
                         {"type", "VEC3"},
                         {"min", fmin},
                         {"max", fmax}});
    attributes["POSITION"] = accessors.size() - 1;
    if (!mesh.normals.empty()) {
      start = bin.size();
      for (const auto& n : mesh.normals) {
        const double len = std::sqrt(double(n[0]) * n[0] + double(n[1]) * n[1] + double(n[2]) * n[2]);
        for (int a = 0; a < 3; ++a) put(bin, static_cast<float>(len > 0 ? n[a] / len : (a == 2 ? 1.0 : 0.0)));
      }
      accessors.push_back({{"bufferView", view(start, kArrayBuffer)},
                           {"componentType", kFloat},
                           {"count", mesh.normals.size()},
                           {"type", "VEC3"}});
      attributes["NORMAL"] = accessors.size() - 1;
    }
    if (!mesh.colors.empty()) {  // RGBA8: 4-byte elements keep the vertex stride aligned, as glTF requires
      start = bin.size();
      for (const auto& c : mesh.colors)
        bin.insert(bin.end(), {c[0], c[1], c[2], mesh.color_channels == 4 ? c[3] : uint8_t(255)});
      accessors.push_back({{"bufferView", view(start, kArrayBuffer)},
                           {"componentType", kUnsignedByte},
                           {"normalized", true},
                           {"count", mesh.colors.size()},
                           {"type", "VEC4"}});
      attributes["COLOR_0"] = accessors.size() - 1;
    }
    json primitive = {{"attributes", attributes}};
    if (mesh.triangles.empty()) {
      primitive["mode"] = 0;  // points
    } else {
      start = bin.size();
      for (const auto& t : mesh.triangles)
        for (uint32_t v : t) put(bin, v);
      accessors.push_back({{"bufferView", view(start, kElementArrayBuffer)},
                           {"componentType", kUnsignedInt},
                           {"count", mesh.triangles.size() * 3},
                           {"type", "SCALAR"}});
      primitive["indices"] = accessors.size() - 1;
      primitive["mode"] = 4;
    }
    json buffer = {{"byteLength", bin.size()}};
    if (!binary) buffer["uri"] = "data:application/octet-stream;base64," + base64(bin);
    doc["buffers"] = json::array({buffer});
    doc["bufferViews"] = std::move(views);
    doc["accessors"] = std::move(accessors);
    doc["meshes"] = json::array({{{"primitives", json::array({primitive})}}});
    doc["nodes"] = json::array({{{"mesh", 0}, {"translation", center}}});
    doc["scenes"] = json::array({{{"nodes", json::array({0})}}});
    if (binary) {
      std::string text = doc.dump();
      while (text.size() % 4) text += ' ';
      std::vector<uint8_t> out;
      put(out, uint32_t{0x46546C67});  // "glTF"
      put(out, uint32_t{2});
      put(out, static_cast<uint32_t>(12 + 8 + text.size() + 8 + bin.size()));
      put(out, static_cast<uint32_t>(text.size()));
      put(out, uint32_t{0x4E4F534A});  // "JSON"
      out.insert(out.end(), text.begin(), text.end());
      put(out, static_cast<uint32_t>(bin.size()));
      put(out, uint32_t{0x004E4942});  // "BIN\0"
      out.insert(out.end(), bin.begin(), bin.end());
      if (out.size() > UINT32_MAX)
        return makeError(ErrorCode::kLimitExceeded, path + ": larger than a GLB can be (4 GiB)");
      return writeFileAtomically(path, out);
    }
  }
  const std::string text = doc.dump() + "\n";
  return writeFileAtomically(path, std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
}

}  // namespace scanpress
