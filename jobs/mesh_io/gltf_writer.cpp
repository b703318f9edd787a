#include "jobs/mesh_io/gltf_writer.h"

#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>
#include <meshoptimizer.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>
#include <vector>

#include "jobs/base64.h"
#include "jobs/file_io.h"
#include "jobs/mesh_io/texcoords.h"

namespace scanpress {
namespace {

using nlohmann::json;

constexpr int kFloat = 5126, kUnsignedByte = 5121, kShort = 5122, kUnsignedShort = 5123, kUnsignedInt = 5125;
constexpr int kArrayBuffer = 34962, kElementArrayBuffer = 34963;

template <typename T>
void put(std::vector<uint8_t>& out, T v) {
  uint8_t b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.insert(out.end(), b, b + sizeof(T));
}

void align4(std::vector<uint8_t>& b) {
  while (b.size() % 4) b.push_back(0);
}

// One part's vertex data in the layout glTF gets: every element a multiple of 4 bytes (glTF's vertex stride rule,
// and meshopt's vertex codec needs it).
struct Arrays {
  bool quantized = false;                // positions as uint16 grid cells (3 + 1 padding), else float
  std::vector<uint8_t> positions;        // stride 8 (quantized) or 12
  std::array<double, 3> pmin{}, pmax{};  // accessor bounds, in the accessor's units
  bool short_normals = false;            // normals as int16 normalized (3 + 1 padding), else float
  std::vector<uint8_t> normals;          // stride 8 or 12 (empty: none)
  std::vector<uint8_t> colors;           // RGBA8, stride 4 (empty: none)
  std::vector<uint8_t> texcoords;        // float (u, 1 - v), stride 8 (empty: none)
  std::vector<uint8_t> indices;          // uint32
  size_t vertices = 0, index_count = 0;
  size_t positionStride() const { return quantized ? 8 : 12; }
};

class Builder {
 public:
  Builder(const WriteOptions& o, const std::vector<GltfPart>& parts) : o_(o) {
    // One translation for every float part: the center of all parts' box (doubles in JSON; float relative to it).
    for (int a = 0; a < 3; ++a) lo_[a] = std::numeric_limits<double>::infinity(), hi_[a] = -lo_[a];
    for (const auto& part : parts)
      for (const auto& p : part.mesh->positions)
        for (int a = 0; a < 3; ++a) lo_[a] = std::min(lo_[a], p[a]), hi_[a] = std::max(hi_[a], p[a]);
    for (int a = 0; a < 3; ++a) center_[a] = (lo_[a] + hi_[a]) / 2;
    quantize_ = o.gltf_compression != GltfCompression::kNone && o.grid && o.grid->bits <= 16;
  }

  Status add(const GltfPart& part) {
    const Mesh& mesh = *part.mesh;
    if (mesh.positions.empty()) return Status::ok();
    if (mesh.positions.size() > UINT32_MAX - 1 || mesh.triangles.size() > (UINT32_MAX - 1) / 3)
      return makeError(ErrorCode::kLimitExceeded, "mesh too large for 32-bit glTF indices");
    const Arrays a = arrays(mesh);
    vertices_ = a.vertices;
    json primitive;
    if (o_.gltf_compression == GltfCompression::kDraco && a.index_count > 0) {
      SP_ASSIGN_OR_RETURN(primitive, dracoPrimitive(mesh, a));
    } else {
      SP_ASSIGN_OR_RETURN(primitive, plainPrimitive(a));
    }
    meshes_.push_back({{"primitives", json::array({primitive})}});
    json node = {{"mesh", meshes_.size() - 1}};
    if (!part.name.empty()) node["name"] = part.name;
    if (a.quantized) {
      const Grid& g = *o_.grid;
      node["translation"] = {g.origin[0] + 0.5 * g.cell, g.origin[1] + 0.5 * g.cell, g.origin[2] + 0.5 * g.cell};
      node["scale"] = {g.cell, g.cell, g.cell};
      used_quantization_ = true;
    } else {
      node["translation"] = center_;
    }
    nodes_.push_back(std::move(node));
    return Status::ok();
  }

