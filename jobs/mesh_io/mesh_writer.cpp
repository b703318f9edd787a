#include "jobs/mesh_io/mesh_writer.h"

#include <zstd.h>

#include <charconv>
#include <cmath>
#include <cstring>
#include <vector>

#include "jobs/file_io.h"
#include "jobs/mesh_io/gltf_writer.h"

namespace scanpress {
namespace {

bool endsWith(const std::string& path, const char* ext) {
  const size_t n = std::strlen(ext);
  if (path.size() < n) return false;
  for (size_t i = 0; i < n; ++i)
    if (std::tolower(static_cast<unsigned char>(path[path.size() - n + i])) != ext[i]) return false;
  return true;
}

// Where a writer's bytes go: an AtomicFile, through zstd when the name ends in .zst (level 3: about as fast as the
// writers, and what `zstd` itself defaults to). Appears complete or not at all.
class MeshOutput {
 public:
  static Result<std::unique_ptr<MeshOutput>> create(const std::string& path) {
    SP_ASSIGN_OR_RETURN(auto file, AtomicFile::create(path));
    auto out = std::unique_ptr<MeshOutput>(new MeshOutput(std::move(file)));
    if (endsWith(path, ".zst")) {
      out->cctx_ = ZSTD_createCCtx();
      if (!out->cctx_) return makeError(ErrorCode::kIo, path + ": out of memory for zstd");
      ZSTD_CCtx_setParameter(out->cctx_, ZSTD_c_compressionLevel, 3);
      out->zbuf_.resize(ZSTD_CStreamOutSize());
    }
    return out;
  }
  ~MeshOutput() { ZSTD_freeCCtx(cctx_); }
  Status append(std::span<const uint8_t> bytes) { return compress(bytes, ZSTD_e_continue); }
  Status append(std::string_view text) {
    return append(std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
  }
  Status commit() {
    SP_RETURN_IF_ERROR(compress({}, ZSTD_e_end));
    return file_->commit();
  }

 private:
  explicit MeshOutput(std::unique_ptr<AtomicFile> file) : file_(std::move(file)) {}
  Status compress(std::span<const uint8_t> bytes, ZSTD_EndDirective mode) {
    if (!cctx_) return mode == ZSTD_e_end ? Status::ok() : file_->append(bytes);
    ZSTD_inBuffer in{bytes.data(), bytes.size(), 0};
    for (;;) {
      ZSTD_outBuffer out{zbuf_.data(), zbuf_.size(), 0};
      const size_t left = ZSTD_compressStream2(cctx_, &out, &in, mode);
      if (ZSTD_isError(left))
        return makeError(ErrorCode::kInternal, file_->path() + ": zstd: " + ZSTD_getErrorName(left));
      SP_RETURN_IF_ERROR(file_->append(std::span<const uint8_t>(zbuf_.data(), out.pos)));
      if (mode == ZSTD_e_end ? left == 0 : in.pos == in.size) return Status::ok();
    }
  }
  std::unique_ptr<AtomicFile> file_;
  ZSTD_CCtx* cctx_ = nullptr;
  std::vector<uint8_t> zbuf_;
};

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
    return makeError(ErrorCode::kLimitExceeded, path + ": mesh too large for an int32-indexed PLY/OBJ/OFF");
  return Status::ok();
}

}  // namespace

Status writePly(const std::string& path, const Mesh& mesh, const WriteOptions& options) {
  SP_RETURN_IF_ERROR(checkMesh(path, mesh));
  SP_ASSIGN_OR_RETURN(auto file, MeshOutput::create(path));
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
  SP_ASSIGN_OR_RETURN(auto file, MeshOutput::create(path));
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

Status writeStl(const std::string& path, const Mesh& mesh, const WriteOptions& /*options*/) {
  SP_RETURN_IF_ERROR(checkMesh(path, mesh));
  if (mesh.triangles.size() > UINT32_MAX)
    return makeError(ErrorCode::kLimitExceeded, path + ": more triangles than binary STL can count");
  SP_ASSIGN_OR_RETURN(auto file, MeshOutput::create(path));
  // Binary STL: an 80-byte header (which must not start with "solid", or readers take it for ASCII), the count,
  // then per triangle its facet normal, three corners (float) and a zero attribute word. Only geometry survives.
  std::vector<uint8_t> buf(80, ' ');
  const char title[] = "binary STL written by scanpress";
  std::memcpy(buf.data(), title, sizeof title - 1);
  putLe(buf, static_cast<uint32_t>(mesh.triangles.size()));
  for (const auto& t : mesh.triangles) {
    const Vec3d& a = mesh.positions[t[0]];
    const Vec3d& b = mesh.positions[t[1]];
    const Vec3d& c = mesh.positions[t[2]];
    const Vec3d u{b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v{c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    Vec3d n{u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (double x : n) putLe(buf, static_cast<float>(len > 0 ? x / len : 0.0));
    for (uint32_t i : t)
      for (double x : mesh.positions[i]) putLe(buf, static_cast<float>(x));
    putLe(buf, uint16_t{0});
    if (buf.size() >= (1u << 20)) {
      SP_RETURN_IF_ERROR(file->append(buf));
      buf.clear();
    }
  }
  SP_RETURN_IF_ERROR(file->append(buf));
  return file->commit();
}

Status writeOff(const std::string& path, const Mesh& mesh, const WriteOptions& options) {
  SP_RETURN_IF_ERROR(checkMesh(path, mesh));
  SP_ASSIGN_OR_RETURN(auto file, MeshOutput::create(path));
  // COFF when the mesh has colors (RGBA per vertex, as integers), OFF otherwise.
  const bool colors = !mesh.colors.empty();
  std::string buf = std::string(colors ? "COFF\n" : "OFF\n") + std::to_string(mesh.positions.size()) + " " +
                    std::to_string(mesh.triangles.size()) + " 0\n";
  char num[64];
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      const auto r = options.double_positions
                         ? std::to_chars(num, num + sizeof num, mesh.positions[i][k])
                         : std::to_chars(num, num + sizeof num, static_cast<float>(mesh.positions[i][k]));
      buf.append(num, r.ptr);
      buf += k < 2 ? ' ' : (colors ? ' ' : '\n');
    }
    if (colors)
      buf += std::to_string(mesh.colors[i][0]) + " " + std::to_string(mesh.colors[i][1]) + " " +
             std::to_string(mesh.colors[i][2]) + " " + std::to_string(mesh.colors[i][3]) + "\n";
    if (buf.size() >= (1u << 20)) {
      SP_RETURN_IF_ERROR(file->append(buf));
      buf.clear();
    }
  }
  for (const auto& t : mesh.triangles) {
    buf += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) + "\n";
    if (buf.size() >= (1u << 20)) {
      SP_RETURN_IF_ERROR(file->append(buf));
      buf.clear();
    }
  }
  SP_RETURN_IF_ERROR(file->append(buf));
  return file->commit();
}

Status writeMeshFile(const std::string& path, const Mesh& mesh, const WriteOptions& options) {
  const std::string base = endsWith(path, ".zst") ? path.substr(0, path.size() - 4) : path;
  if (endsWith(base, ".ply")) return writePly(path, mesh, options);
  if (endsWith(base, ".obj")) return writeObj(path, mesh, options);
  if (endsWith(base, ".stl")) return writeStl(path, mesh, options);
  if (endsWith(base, ".off")) return writeOff(path, mesh, options);
  if (base == path && (endsWith(path, ".glb") || endsWith(path, ".gltf"))) return writeGltf(path, mesh, options);
  return makeError(ErrorCode::kInvalidArgument,
                   path + ": output must end in .ply, .obj, .stl or .off (optionally .zst), .glb or .gltf");
}

}  // namespace scanpress
