// Mesh writers: PLY binary little endian (with normals and colors when present), OBJ (normals, colors as the
// common `v x y z r g b` extension), binary STL (geometry only), OFF (COFF with colors), each optionally through
// zstd (a name ending in .zst), and glTF 2.0 (jobs/mesh_io/gltf_writer.h). All write through AtomicFile: the
// output appears complete or not at all.
#pragma once

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
};

Status writePly(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});
Status writeObj(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});
Status writeStl(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});
Status writeOff(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});
// By extension: .ply, .obj, .stl, .off (each optionally followed by .zst), .glb, .gltf; anything else is
// kInvalidArgument.
Status writeMeshFile(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});

}  // namespace scanpress