  // The document and the binary buffer (buffer 0).
  Status finish(const std::string& path) {
    const bool binary = path.size() >= 4 && (path.compare(path.size() - 4, 4, ".glb") == 0 ||
                                             path.compare(path.size() - 4, 4, ".GLB") == 0);
    json doc;
    doc["asset"] = {{"version", "2.0"}, {"generator", "scanpress"}};
    doc["scene"] = 0;
    json scene_nodes = json::array();
    for (size_t i = 0; i < nodes_.size(); ++i) scene_nodes.push_back(i);
    doc["scenes"] = json::array({nodes_.empty() ? json::object() : json{{"nodes", scene_nodes}}});
    align4(bin_);  // the GLB chunk's length must be a multiple of 4 (the compressed views end anywhere)
    if (!nodes_.empty()) {
      json buffer = {{"byteLength", bin_.size()}};
      if (!binary) buffer["uri"] = "data:application/octet-stream;base64," + base64(bin_);
      json buffers = json::array({buffer});
      if (fallback_bytes_ > 0)  // meshopt: the uncompressed views' buffer, which has no data of its own
        buffers.push_back({{"byteLength", fallback_bytes_},
                           {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}});
      doc["buffers"] = std::move(buffers);
      doc["bufferViews"] = views_;
      doc["accessors"] = accessors_;
      doc["meshes"] = meshes_;
      doc["nodes"] = nodes_;
      json used = json::array();
      if (fallback_bytes_ > 0) used.push_back("EXT_meshopt_compression");
      if (used_draco_) used.push_back("KHR_draco_mesh_compression");
      if (used_quantization_) used.push_back("KHR_mesh_quantization");
      if (!used.empty()) doc["extensionsUsed"] = used, doc["extensionsRequired"] = used;
    }
    if (binary) {
      std::string text = doc.dump();
      while (text.size() % 4) text += ' ';
      std::vector<uint8_t> out;
      put(out, uint32_t{0x46546C67});  // "glTF"
      put(out, uint32_t{2});
      const bool has_bin = !nodes_.empty();
      put(out, static_cast<uint32_t>(12 + 8 + text.size() + (has_bin ? 8 + bin_.size() : 0)));
      put(out, static_cast<uint32_t>(text.size()));
      put(out, uint32_t{0x4E4F534A});  // "JSON"
      out.insert(out.end(), text.begin(), text.end());
      if (has_bin) {
        put(out, static_cast<uint32_t>(bin_.size()));
        put(out, uint32_t{0x004E4942});  // "BIN\0"
        out.insert(out.end(), bin_.begin(), bin_.end());
      }
      if (out.size() > UINT32_MAX)
        return makeError(ErrorCode::kLimitExceeded, path + ": larger than a GLB can be (4 GiB)");
      return writeFileAtomically(path, out);
    }
    const std::string text = doc.dump() + "\n";
    return writeFileAtomically(path, std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
  }

 private:
  Arrays arrays(const Mesh& mesh) const {
    Arrays a;
    a.vertices = mesh.positions.size();
    a.quantized = quantize_;
    for (int k = 0; k < 3; ++k) a.pmin[k] = std::numeric_limits<double>::max(), a.pmax[k] = -a.pmin[k];
    for (const auto& p : mesh.positions) {
      for (int k = 0; k < 3; ++k) {
        double v;
        if (a.quantized) {  // the cell the (cell-centered) position lies in
          const Grid& g = *o_.grid;
          v = std::clamp(std::floor((p[k] - g.origin[k]) / g.cell), 0.0, double(g.maxCoord()));
          put(a.positions, static_cast<uint16_t>(v));
        } else {
          const float f = static_cast<float>(p[k] - center_[k]);
          put(a.positions, f);
          v = f;
        }
        a.pmin[k] = std::min(a.pmin[k], v), a.pmax[k] = std::max(a.pmax[k], v);
      }
      if (a.quantized) put(a.positions, uint16_t{0});
    }
    // Compressed, normals are 16-bit normalized (KHR_mesh_quantization): finer than the container's octahedral
    // normals (at most 16 bits for two components), and what the codecs compress far better than floats.
    a.short_normals = o_.gltf_compression != GltfCompression::kNone;
    for (const auto& n : mesh.normals) {
      const double len = std::sqrt(double(n[0]) * n[0] + double(n[1]) * n[1] + double(n[2]) * n[2]);
      for (int k = 0; k < 3; ++k) {
        const double u = len > 0 ? n[k] / len : (k == 2 ? 1.0 : 0.0);
        if (a.short_normals) put(a.normals, static_cast<int16_t>(std::lround(std::clamp(u, -1.0, 1.0) * 32767)));
        else put(a.normals, static_cast<float>(u));
      }
      if (a.short_normals) put(a.normals, int16_t{0});
    }
    for (const auto& c : mesh.colors)
      a.colors.insert(a.colors.end(), {c[0], c[1], c[2], mesh.color_channels == 4 ? c[3] : uint8_t(255)});
    // Texture coordinates (texcoords.h): glTF's origin is the image's top left, OBJ's and PLY's its bottom left.
    if (const auto tc = findTexcoords(mesh.scalar_channels)) {
      const size_t stride = scalarWords(mesh.scalar_channels);
      for (size_t i = 0; i < a.vertices; ++i) {
        const uint32_t* words = mesh.scalars.data() + i * stride;
        put(a.texcoords, static_cast<float>(floatChannelValue(mesh.scalar_channels[tc->u], words + tc->u_word)));
        put(a.texcoords, static_cast<float>(1.0 - floatChannelValue(mesh.scalar_channels[tc->v], words + tc->v_word)));
      }
    }
    for (const auto& t : mesh.triangles)
      for (uint32_t v : t) put(a.indices, v);
    a.index_count = mesh.triangles.size() * 3;
    if (o_.gltf_compression == GltfCompression::kMeshopt && a.index_count > 0) reorderForMeshopt(a);
    return a;
  }

  // The order meshoptimizer's codecs compress best (what gltfpack does): triangles for the vertex cache, then
  // vertices in first-use order; the same triangles over the same vertices.
  static void reorderForMeshopt(Arrays& a) {
    auto* idx = reinterpret_cast<unsigned int*>(a.indices.data());
    meshopt_optimizeVertexCache(idx, idx, a.index_count, a.vertices);
    std::vector<unsigned int> remap(a.vertices);
    const size_t used = meshopt_optimizeVertexFetchRemap(remap.data(), idx, a.index_count, a.vertices);
    // Unreferenced vertices (points of a soup, stray vertices) keep their place after the used ones.
    size_t next = used;
    for (auto& r : remap)
      if (r == ~0u) r = static_cast<unsigned int>(next++);
    meshopt_remapIndexBuffer(idx, idx, a.index_count, remap.data());
    auto apply = [&](std::vector<uint8_t>& data, size_t stride) {
      if (data.empty()) return;
      std::vector<uint8_t> out(data.size());
      for (size_t v = 0; v < a.vertices; ++v) std::memcpy(&out[remap[v] * stride], &data[v * stride], stride);
      data.swap(out);
    };
    apply(a.positions, a.positionStride());
    apply(a.normals, a.short_normals ? 8 : 12);
    apply(a.colors, 4);
    apply(a.texcoords, 8);
  }

  // A buffer view of `data`: appended to buffer 0 as is, or with meshopt, compressed into buffer 0 and described
  // at its place in the fallback buffer. `stride` 0: indices.
  Result<size_t> view(const std::vector<uint8_t>& data, size_t count, size_t stride, int target) {
    json v;
    if (o_.gltf_compression != GltfCompression::kMeshopt) {
      align4(bin_);
      v = {{"buffer", 0}, {"byteOffset", bin_.size()}, {"byteLength", data.size()}, {"target", target}};
      if (stride) v["byteStride"] = stride;
      bin_.insert(bin_.end(), data.begin(), data.end());
    } else {
      std::vector<uint8_t> packed;
      std::string mode;
      size_t ext_stride = stride;
      if (stride) {
        meshopt_encodeVertexVersion(0);
        packed.resize(meshopt_encodeVertexBufferBound(count, stride));
        packed.resize(meshopt_encodeVertexBuffer(packed.data(), packed.size(), data.data(), count, stride));
        mode = "ATTRIBUTES";
      } else {
        meshopt_encodeIndexVersion(1);
        packed.resize(meshopt_encodeIndexBufferBound(count, vertices_));
        packed.resize(meshopt_encodeIndexBuffer(packed.data(), packed.size(),
                                                reinterpret_cast<const unsigned int*>(data.data()), count));
        mode = "TRIANGLES";
        ext_stride = 4;
      }
      if (packed.empty()) return makeError(ErrorCode::kInternal, "meshoptimizer could not encode a buffer view");
      align4(bin_);
      const size_t at = bin_.size();
      bin_.insert(bin_.end(), packed.begin(), packed.end());
      fallback_bytes_ = (fallback_bytes_ + 3) / 4 * 4;
      v = {{"buffer", 1}, {"byteOffset", fallback_bytes_}, {"byteLength", data.size()}, {"target", target}};
      if (stride) v["byteStride"] = stride;
      v["extensions"] = {{"EXT_meshopt_compression",
                          {{"buffer", 0},
                           {"byteOffset", at},
                           {"byteLength", packed.size()},
                           {"byteStride", ext_stride},
                           {"count", count},
                           {"mode", mode}}}};
      fallback_bytes_ += data.size();
    }
    views_.push_back(std::move(v));
    return views_.size() - 1;
  }

  json positionAccessor(const Arrays& a, size_t count) const {
    json acc = {{"componentType", a.quantized ? kUnsignedShort : kFloat},
                {"count", count},
                {"type", "VEC3"},
                {"min", a.pmin},
                {"max", a.pmax}};
    return acc;
  }

  Result<json> plainPrimitive(const Arrays& a) {
    json attributes;
    json acc = positionAccessor(a, a.vertices);
    SP_ASSIGN_OR_RETURN(acc["bufferView"], view(a.positions, a.vertices, a.positionStride(), kArrayBuffer));
    accessors_.push_back(std::move(acc));
    attributes["POSITION"] = accessors_.size() - 1;
    if (!a.normals.empty()) {
      SP_ASSIGN_OR_RETURN(size_t v, view(a.normals, a.vertices, a.short_normals ? 8 : 12, kArrayBuffer));
      json acc = {{"bufferView", v},
                  {"componentType", a.short_normals ? kShort : kFloat},
                  {"count", a.vertices},
                  {"type", "VEC3"}};
      if (a.short_normals) acc["normalized"] = true, used_quantization_ = true;
      accessors_.push_back(std::move(acc));
      attributes["NORMAL"] = accessors_.size() - 1;
    }
    if (!a.colors.empty()) {
      SP_ASSIGN_OR_RETURN(size_t v, view(a.colors, a.vertices, 4, kArrayBuffer));
      accessors_.push_back({{"bufferView", v},
                            {"componentType", kUnsignedByte},
                            {"normalized", true},
                            {"count", a.vertices},
                            {"type", "VEC4"}});
      attributes["COLOR_0"] = accessors_.size() - 1;
    }
    if (!a.texcoords.empty()) {
      SP_ASSIGN_OR_RETURN(size_t v, view(a.texcoords, a.vertices, 8, kArrayBuffer));
      accessors_.push_back({{"bufferView", v}, {"componentType", kFloat}, {"count", a.vertices}, {"type", "VEC2"}});
      attributes["TEXCOORD_0"] = accessors_.size() - 1;
    }
    json primitive = {{"attributes", attributes}};
    if (a.index_count == 0) {
      primitive["mode"] = 0;  // points
    } else {
      SP_ASSIGN_OR_RETURN(size_t v, view(a.indices, a.index_count, 0, kElementArrayBuffer));
      accessors_.push_back({{"bufferView", v},
                            {"componentType", kUnsignedInt},
                            {"count", a.index_count},
                            {"type", "SCALAR"}});
      primitive["indices"] = accessors_.size() - 1;
      primitive["mode"] = 4;
    }
    return primitive;
  }

  // KHR_draco_mesh_compression: the primitive's data is one Draco stream; the accessors have no buffer views and
  // carry the counts (and the position bounds) of Draco's decode of it, which may split or merge vertices.
  Result<json> dracoPrimitive(const Mesh& mesh, const Arrays& a) {
    draco::Mesh dm;
    const uint32_t n = static_cast<uint32_t>(a.vertices);
    dm.set_num_points(n);
    auto attribute = [&](draco::GeometryAttribute::Type type, int comps, draco::DataType dt, bool normalized,
                         int bytes_per, const std::vector<uint8_t>& data, size_t stride) {
      draco::GeometryAttribute ga;
      ga.Init(type, nullptr, comps, dt, normalized, comps * bytes_per, 0);
      const int id = dm.AddAttribute(ga, true, n);
      for (uint32_t i = 0; i < n; ++i)
        dm.attribute(id)->SetAttributeValue(draco::AttributeValueIndex(i), data.data() + i * stride);
      return id;
    };
    const int pos = a.quantized ? attribute(draco::GeometryAttribute::POSITION, 3, draco::DT_UINT16, false, 2,
                                            a.positions, a.positionStride())
                                : attribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false, 4,
                                            a.positions, a.positionStride());
    // Normals as a generic attribute: Draco's normal-specific prediction assumes float normals and decodes 16-bit
    // integer ones wrongly (measured: values near 0); glTF matches attributes by id, not by Draco's type.
    const int nor = a.normals.empty()
                        ? -1
                        : attribute(draco::GeometryAttribute::GENERIC, 3, draco::DT_INT16, true, 2, a.normals, 8);
    const int col =
        a.colors.empty() ? -1 : attribute(draco::GeometryAttribute::COLOR, 4, draco::DT_UINT8, true, 1, a.colors, 4);
    const int tex = a.texcoords.empty() ? -1
                                        : attribute(draco::GeometryAttribute::TEX_COORD, 2, draco::DT_FLOAT32, false,
                                                    4, a.texcoords, 8);
    for (const auto& t : mesh.triangles)
      dm.AddFace({draco::PointIndex(t[0]), draco::PointIndex(t[1]), draco::PointIndex(t[2])});
    draco::Encoder enc;
    enc.SetSpeedOptions(3, 3);  // Draco's -cl 7: its default trade of size and speed
    enc.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
    draco::EncoderBuffer buffer;
    if (auto st = enc.EncodeMeshToBuffer(dm, &buffer); !st.ok())
      return makeError(ErrorCode::kInternal, std::string("Draco could not encode the mesh: ") + st.error_msg());
    draco::DecoderBuffer in;
    in.Init(buffer.data(), buffer.size());
    draco::Decoder dec;
    auto decoded = dec.DecodeMeshFromBuffer(&in);
    if (!decoded.ok())
      return makeError(ErrorCode::kInternal,
                       std::string("Draco could not decode its own stream: ") + decoded.status().error_msg());
    const draco::Mesh& d = *decoded.value();
    // The bounds of the positions as decoded.
    Arrays bounds = a;
    const draco::PointAttribute* dp = d.GetNamedAttribute(draco::GeometryAttribute::POSITION);
    if (!dp) return makeError(ErrorCode::kInternal, "Draco's decode has no positions");
    for (int k = 0; k < 3; ++k) bounds.pmin[k] = std::numeric_limits<double>::max(), bounds.pmax[k] = -bounds.pmin[k];
    for (uint32_t i = 0; i < d.num_points(); ++i) {
      double v[3];
      if (a.quantized) {
        uint16_t q[3];
        dp->GetMappedValue(draco::PointIndex(i), q);
        for (int k = 0; k < 3; ++k) v[k] = q[k];
      } else {
        float f[3];
        dp->GetMappedValue(draco::PointIndex(i), f);
        for (int k = 0; k < 3; ++k) v[k] = f[k];
      }
      for (int k = 0; k < 3; ++k)
        bounds.pmin[k] = std::min(bounds.pmin[k], v[k]), bounds.pmax[k] = std::max(bounds.pmax[k], v[k]);
    }
    align4(bin_);
    views_.push_back({{"buffer", 0}, {"byteOffset", bin_.size()}, {"byteLength", buffer.size()}});
    bin_.insert(bin_.end(), buffer.data(), buffer.data() + buffer.size());
    const size_t draco_view = views_.size() - 1;
    json attributes, ids;
    accessors_.push_back(positionAccessor(bounds, d.num_points()));
    attributes["POSITION"] = accessors_.size() - 1;
    ids["POSITION"] = dm.attribute(pos)->unique_id();
    if (nor >= 0) {
      accessors_
          .push_back({{"componentType", kShort}, {"normalized", true}, {"count", d.num_points()}, {"type", "VEC3"}});
      used_quantization_ = true;
      attributes["NORMAL"] = accessors_.size() - 1;
      ids["NORMAL"] = dm.attribute(nor)->unique_id();
    }
    if (col >= 0) {
      accessors_.push_back({{"componentType", kUnsignedByte},
                            {"normalized", true},
                            {"count", d.num_points()},
                            {"type", "VEC4"}});
      attributes["COLOR_0"] = accessors_.size() - 1;
      ids["COLOR_0"] = dm.attribute(col)->unique_id();
    }
    if (tex >= 0) {
      accessors_.push_back({{"componentType", kFloat}, {"count", d.num_points()}, {"type", "VEC2"}});
      attributes["TEXCOORD_0"] = accessors_.size() - 1;
      ids["TEXCOORD_0"] = dm.attribute(tex)->unique_id();
    }
    accessors_.push_back({{"componentType", kUnsignedInt}, {"count", size_t(d.num_faces()) * 3}, {"type", "SCALAR"}});
    used_draco_ = true;
    return json{{"attributes", attributes},
                {"indices", accessors_.size() - 1},
                {"mode", 4},
                {"extensions", {{"KHR_draco_mesh_compression", {{"bufferView", draco_view}, {"attributes", ids}}}}}};
  }

