// glTF 2.0 output (https://registry.khronos.org/glTF/specs/2.0/glTF-2.0.html): `.glb` (binary: a JSON chunk and
// a BIN chunk) or `.gltf` (JSON with the buffer embedded as a base64 data URI, one self-contained file).
//
// One node per part (the whole scan, or one per tile), each with one mesh of one primitive: POSITION, NORMAL when
// the mesh has normals (unit length as glTF requires: a zero normal, e.g. of an isolated vertex, is written as +Z),
// COLOR_0 when it has colors (RGBA8 normalized), and 32-bit indices; a mesh without triangles is written as points.
// Uncompressed, positions are floats relative to the node's translation (the center of the scan's box, so that
// scans far from the origin keep their precision in float). Compressed:
//   - EXT_meshopt_compression: every buffer view coded with meshoptimizer's vertex and index codecs (vertex codec
//     version 0 and index codec version 1, the versions the extension specifies), decoded by viewers such as
//     three.js and Babylon.js; the uncompressed views are described by a fallback buffer without data.
//   - KHR_draco_mesh_compression: each primitive coded by Draco (edgebreaker, no quantization: lossless on what
//     it is given); the accessors' counts and bounds are those of Draco's own decode of it.
// With a compression and a grid of at most 16 bits, positions are the grid's integer cells as unsigned shorts
// (KHR_mesh_quantization), the node's scale the cell and its translation the first cell's center: exact, and
// what the codecs compress best. The JSON is written with nlohmann::json; the compression is the libraries'.
#pragma once

#include <string>
#include <vector>

#include "engine/mesh.h"
#include "engine/status.h"
#include "jobs/mesh_io/mesh_writer.h"

namespace scanpress {

struct GltfPart {
  std::string name;  // the node's name ("" for none)
  const Mesh* mesh = nullptr;
};

Status writeGltf(const std::string& path, const Mesh& mesh, const WriteOptions& options = {});
// Several parts, one node each (e.g. one per tile), in one scene.
Status writeGltfParts(const std::string& path, const std::vector<GltfPart>& parts, const WriteOptions& options = {});

// "none", "meshopt", "draco".
const char* gltfCompressionName(GltfCompression c);
Result<GltfCompression> parseGltfCompression(const std::string& name);

}  // namespace scanpress
