// The operations behind the CLI: encode a mesh file into a container (jobs/pipeline.h), decode a container (or
// some of its tiles) into a mesh file. Each returns a typed result; the CLI and the batch runner turn them into
// output, reports and exit codes.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

#include "engine/container/container.h"
#include "engine/quantize.h"
#include "jobs/measure.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs/pipeline.h"

namespace scanpress {

// What `decode` may use by default: enough for the in-memory decode of scans to about 1.5M vertices; larger ones
// stream.
constexpr uint64_t kDefaultDecodeBudget = uint64_t(256) << 20;

struct DecodeSettings {
  std::string input;
  std::string output;
  std::optional<std::vector<uint32_t>> tiles;  // all tiles when empty; each at most once
  std::optional<uint32_t> level;               // progressive codecs: decode this level (grid bits = lossless)
  std::optional<uint64_t> bytes;               // progressive codecs: the finest level within this many payload bytes
                                               // (not with `level`)
  // World units (xmin, ymin, zmin, xmax, ymax, zmax): decode only the tiles whose bounds meet the box (not with
  // `tiles`); `crop` also drops every triangle not wholly inside it (and the vertices no triangle then uses; a point
  // cloud keeps the points inside).
  std::optional<std::array<double, 6>> box;
  bool crop = false;
  // glTF output only: compression (jobs/mesh_io/gltf_writer.h), and one node per decoded tile instead of one mesh
  // welded from them.
  GltfCompression gltf_compression = GltfCompression::kNone;
  bool gltf_tile_nodes = false;
  // Bytes the decode may use (jobs/stream_decode.h): when the in-memory decode would need more, PLY, OBJ, STL
  // and OFF output streams through scratch files in `scratch_dir` (empty: the system temp directory), glTF is
  // refused. 0: no limit.
  uint64_t memory_budget = kDefaultDecodeBudget;
  std::string scratch_dir;
};

struct DecodeResult {
  uint64_t vertices = 0, faces = 0;
  uint32_t tiles = 0;
  bool double_positions = false;
  std::optional<uint32_t> level;                // the level decoded, when one was asked for (directly or by bytes)
  uint64_t level_bytes = 0;                     // payload bytes that level needs, over the decoded tiles
  uint16_t subset_index = 0, subset_count = 0;  // the container is a part (encode --subset): its tiles only
  bool streamed = false;                        // decoded tile batch by tile batch under the memory budget
  // The container's scalar channels when the output format has no place for them (only PLY does): not silent.
  std::vector<DroppedProperty> dropped;
};

// A tile's bounds in world units: the outer faces of the cells its vertices occupy (min x, y, z, max x, y, z).
std::array<double, 6> tileWorldBounds(const TileEntry& tile, const Grid& grid);

// Decodes the selected tiles and welds them (in memory).
// With a level, every tile is decoded at that level (progressive codecs only).
Result<QuantizedMesh> decodeContainer(const std::string& path, const std::optional<std::vector<uint32_t>>& tiles,
                                      ContainerHeader* header = nullptr, std::optional<uint32_t> level = std::nullopt);
Result<DecodeResult> decodeFile(const DecodeSettings& settings);

// The mesh decodeFile would write (tiles, level, box and crop as `settings` choose; `output` and the glTF options
// are not used), in memory: for library callers (the Python module).
struct DecodedMesh {
  Mesh mesh;
  DecodeResult result;
  ContainerHeader header;
};
Result<DecodedMesh> decodeToMesh(const DecodeSettings& settings);

// `scanpress merge`: joins the N partial containers of one scan (`encode --subset i/N`, i = 0..N-1, in any order)
// into the whole container, byte for byte what one process writes with the same settings. Fails naming the part
// when one is missing, repeated, whole, of another split, grid or attribute layout, or holds a tile not of its
// share; the output appears complete or not at all.
struct MergeResult {
  uint32_t parts = 0, tiles = 0;
  uint64_t bytes = 0;
};
Result<MergeResult> mergeContainers(const std::vector<std::string>& parts, const std::string& output);

// Whether float positions requantize to the same cells on this grid (otherwise writers use double).
bool floatPositionsSuffice(const QuantizedMesh& mesh, const Grid& grid);
bool floatPositionSuffices(const Vec3u& q, const Grid& grid);

// Whether a world point lies in a box (xmin, ymin, zmin, xmax, ymax, zmax; closed).
bool insideBox(const Vec3d& p, const std::array<double, 6>& box);

}  // namespace scanpress
