// glTF 2.0 output (https://registry.khronos.org/glTF/specs/2.0/glTF-2.0.html): `.glb` (binary: a JSON chunk and
// a BIN chunk) or `.gltf` (JSON with the buffer embedded as a base64 data URI, one self-contained file).
//
// One mesh, one node, one primitive: POSITION (float, relative to the node's translation, which is the center of
// the mesh's bounding box, so that scans far from the origin keep their precision in float), NORMAL when the mesh
// has normals (unit length as glTF requires: a zero normal, e.g. of an isolated vertex, is written as +Z), COLOR_0
// when it has colors (RGBA8 normalized), and 32-bit indices; a mesh without triangles is written as points. The
// document is written with nlohmann::json, which scanpress already uses; the compressed variants
// (KHR_draco_mesh_compression, EXT_meshopt_compression) are not written yet.
#pragma once

#include <string>

#include "engine/mesh.h"
#include "engine/status.h"
#include "jobs/mesh_io/mesh_writer.h"

namespace scanpress {

Status writeGltf(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});

}  // namespace scanpress
