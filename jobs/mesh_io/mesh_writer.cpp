#include "jobs/mesh_io/mesh_writer.h"

#include <charconv>
#include <cstring>
#include <vector>

#include "jobs/file_io.h"

namespace scanpress {
namespace {

template <typename T>
void putLe(std::vector<uint8_t>& out, T v) {
  uint8_t b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.insert(out.end(), b, b + sizeof(T));
}

Status checkMesh(const std::string& path, const Mesh& mesh) {
  if (!mesh.normals.empty() && mesh.normals.size() != mesh.positions.size())
    return makeError(ErrorCode::kInternal, path + ": normals do not match vertices");
  if (!mesh.colors.empty() && mesh.colors.size() != mesh.positions.size())
    return makeError(ErrorCode::kInternal, path + ": colors do not match vertices");
  if (mesh.triangles.size() > 0x7FFFFFFF || mesh.positions.size() > 0x7FFFFFFF)
    return makeError(ErrorCode::kLimitExceeded, path + ": mesh too large for an int32-indexed PLY/OBJ");
  return Status::ok();
}

}  // namespace

Status writePly(const std::string& path, const Mesh& mesh, const WriteOptions& options) {
  SP_RETURN_IF_ERROR(checkMesh(path, mesh));
  SP_ASSIGN_OR_RETURN(auto file, AtomicFile::create(path));
  const bool normals = !mesh.normals.empty();
  const bool colors = !mesh.colors.empty();
  const bool alpha = colors && mesh.color_channels == 4;
  std::string header = "ply\nformat binary_little_endian 1.0\ncomment written by scanpress\n";
  header += "element vertex " + std::to_string(mesh.positions.size()) + "\n";
  const char* t = options.double_positions ? "double" : "float";
  for (const char* axis : {"x", "y", "z"}) header += std::string("property ") + t + " " + axis + "\n";
  if (normals) header += "property float nx\nproperty float ny\nproperty float nz\n";
  if (colors) header += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  if (alpha) header += "property uchar alpha\n";
  header += "element face " + std::to_string(mesh.triangles.size()) + "\n";
  header += "property list uchar int vertex_indices\nend_header\n";
  SP_RETURN_IF_ERROR(file->append(header));
  std::vector<uint8_t> buf;
  buf.reserve(1u << 20);
  auto drain = [&]() -> Status {
    if (buf.size() < (1u << 20) - 64) return Status::ok();
    Status s = file->append(buf);
    buf.clear();
    return s;
  };
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    for (double c : mesh.positions[i]) {
      if (options.double_positions) putLe(buf, c);
      else putLe(buf, static_cast<float>(c));
    }
    if (normals)
      for (float c : mesh.normals[i]) putLe(buf, c);
    if (colors) buf.insert(buf.end(), mesh.colors[i].begin(), mesh.colors[i].begin() + (alpha ? 4 : 3));
    SP_RETURN_IF_ERROR(drain());
  }
  for (const auto& tri : mesh.triangles) {
    buf.push_back(3);
    for (uint32_t v : tri) putLe(buf, static_cast<int32_t>(v));
    SP_RETURN_IF_ERROR(drain());
  }
  SP_RETURN_IF_ERROR(file->append(buf));
  return file->commit();
}

Status writeObj(const std::string& path, const Mesh& mesh, const WriteOptions& options) {
  SP_RETURN_IF_ERROR(checkMesh(path, mesh));
  SP_ASSIGN_OR_RETURN(auto file, AtomicFile::create(path));
  std::string buf;
  buf.reserve(1u << 20);
  char num[64];
  auto put = [&](double v, bool dbl) {
    auto r = dbl ? std::to_chars(num, num + sizeof num, v)
                 : std::to_chars(num, num + sizeof num, static_cast<float>(v));
    buf.append(num, r.ptr);
  };
  auto drain = [&]() -> Status {
    if (buf.size() < (1u << 20) - 256) return Status::ok();
    Status s = file->append(buf);
    buf.clear();
    return s;
  };
  buf += "# written by scanpress\n";
  const bool colors = !mesh.colors.empty();
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    buf += "v";
    for (double c : mesh.positions[i]) buf += ' ', put(c, options.double_positions);
    if (colors)
      for (int k = 0; k < 3; ++k) buf += ' ', put(mesh.colors[i][k] / 255.0, false);
    buf += '\n';
    SP_RETURN_IF_ERROR(drain());
  }
  const bool normals = !mesh.normals.empty();
  for (const auto& n : mesh.normals) {
    buf += "vn";
    for (float c : n) buf += ' ', put(c, false);
    buf += '\n';
    SP_RETURN_IF_ERROR(drain());
  }
  for (const auto& tri : mesh.triangles) {
    buf += 'f';
    for (uint32_t v : tri) {
      buf += ' ';
      buf += std::to_string(v + 1);
      if (normals) buf += "//" + std::to_string(v + 1);
    }
    buf += '\n';
    SP_RETURN_IF_ERROR(drain());
  }
  SP_RETURN_IF_ERROR(file->append(buf));
  return file->commit();
}

Status writeMeshFile(const std::string& path, const Mesh& mesh, const WriteOptions& options) {
  auto ends = [&](const char* ext) {
    const size_t n = std::strlen(ext);
    if (path.size() < n) return false;
    for (size_t i = 0; i < n; ++i)
      if (std::tolower(static_cast<unsigned char>(path[path.size() - n + i])) != ext[i]) return false;
    return true;
  };
  if (ends(".ply")) return writePly(path, mesh, options);
  if (ends(".obj")) return writeObj(path, mesh, options);
  return makeError(ErrorCode::kInvalidArgument, path + ": output must end in .ply or .obj");
}

}  // namespace scanpress
