// Mesh writers: PLY binary little endian (with normals, colors and scalar channels when present), OBJ (normals,
// colors as the common `v x y z r g b` extension, texture coordinates as `vt`: texcoords.h), binary STL (geometry
// only), OFF (COFF with colors), each optionally through zstd (a name ending in .zst), and glTF 2.0
// (jobs/mesh_io/gltf_writer.h). All write through AtomicFile: the output appears complete or not at all.
//
// The four indexed formats are also written piece by piece (MeshFileWriter), for a mesh that is never whole in
// memory: the streaming decode (jobs/stream_decode.h) learns the counts every header needs only at its end, so it
// keeps its vertices and the bytes of its faces (MeshFileFormat::face) in scratch files and writes the file last.
#pragma once

#include <memory>
#include <span>
#include <string>

#include "engine/mesh.h"
#include "engine/quantize.h"
#include "engine/status.h"

namespace scanpress {

// glTF output only (jobs/mesh_io/gltf_writer.h).
enum class GltfCompression : uint8_t { kNone, kMeshopt, kDraco };

struct WriteOptions {
  // Positions as double instead of float (needed when float cannot hold the grid's precision).
  bool double_positions = false;
  GltfCompression gltf_compression = GltfCompression::kNone;
  // The grid the positions lie on (decoded containers): with compression and at most 16 bits, glTF positions are
  // its integer cells (KHR_mesh_quantization, exact). nullptr: float positions.
  const Grid* grid = nullptr;
  // OBJ writes the `mtllib` and `usemtl` lines, PLY the `comment TextureFile` line; other formats none of them
  // (the caller reports them dropped).
  MaterialNames materials;
};

Status writePly(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});
Status writeObj(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});
Status writeStl(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});
Status writeOff(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});
// By extension: .ply, .obj, .stl, .off (each optionally followed by .zst), .glb, .gltf; anything else is
// kInvalidArgument.
Status writeMeshFile(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});

// What an indexed mesh file holds, which its header states before the first vertex.
struct MeshFileLayout {
  uint64_t vertices = 0, faces = 0;
  bool normals = false;
  uint8_t color_channels = 0;  // 0, 3 or 4
  bool double_positions = false;
  // Scalar channels, written by PLY only (at their type, after the colors); other formats have no place for them
  // (the caller reports them dropped: channelsWritten in texcoords.h). The OBJ writer writes a mesh's texture
  // coordinates itself (writeObj), not through this layout.
  std::vector<ScalarChannel> scalars;
  MaterialNames materials;  // OBJ's `mtllib` and `usemtl` lines, PLY's `comment TextureFile` line
};

// The byte form of one indexed format (.ply, .obj, .stl, .off; .zst is the output's business).
class MeshFileFormat {
 public:
  enum class Kind : uint8_t { kPly, kObj, kStl, kOff };
  // By the name's extension (a trailing .zst is skipped); glTF and anything else: kInvalidArgument.
  static Result<MeshFileFormat> forPath(const std::string& path);
  static MeshFileFormat of(Kind kind) { return MeshFileFormat(kind); }
  Kind kind() const { return kind_; }
  // Whether the file lists vertices (STL repeats the corners in every facet instead).
  bool indexed() const { return kind_ != Kind::kStl; }
  void header(const MeshFileLayout& layout, std::string& out) const;
  // `normal` and `color` are null when the layout has none; `scalars` (the layout's words) when it has scalars.
  void vertex(const MeshFileLayout& layout, const Vec3d& p, const Vec3f* normal, const Rgba8* color,
              const uint32_t* scalars, std::string& out) const;
  // `corners`: the triangle's positions (used by STL only).
  void face(const MeshFileLayout& layout, const Triangle& t, const std::array<Vec3d, 3>& corners,
            std::string& out) const;

 private:
  explicit MeshFileFormat(Kind kind) : kind_(kind) {}
  Kind kind_;
};

// An indexed mesh file written in order: header (at create), the vertices, then the faces, each given once;
// commit() checks that the counts match the layout's and makes the file appear. Until then nothing is under the
// final name.
class MeshFileWriter {
 public:
  // The format by the name's extension, or the one given.
  static Result<std::unique_ptr<MeshFileWriter>> create(const std::string& path, const MeshFileLayout& layout);
  static Result<std::unique_ptr<MeshFileWriter>> create(const std::string& path, const MeshFileLayout& layout,
                                                        MeshFileFormat format);
  ~MeshFileWriter();
  const MeshFileFormat& format() const { return format_; }
  Status vertex(const Vec3d& p, const Vec3f* normal, const Rgba8* color, const uint32_t* scalars = nullptr);
  Status face(const Triangle& t, const std::array<Vec3d, 3>& corners);
  // Faces already in this format's bytes (MeshFileFormat::face), `count` of them.
  Status faceBytes(std::span<const uint8_t> bytes, uint64_t count);
  // Records the layout does not count, as they are (a textured OBJ's `v`, `vt`, `vn` and `f` lines, with a layout
  // of no vertices and faces).
  Status records(std::string_view text);
  Status commit();

 private:
  class Output;
  MeshFileWriter(MeshFileFormat format, const MeshFileLayout& layout, std::unique_ptr<Output> out);
  Status drain(bool force = false);
  MeshFileFormat format_;
  MeshFileLayout layout_;
  std::unique_ptr<Output> out_;
  std::string buf_;
  uint64_t vertices_ = 0, faces_ = 0;
};

}  // namespace scanpress
