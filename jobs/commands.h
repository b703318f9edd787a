// The operations behind the CLI: encode a mesh file into a container, decode a container (or some of its
// tiles) into a mesh file, describe a container. Each returns a typed result; the CLI and (later) the batch
// runner turn them into output, reports and exit codes.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "engine/container/container.h"
#include "engine/quantize.h"
#include "jobs/measure.h"
#include "jobs/mesh_io/mesh_reader.h"

namespace scanpress {

// Everything that decides what an encode produces and how it runs. The CLI's `encode` options and the job files'
// keys both map onto this struct (jobs/config.cpp).
struct EncodeSettings {
  std::string input;
  std::string output;
  std::string codec = "store";
  int bits = kDefaultGridBits;
  int normal_bits = kDefaultNormalBits;
  bool keep_normals = true;
  bool keep_colors = true;
  uint64_t tile_triangles = 131072;  // target triangles per tile (tiles adapt to density around it)
  int threads = 0;                   // 0: all cores
  uint64_t memory_budget = 0;        // bytes; 0: no limit (the scan is processed in memory)
  std::string scratch_dir;           // parent of the temporary tile bins; empty: the system temp directory
  MeasureSettings measure;           // error of the decoded result, per tile and overall
  // Fault injection for tests only (not reachable from the CLI or job files): these tiles fail with kInternal,
  // to exercise the handling of a failed tile.
  std::vector<uint32_t> fail_tiles;
};

struct StageSeconds {
  double read = 0;      // first pass over the input: bounds, counts (and the mesh itself when it fits)
  double quantize = 0;  // second pass: quantization, degenerate triangles, tile histogram
  double tile = 0;      // tiling and binning
  double encode = 0;    // the parallel per-tile pipeline, including the ordered write
  double write = 0;     // index, footer, sync and rename
};

// A tile of an encode: the counts its decoder yields (for a failed tile, the counts it had as built).
struct TileReport {
  uint32_t id = 0;
  uint32_t vertices = 0;
  uint32_t faces = 0;
  uint32_t border_vertices = 0;
  uint64_t bytes = 0;
  Status status;
  ErrorStats forward, backward;  // when measured
};

struct EncodeResult {
  ReadStats read;
  Grid grid;
  AttributeLayout layout;
  QuantizeStats quantize;
  uint64_t vertices = 0;       // distinct vertices encoded (after dropping)
  uint64_t faces = 0;          // triangles encoded
  uint64_t tile_vertices = 0;  // vertices summed over tiles (border vertices count once per tile)
  uint64_t bytes = 0;          // container size
  std::vector<TileReport> tiles;
  uint32_t failed_tiles = 0;
  bool out_of_core = false;  // tile data went through scratch files
  int threads = 0;
  uint64_t peak_rss = 0;  // bytes, this process so far
  bool measured = false;
  double diagonal = 0;  // of the input's bounding box
  ErrorAccumulator forward, backward;  // over all tiles: original -> decoded, decoded -> original
  StageSeconds seconds;
  std::string codec;
  double bitsPerVertex() const { return vertices ? 8.0 * bytes / vertices : 0.0; }
};

// Observer of a running encode (progress display). Called from the pipeline's serial writer only.
class ProgressListener {
 public:
  virtual ~ProgressListener() = default;
  virtual void stage(const char* /*name*/) {}
  virtual void tiles(uint32_t /*done*/, uint32_t /*total*/, uint64_t /*triangles_done*/) {}
};

// Encodes one scan: tiling, the parallel per-tile pipeline, the container (jobs/pipeline.cpp). The container is
// written even when some tiles fail (they are listed in the result); it is not written at all on a read or
// write error.
// Measuring uses `device` (one per job); one is created when none is given.
Result<EncodeResult> encodeFile(const EncodeSettings& settings, ProgressListener* progress = nullptr,
                                std::shared_ptr<EmbreeDevice> device = nullptr);

struct DecodeSettings {
  std::string input;
  std::string output;
  std::optional<std::vector<uint32_t>> tiles;  // all tiles when empty
  std::optional<uint32_t> level;               // progressive codecs: decode this level (grid bits = lossless)
  std::optional<uint64_t> bytes;               // progressive codecs: the finest level within this many payload bytes
};

struct DecodeResult {
  uint64_t vertices = 0, faces = 0;
  uint32_t tiles = 0;
  bool double_positions = false;
  std::optional<uint32_t> level;  // the level decoded, when one was asked for (directly or by bytes)
  uint64_t level_bytes = 0;       // payload bytes that level needs, over the decoded tiles
};

// Decodes the selected tiles and welds them (in memory).
// With a level, every tile is decoded at that level (progressive codecs only).
Result<QuantizedMesh> decodeContainer(const std::string& path, const std::optional<std::vector<uint32_t>>& tiles,
                                      ContainerHeader* header = nullptr, std::optional<uint32_t> level = std::nullopt);
Result<DecodeResult> decodeFile(const DecodeSettings& settings);

// Whether float positions requantize to the same cells on this grid (otherwise writers use double).
bool floatPositionsSuffice(const QuantizedMesh& mesh, const Grid& grid);

}  // namespace scanpress