  const WriteOptions& o_;
  Vec3d lo_{}, hi_{}, center_{};
  bool quantize_ = false;
  std::vector<uint8_t> bin_;
  size_t fallback_bytes_ = 0;
  size_t vertices_ = 0;  // of the part being added (meshopt's index codec bound)
  json views_ = json::array(), accessors_ = json::array(), meshes_ = json::array(), nodes_ = json::array();
  bool used_draco_ = false, used_quantization_ = false;
};

}  // namespace

const char* gltfCompressionName(GltfCompression c) {
  switch (c) {
    case GltfCompression::kNone: return "none";
    case GltfCompression::kMeshopt: return "meshopt";
    case GltfCompression::kDraco: return "draco";
  }
  return "none";
}

Result<GltfCompression> parseGltfCompression(const std::string& name) {
  for (GltfCompression c : {GltfCompression::kNone, GltfCompression::kMeshopt, GltfCompression::kDraco})
    if (name == gltfCompressionName(c)) return c;
  return makeError(ErrorCode::kInvalidArgument,
                   "unknown glTF compression '" + name + "' (available: none, meshopt, draco)");
}

Status writeGltfParts(const std::string& path, const std::vector<GltfPart>& parts, const WriteOptions& options) {
  Builder b(options, parts);
  for (const auto& part : parts) {
    if (Status st = b.add(part); !st.isOk()) return st.withContext(path);
  }
  return b.finish(path);
}

Status writeGltf(const std::string& path, const Mesh& mesh, const WriteOptions& options) {
  return writeGltfParts(path, {GltfPart{"", &mesh}}, options);
}

}  // namespace scanpress
