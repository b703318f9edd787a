#include "jobs/mesh_io/mesh_writer.h"

#include <zstd.h>

#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <vector>

#include <unordered_map>

#include "jobs/file_io.h"
#include "jobs/mesh_io/gltf_writer.h"
#include "jobs/mesh_io/texcoords.h"

namespace scanpress {
namespace {

bool endsWith(const std::string& path, const char* ext) {
  const size_t n = std::strlen(ext);
  if (path.size() < n) return false;
  for (size_t i = 0; i < n; ++i)
    if (std::tolower(static_cast<unsigned char>(path[path.size() - n + i])) != ext[i]) return false;
  return true;
}

}  // namespace

// Where a writer's bytes go: an AtomicFile, through zstd when the name ends in .zst (level 3: about as fast as the
// writers, and what `zstd` itself defaults to). Appears complete or not at all.
class MeshFileWriter::Output {
 public:
  static Result<std::unique_ptr<Output>> create(const std::string& path) {
    SP_ASSIGN_OR_RETURN(auto file, AtomicFile::create(path));
    auto out = std::unique_ptr<Output>(new Output(std::move(file)));
    if (endsWith(path, ".zst")) {
      out->cctx_ = ZSTD_createCCtx();
      if (!out->cctx_) return makeError(ErrorCode::kIo, path + ": out of memory for zstd");
      ZSTD_CCtx_setParameter(out->cctx_, ZSTD_c_compressionLevel, 3);
      out->zbuf_.resize(ZSTD_CStreamOutSize());
    }
    return out;
  }
  ~Output() { ZSTD_freeCCtx(cctx_); }
  const std::string& path() const { return file_->path(); }
  Status append(std::span<const uint8_t> bytes) { return compress(bytes, ZSTD_e_continue); }
  Status append(std::string_view text) {
    return append(std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
  }
  Status commit() {
    SP_RETURN_IF_ERROR(compress({}, ZSTD_e_end));
    return file_->commit();
  }

 private:
  explicit Output(std::unique_ptr<AtomicFile> file) : file_(std::move(file)) {}
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

namespace {

template <typename T>
void putLe(std::string& out, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.append(b, sizeof(T));
}

void putNumber(std::string& out, double v, bool dbl) {
  char num[64];
  const auto r = dbl ? std::to_chars(num, num + sizeof num, v) : std::to_chars(num, num + sizeof num, float(v));
  out.append(num, r.ptr);
}

void putIndex(std::string& out, uint64_t v) {
  char num[24];
  const auto r = std::to_chars(num, num + sizeof num, v);
  out.append(num, r.ptr);
}

Status checkMesh(const std::string& path, const Mesh& mesh) {
  if (mesh.scalars.size() != mesh.positions.size() * scalarWords(mesh.scalar_channels))
    return makeError(ErrorCode::kInternal, path + ": scalar values do not match vertices");
  if (!mesh.normals.empty() && mesh.normals.size() != mesh.positions.size())
    return makeError(ErrorCode::kInternal, path + ": normals do not match vertices");
  if (!mesh.colors.empty() && mesh.colors.size() != mesh.positions.size())
    return makeError(ErrorCode::kInternal, path + ": colors do not match vertices");
  return Status::ok();
}

// A float channel's value as OBJ text: the shortest digits that read back to the same value at its type.
void putChannelValue(std::string& out, const ScalarChannel& c, const uint32_t* words) {
  char num[64];
  const auto r = c.type == ScalarType::kFloat64 ? std::to_chars(num, num + sizeof num, floatChannelValue(c, words))
                                                : std::to_chars(num, num + sizeof num, std::bit_cast<float>(words[0]));
  out.append(num, r.ptr);
}

// OBJ with texture coordinates: one `v` per distinct position and color (the wedges a reader split at seams share
// theirs again; so do any other vertices at one position and color), a `vt` and (with normals) a `vn` per vertex,
// and faces `f p/t[/n]`. A vertex no face uses keeps its `v`, and its `vt` is named by no face.
Status writeTexturedObj(const std::string& path, const Mesh& mesh, const WriteOptions& options,
                        const TexcoordChannels& tc) {
  if (mesh.triangles.size() > 0x7FFFFFFF || mesh.positions.size() > 0x7FFFFFFF)
    return makeError(ErrorCode::kLimitExceeded, path + ": mesh too large for an int32-indexed OBJ");
  MeshFileLayout header;
  header.materials = options.materials;
  SP_ASSIGN_OR_RETURN(auto writer,
                      MeshFileWriter::create(path, header, MeshFileFormat::of(MeshFileFormat::Kind::kObj)));
  const size_t n = mesh.positions.size(), stride = scalarWords(mesh.scalar_channels);
  const bool colors = !mesh.colors.empty(), normals = !mesh.normals.empty();
  struct Key {
    Vec3d p;
    Rgba8 c;
    bool operator==(const Key& o) const { return std::memcmp(p.data(), o.p.data(), sizeof p) == 0 && c == o.c; }
  };
  struct KeyHash {
    size_t operator()(const Key& k) const {
      uint64_t h = 0xcbf29ce484222325ull;
      for (double x : k.p) h = (h ^ std::bit_cast<uint64_t>(x)) * 0x100000001b3ull;
      for (uint8_t x : k.c) h = (h ^ x) * 0x100000001b3ull;
      return size_t(h ^ (h >> 29));
    }
  };
  std::unordered_map<Key, uint32_t, KeyHash> welded;
  welded.reserve(n);
  std::vector<uint32_t> position_of(n);
  std::string text;
  auto flush = [&]() -> Status {
    if (text.size() < (1u << 20)) return Status::ok();
    Status st = writer->records(text);
    text.clear();
    return st;
  };
  for (size_t i = 0; i < n; ++i) {
    const Key key{mesh.positions[i], colors ? mesh.colors[i] : Rgba8{255, 255, 255, 255}};
    const auto [it, fresh] = welded.emplace(key, uint32_t(welded.size()));
    position_of[i] = it->second;
    if (!fresh) continue;
    text += 'v';
    for (double c : key.p) text += ' ', putNumber(text, c, options.double_positions);
    if (colors)
      for (int k = 0; k < 3; ++k) text += ' ', putNumber(text, key.c[k] / 255.0, false);
    text += '\n';
    SP_RETURN_IF_ERROR(flush());
  }
  for (size_t i = 0; i < n; ++i) {
    const uint32_t* words = mesh.scalars.data() + i * stride;
    text += "vt ";
    putChannelValue(text, mesh.scalar_channels[tc.u], words + tc.u_word);
    text += ' ';
    putChannelValue(text, mesh.scalar_channels[tc.v], words + tc.v_word);
    text += '\n';
    if (normals) {
      text += "vn";
      for (float c : mesh.normals[i]) text += ' ', putNumber(text, c, false);
      text += '\n';
    }
    SP_RETURN_IF_ERROR(flush());
  }
  for (const Triangle& t : mesh.triangles) {
    text += 'f';
    for (uint32_t v : t) {
      text += ' ';
      putIndex(text, uint64_t(position_of[v]) + 1);
      text += '/';
      putIndex(text, uint64_t(v) + 1);
      if (normals) text += '/', putIndex(text, uint64_t(v) + 1);
    }
    text += '\n';
    SP_RETURN_IF_ERROR(flush());
  }
  SP_RETURN_IF_ERROR(writer->records(text));
  return writer->commit();
}

Status writeWith(const std::string& path, const Mesh& mesh, const WriteOptions& options, MeshFileFormat format) {
  SP_RETURN_IF_ERROR(checkMesh(path, mesh));
  if (format.kind() == MeshFileFormat::Kind::kObj && !mesh.triangles.empty())
    if (const auto tc = findTexcoords(mesh.scalar_channels)) return writeTexturedObj(path, mesh, options, *tc);
  MeshFileLayout layout;
  layout.vertices = mesh.positions.size();
  layout.faces = mesh.triangles.size();
  layout.normals = !mesh.normals.empty();
  layout.color_channels = mesh.colors.empty() ? 0 : (mesh.color_channels == 4 ? 4 : 3);
  layout.double_positions = options.double_positions;
  if (format.kind() == MeshFileFormat::Kind::kPly) layout.scalars = mesh.scalar_channels;
  layout.materials = options.materials;
  const size_t stride = scalarWords(layout.scalars);
  SP_ASSIGN_OR_RETURN(auto writer, MeshFileWriter::create(path, layout, format));
  if (format.indexed())
    for (size_t i = 0; i < mesh.positions.size(); ++i)
      SP_RETURN_IF_ERROR(writer->vertex(mesh.positions[i], layout.normals ? &mesh.normals[i] : nullptr,
                                        layout.color_channels ? &mesh.colors[i] : nullptr,
                                        stride ? mesh.scalars.data() + i * stride : nullptr));
  for (const Triangle& t : mesh.triangles)
    SP_RETURN_IF_ERROR(writer->face(t, {mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]}));
  return writer->commit();
}

}  // namespace

std::vector<bool> channelsWritten(const std::string& path, std::span<const ScalarChannel> channels, bool triangles) {
  std::vector<bool> written(channels.size(), false);
  const auto f = MeshFileFormat::forPath(path);
  if (f.isOk() && f->kind() == MeshFileFormat::Kind::kPly) return std::vector<bool>(channels.size(), true);
  const bool obj = f.isOk() && f->kind() == MeshFileFormat::Kind::kObj;
  const bool gltf = endsWith(path, ".glb") || endsWith(path, ".gltf");
  if ((obj && triangles) || gltf)
    if (const auto tc = findTexcoords(channels)) written[tc->u] = written[tc->v] = true;
  // Lossless normals are written as the mesh's normals (dequantizeMesh lifts them out of the channels).
  if (obj || gltf)
    if (const auto word = losslessNormalsWord(channels))
      for (size_t i = 0, w = 0; i < channels.size(); w += size_t(scalarTypeWords(channels[i++].type)))
        if (w >= *word && w < *word + 3) written[i] = true;
  return written;
}

Result<MeshFileFormat> MeshFileFormat::forPath(const std::string& path) {
  const std::string base = endsWith(path, ".zst") ? path.substr(0, path.size() - 4) : path;
  if (endsWith(base, ".ply")) return MeshFileFormat(Kind::kPly);
  if (endsWith(base, ".obj")) return MeshFileFormat(Kind::kObj);
  if (endsWith(base, ".stl")) return MeshFileFormat(Kind::kStl);
  if (endsWith(base, ".off")) return MeshFileFormat(Kind::kOff);
  return makeError(ErrorCode::kInvalidArgument,
                   path + ": output must end in .ply, .obj, .stl or .off (optionally .zst)");
}

void MeshFileFormat::header(const MeshFileLayout& layout, std::string& out) const {
  switch (kind_) {
    case Kind::kPly: {
      out += "ply\nformat binary_little_endian 1.0\ncomment written by scanpress\n";
      if (!layout.materials.texture.empty()) out += "comment TextureFile " + layout.materials.texture + "\n";
      out += "element vertex " + std::to_string(layout.vertices) + "\n";
      const char* t = layout.double_positions ? "double" : "float";
      for (const char* axis : {"x", "y", "z"}) out += std::string("property ") + t + " " + axis + "\n";
      if (layout.normals) out += "property float nx\nproperty float ny\nproperty float nz\n";
      if (layout.color_channels) out += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
      if (layout.color_channels == 4) out += "property uchar alpha\n";
      for (const ScalarChannel& c : layout.scalars)
        out += std::string("property ") + scalarTypeName(c.type) + " " + c.name + "\n";
      out += "element face " + std::to_string(layout.faces) + "\n";
      out += "property list uchar int vertex_indices\nend_header\n";
      return;
    }
    case Kind::kObj:
      out += "# written by scanpress\n";
      if (!layout.materials.library.empty()) out += "mtllib " + layout.materials.library + "\n";
      if (!layout.materials.material.empty()) out += "usemtl " + layout.materials.material + "\n";
      return;
    case Kind::kStl: {
      // Binary STL: an 80-byte header (which must not start with "solid", or readers take it for ASCII), the
      // count, then per triangle its facet normal, three corners (float) and a zero attribute word.
      const std::string title = "binary STL written by scanpress";
      out += title + std::string(80 - title.size(), ' ');
      putLe(out, static_cast<uint32_t>(layout.faces));
      return;
    }
    case Kind::kOff:
      // COFF when the mesh has colors (RGBA per vertex, as integers), OFF otherwise.
      out += layout.color_channels ? "COFF\n" : "OFF\n";
      out += std::to_string(layout.vertices) + " " + std::to_string(layout.faces) + " 0\n";
      return;
  }
}

void MeshFileFormat::vertex(const MeshFileLayout& layout, const Vec3d& p, const Vec3f* normal, const Rgba8* color,
                            const uint32_t* scalars, std::string& out) const {
  switch (kind_) {
    case Kind::kPly:
      for (double c : p) {
        if (layout.double_positions) putLe(out, c);
        else putLe(out, static_cast<float>(c));
      }
      if (normal)
        for (float c : *normal) putLe(out, c);
      if (color) out.append(reinterpret_cast<const char*>(color->data()), layout.color_channels == 4 ? 4 : 3);
      if (scalars)
        for (const ScalarChannel& c : layout.scalars) {  // each value's bytes, little-endian at its type
          const uint64_t bits = uint64_t(scalars[0]) |
                                (c.type == ScalarType::kFloat64 ? uint64_t(scalars[1]) << 32 : 0);
          for (int b = 0; b < scalarTypeBytes(c.type); ++b) out += char(uint8_t(bits >> (8 * b)));
          scalars += scalarTypeWords(c.type);
        }
      return;
    case Kind::kObj:
      // Each vertex's normal follows it (`vn` lines count like `v` lines, so face corners use one index).
      out += 'v';
      for (double c : p) out += ' ', putNumber(out, c, layout.double_positions);
      if (color)
        for (int k = 0; k < 3; ++k) out += ' ', putNumber(out, (*color)[k] / 255.0, false);
      out += '\n';
      if (normal) {
        out += "vn";
        for (float c : *normal) out += ' ', putNumber(out, c, false);
        out += '\n';
      }
      return;
    case Kind::kStl: return;
    case Kind::kOff:
      for (int k = 0; k < 3; ++k) {
        putNumber(out, p[k], layout.double_positions);
        out += k < 2 || color ? ' ' : '\n';
      }
      if (color) {
        for (int k = 0; k < 4; ++k) {
          putIndex(out, (*color)[k]);
          out += k < 3 ? ' ' : '\n';
        }
      }
      return;
  }
}

void MeshFileFormat::face(const MeshFileLayout& layout, const Triangle& t, const std::array<Vec3d, 3>& corners,
                          std::string& out) const {
  switch (kind_) {
    case Kind::kPly:
      out += char(3);
      for (uint32_t v : t) putLe(out, static_cast<int32_t>(v));
      return;
    case Kind::kObj:
      out += 'f';
      for (uint32_t v : t) {
        out += ' ';
        putIndex(out, uint64_t(v) + 1);
        if (layout.normals) out += "//", putIndex(out, uint64_t(v) + 1);
      }
      out += '\n';
      return;
    case Kind::kStl: {
      const Vec3d &a = corners[0], &b = corners[1], &c = corners[2];
      const Vec3d u{b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v{c[0] - a[0], c[1] - a[1], c[2] - a[2]};
      const Vec3d n{u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
      const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      for (double x : n) putLe(out, static_cast<float>(len > 0 ? x / len : 0.0));
      for (const Vec3d& p : corners)
        for (double x : p) putLe(out, static_cast<float>(x));
      putLe(out, uint16_t{0});
      return;
    }
    case Kind::kOff:
      out += "3 ";
      for (int k = 0; k < 3; ++k) {
        putIndex(out, t[k]);
        out += k < 2 ? ' ' : '\n';
      }
      return;
  }
}

MeshFileWriter::MeshFileWriter(MeshFileFormat format, const MeshFileLayout& layout, std::unique_ptr<Output> out)
    : format_(format), layout_(layout), out_(std::move(out)) {}

MeshFileWriter::~MeshFileWriter() = default;

Result<std::unique_ptr<MeshFileWriter>> MeshFileWriter::create(const std::string& path, const MeshFileLayout& layout) {
  SP_ASSIGN_OR_RETURN(MeshFileFormat format, MeshFileFormat::forPath(path));
  return create(path, layout, format);
}

Result<std::unique_ptr<MeshFileWriter>> MeshFileWriter::create(const std::string& path, const MeshFileLayout& layout,
                                                               MeshFileFormat format) {
  if (format.indexed() && (layout.faces > 0x7FFFFFFF || layout.vertices > 0x7FFFFFFF))
    return makeError(ErrorCode::kLimitExceeded, path + ": mesh too large for an int32-indexed PLY/OBJ/OFF");
  if (!format.indexed() && layout.faces > UINT32_MAX)
    return makeError(ErrorCode::kLimitExceeded, path + ": more triangles than binary STL can count");
  SP_ASSIGN_OR_RETURN(auto out, Output::create(path));
  auto writer = std::unique_ptr<MeshFileWriter>(new MeshFileWriter(format, layout, std::move(out)));
  writer->buf_.reserve(1u << 20);
  format.header(layout, writer->buf_);
  return writer;
}

Status MeshFileWriter::drain(bool force) {
  if (!force && buf_.size() < (1u << 20) - 512) return Status::ok();
  Status s = out_->append(buf_);
  buf_.clear();
  return s;
}

Status MeshFileWriter::vertex(const Vec3d& p, const Vec3f* normal, const Rgba8* color, const uint32_t* scalars) {
  if (!format_.indexed()) return Status::ok();  // STL: the corners come with the faces
  if (vertices_ == layout_.vertices || faces_ != 0)
    return makeError(ErrorCode::kInternal, out_->path() + ": more vertices than the header says, or after a face");
  ++vertices_;
  if (!layout_.scalars.empty() && !scalars)
    return makeError(ErrorCode::kInternal, out_->path() + ": a vertex without the layout's scalar values");
  format_.vertex(layout_, p, normal, color, layout_.scalars.empty() ? nullptr : scalars, buf_);
  return drain();
}

Status MeshFileWriter::face(const Triangle& t, const std::array<Vec3d, 3>& corners) {
  if (faces_ == layout_.faces)
    return makeError(ErrorCode::kInternal, out_->path() + ": more faces than the header says");
  ++faces_;
  format_.face(layout_, t, corners, buf_);
  return drain();
}

Status MeshFileWriter::faceBytes(std::span<const uint8_t> bytes, uint64_t count) {
  if (count > layout_.faces - faces_)
    return makeError(ErrorCode::kInternal, out_->path() + ": more faces than the header says");
  faces_ += count;
  SP_RETURN_IF_ERROR(drain(true));
  return out_->append(bytes);
}

Status MeshFileWriter::records(std::string_view text) {
  SP_RETURN_IF_ERROR(drain(true));
  return out_->append(text);
}

Status MeshFileWriter::commit() {
  if ((format_.indexed() && vertices_ != layout_.vertices) || faces_ != layout_.faces)
    return makeError(ErrorCode::kInternal, out_->path() + ": " + std::to_string(vertices_) + " vertices and " +
                                               std::to_string(faces_) + " faces written, the header says " +
                                               std::to_string(layout_.vertices) + " and " +
                                               std::to_string(layout_.faces));
  SP_RETURN_IF_ERROR(drain(true));
  return out_->commit();
}

Status writePly(const std::string& path, const Mesh& mesh, const WriteOptions& options) {
  return writeWith(path, mesh, options, MeshFileFormat::of(MeshFileFormat::Kind::kPly));
}
Status writeObj(const std::string& path, const Mesh& mesh, const WriteOptions& options) {
  return writeWith(path, mesh, options, MeshFileFormat::of(MeshFileFormat::Kind::kObj));
}
Status writeStl(const std::string& path, const Mesh& mesh, const WriteOptions& options) {
  return writeWith(path, mesh, options, MeshFileFormat::of(MeshFileFormat::Kind::kStl));
}
Status writeOff(const std::string& path, const Mesh& mesh, const WriteOptions& options) {
  return writeWith(path, mesh, options, MeshFileFormat::of(MeshFileFormat::Kind::kOff));
}

Status writeMeshFile(const std::string& path, const Mesh& mesh, const WriteOptions& options) {
  if (endsWith(path, ".glb") || endsWith(path, ".gltf")) return writeGltf(path, mesh, options);
  auto format = MeshFileFormat::forPath(path);
  if (!format.isOk())
    return makeError(ErrorCode::kInvalidArgument,
                     path + ": output must end in .ply, .obj, .stl or .off (optionally .zst), .glb or .gltf");
  return writeWith(path, mesh, options, *format);
}

}  // namespace scanpress
