// Decoding a container into a mesh file under a memory budget (`decode --memory-budget`).
//
// The in-memory decode (jobs/commands.cpp) holds every decoded tile, the welded mesh and its float copy at once,
// about 150 bytes per vertex. The streaming decode holds a batch of tiles at a time and writes the output as it
// goes, and its file is byte for byte the in-memory decode's:
//  - Tiles are decoded in batches (in parallel inside a batch) whose estimated decode memory fits half the budget,
//    and welded in the order the in-memory decode welds them. A larger tile goes alone; one that needs more than
//    three quarters of the budget is an error that names it and the budget it needs.
//  - Only vertices that can meet another tile are looked up or kept for welding: those inside another chosen
//    tile's bounds (the index's bounds for complete decodes; a first pass measures them for --level, whose coarse
//    vertices may lie outside). A kept vertex is dropped once the last tile whose bounds hold it is done. Memory
//    for welding is therefore proportional to the vertices near tile borders that are still open.
//  - The vertices (quantized, 20 bytes each, and their scalar words when the output writes scalar channels) and
//    the faces (already in the output format's bytes) go to scratch files; the output is written last, when the
//    counts its header needs are known (jobs/mesh_io/mesh_writer.h). Normals a coarse level derives from the welded
//    triangles (engine/codecs/codec.h, deriveAttributes; when some tile has no attributes of its own at that
//    level), octahedral or lossless, are summed in the same order and patched into the scratch files when the
//    vertex's last tile is done.
//  - `crop` numbers vertices by their first use in a kept triangle, as the in-memory crop does.
// glTF is not written this way (its binary buffer precedes nothing, but its JSON needs bounds and it is one
// buffer), nor OBJ with texture coordinates (one `v` line per position, shared by the wedges at texture seams, which
// needs every position at once): the caller refuses them over the budget.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "jobs/container_file.h"

namespace scanpress {

// Decode memory a tile needs, estimated from its index counts (the largest codec's peak while decoding a tile,
// plus the decoded tile itself), with `scalar_stride` scalar words per vertex.
uint64_t tileDecodeBytes(const TileEntry& e, size_t scalar_stride = 0);
// What the in-memory decode of `chosen` peaks at (decoded tiles, welded mesh, float copy, weld table).
// `scalar_stride`: the layout's scalar words per vertex (each held in the tile, the welded copy and the mesh).
uint64_t inMemoryDecodeBytes(const std::vector<const TileEntry*>& chosen, size_t scalar_stride = 0);

struct DecodedTile {
  QuantizedMesh mesh;
  bool complete = true;        // as decodeTilePayload says (false: a coarse level, or attributes the codec derives)
  bool own_attributes = true;  // as decodeTilePayload says (a coarse level of kdtree or octree from version 3 too)
};
// Decodes `tiles` in parallel (at `level` when given), in their order; fails with the first failing tile's error.
Result<std::vector<DecodedTile>> decodeTiles(const ContainerFile& file, std::span<const TileEntry* const> tiles,
                                             std::optional<uint32_t> level);

struct StreamDecodeSettings {
  std::optional<uint32_t> level;
  std::optional<std::array<double, 6>> crop;  // world box; triangles wholly inside are kept
  uint64_t memory_budget = 0;                 // bytes (at least 16 MiB)
  // Weld by and write the scalar channels (what the in-memory decode does when the format writes any): PLY writes
  // them all, and lossless normals are PLY's and OBJ's normals (the caller leaves this false for STL and OFF, which
  // write none). Not for OBJ with texture coordinates (its `v` lines are shared by the wedges at seams: the caller
  // refuses it).
  bool scalars = false;
  std::string scratch_parent;  // empty: the system temp directory
  MaterialNames materials;     // OBJ output's `mtllib` and `usemtl`, PLY output's `comment TextureFile`
};

struct StreamDecodeResult {
  uint64_t vertices = 0, faces = 0;
  bool double_positions = false;
  uint32_t batches = 0;  // decode batches (1: everything fit at once)
};

// A container's shape at low resolution within `memory_budget` (for thumbnails): tiles decoded a batch at a time,
// the vertices clustered by their cell in a grid of `cells` per axis over the container's bounds (each cluster at
// the mean of its vertices), and the triangles that span three clusters kept once each (vertex clustering;
// Rossignac and Borrel 1993). Memory grows with
// the clustered mesh, at most a few times cells^2 for a surface, not with the scan.
Result<Mesh> decodeClustered(const ContainerFile& file, uint32_t cells, uint64_t memory_budget);

Result<StreamDecodeResult> streamDecode(const ContainerFile& file, const std::vector<const TileEntry*>& chosen,
                                        const std::string& output, const StreamDecodeSettings& settings);

}  // namespace scanpress
