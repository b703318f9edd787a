// Mesh writers: PLY binary little endian (with normals and colors when present) and OBJ. Both write through
// AtomicFile: the output appears complete or not at all.
#pragma once

#include <string>

#include "engine/mesh.h"
#include "engine/status.h"

namespace scanpress {

struct WriteOptions {
  // Positions as double instead of float (needed when float cannot hold the grid's precision).
  bool double_positions = false;
};

Status writePly(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});
Status writeObj(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});
// By extension (.ply or .obj); anything else is kInvalidArgument.
Status writeMeshFile(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});

}  // namespace scanpress
