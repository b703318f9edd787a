// The encode pipeline for one scan, in named steps (jobs/pipeline.cpp):
//
//   survey  stream the input once: bounding box, counts, which attributes exist, which vertices triangles use (and
//           the mesh itself, if small); the scan's one global grid, from the box of the vertices that triangles use
//           (a point cloud: of all its points)
//   ingest  stream again (or replay the kept mesh): quantize vertices into the vertex store, drop triangles that
//           quantization makes degenerate (failing when more than kMaxDegenerateShare of them, unless allowed),
//           count each vertex's valence, histogram triangle centroids (a point cloud: its points)
//   tile    octree tiles from the histogram (spatial/tiling.h), then a counting sort of triangles (or points) into
//           tile bins
//   encode  a oneTBB flow graph: source -> limiter -> tile task (parallel: build the tile with its lock flags,
//           the stages, the codec, the measurement) -> sequencer (tile order) -> serial container writer
//   finish  index, footer, sync, rename
//
// Memory: the store, the spill and the bins go to scratch files when they would not fit in half of the budget
// (2 GiB when none is set: beyond that, scratch files are faster too); their buffers take about a quarter each,
// and with a budget the limiter keeps the tiles in flight (and the tile size) within the rest. The output is
// byte-identical at any thread count: each tile's bytes depend only on its content, and the sequencer restores
// tile order.
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "engine/codecs/codec.h"
#include "engine/quantize.h"
#include "engine/stages/stage.h"
#include "jobs/measure.h"
#include "jobs/mesh_io/mesh_reader.h"

namespace scanpress {

// What an encode aims at instead of fixed settings (jobs/targets.cpp): an error bound or a size budget. A target
// without fixed bits chooses the quantization bits; for a codec with an error knob (errorKnobOf), the target also
// chooses how far each tile departs from the quantized tile.
enum class TargetKind : uint8_t {
  kNone = 0,
  kMaxError = 1,       // measured symmetric error of the decoded scan <= max_error * diagonal
  kMaxBytes = 2,       // container bytes <= max_bytes, at the least error
  kBitsPerVertex = 3,  // 8 * bytes / vertices <= bpv, at the least error
};
enum class ErrorMetric : uint8_t {
  kRms = 0,  // symmetric RMS (the larger of the two one-sided RMS), as `scanpress measure` reports it
  kMax = 1,  // symmetric max (Hausdorff, vertices included)
};
struct EncodeTarget {
  TargetKind kind = TargetKind::kNone;
  double max_error = 0;  // kMaxError: relative to the diagonal of the scan's bounding box
  ErrorMetric metric = ErrorMetric::kRms;
  uint64_t max_bytes = 0;   // kMaxBytes
  double bpv = 0;           // kBitsPerVertex
  bool fixed_bits = false;  // the bits were given (--bits, /codec/bits): the search keeps them
  bool active() const { return kind != TargetKind::kNone; }
};
const char* targetKindName(TargetKind kind);  // "max_error", "max_bytes", "bpv"
const char* errorMetricName(ErrorMetric m);   // "rms", "max"

// Everything that decides what an encode produces and how it runs. The CLI's `encode` options and the job files'
// keys both map onto this struct (jobs/config.cpp).
struct EncodeSettings {
  std::string input;
  std::string output;
  std::string codec = "edgebreaker";  // the smallest lossless codec (bench/RESULTS.md)
  int bits = kDefaultGridBits;
  int normal_bits = kDefaultNormalBits;
  int color_bits = 8;  // levels per color channel: 2^color_bits (8: exact)
  // Texture coordinates kept as multiples of 2^-uv_bits (1..kMaxScalarBits; ScalarChannel::bits); 0: lossless.
  int uv_bits = 0;
  bool keep_normals = true;
  // Normals bit for bit, as float channels nx, ny, nz (kLosslessNormalChannels) instead of octahedral codes: for the
  // codecs that carry scalar channels.
  bool lossless_normals = false;
  bool keep_colors = true;
  // Per-vertex scalar properties (a PLY's confidence, intensity, quality, ...), kept losslessly at their type by
  // the codecs that carry them (store, kdtree, octree, edgebreaker, pm); prm and the remesh stage resample them and
  // drop texture coordinates, and the report says so.
  bool keep_scalars = true;
  bool allow_degenerate = false;     // quantization may drop more than kMaxDegenerateShare of the triangles
  uint64_t tile_triangles = 131072;  // target triangles per tile (tiles adapt to density around it)
  int threads = 0;                   // 0: all cores
  uint64_t memory_budget = 0;        // bytes; 0: no limit (the scan is processed in memory)
  std::string scratch_dir;           // parent of the temporary tile bins; empty: the system temp directory
  MeasureSettings measure;           // error of the decoded result, per tile and overall
  std::vector<StageSpec> stages;     // geometry stages every tile runs before the codec, in order
  CodecOptions codec_options;        // the codec's typed options
  bool strict = false;               // fail (kUnsupported) when the input holds anything the container drops
  EncodeTarget target;               // none: the settings above are used as they are
  // A partial container (`--subset i/N`, issue 23): the scan is read and tiled as a whole encode does, and only
  // the tiles t with t % N == i are encoded; `scanpress merge` joins the N parts. 0 and 0: the whole scan.
  uint16_t subset_index = 0, subset_count = 0;
  // Set by the target search for one pass (jobs/targets.cpp), not by users. For a codec with an error knob:
  // `tile_error` > 0 makes every tile search the knob so that its measured error (`tile_metric`, relative to the
  // scan's diagonal) stays within it; else `knob_cells` >= 0 sets the knob of every tile to that many grid cells.
  double tile_error = 0;
  ErrorMetric tile_metric = ErrorMetric::kRms;
  double knob_cells = -1;
};

// `--codec auto` (/codec/name "auto"): under an error or size target, the target search runs for pm and for
// edgebreaker and keeps the smaller result that meets an error target (the least error that fits a size target);
// simplification wins at loose RMS targets, plain quantization at tight ones and under the max metric (bench/
// RESULTS.md, "Error targets"). Without a target, auto is edgebreaker, the smallest lossless codec.
inline constexpr const char* kAutoCodec = "auto";
// Whether `name` is a codec or auto.
inline bool knownCodecName(const std::string& name) { return name == kAutoCodec || findCodec(name) != nullptr; }

// A lossy codec's error knob: sets how far the codec may depart from the tile, in grid cells (pm:
// PmOptions::max_error). nullptr for a codec without one (every lossless codec).
using ErrorKnob = void (*)(CodecOptions& options, double cells);
// prm's knob: lattice spacing in grid cells per grid cell of allowed error.
inline constexpr double kPrmSpacingPerCell = 16;
ErrorKnob errorKnobOf(CodecId id);

// The share of a mesh's triangles that quantization may make degenerate (two corners in one cell) and drop before
// the encode fails with kLimitExceeded, unless EncodeSettings::allow_degenerate. Triangles that are degenerate in
// the input already (a repeated vertex index) do not count: no grid keeps them.
constexpr double kMaxDegenerateShare = 0.001;

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
  double knob_cells = -1;        // the error knob this tile was encoded at (a codec with one, under a target)
  bool target_met = true;        // under a per-tile error target: the tile's measured error is within it
  uint32_t knob_trials = 0;      // encodes the per-tile search ran
};

// What the target search did (jobs/targets.cpp), for the report.
struct TargetAttempt {
  std::string codec;  // the codec of this pass (with --codec auto, each candidate's)
  int bits = 0;
  double knob_cells = -1;  // global knob (size targets with a knob codec), or -1
  uint64_t bytes = 0;
  uint64_t vertices = 0;
  double error = -1;  // relative to the diagonal, in the target's metric; -1: not measured
  bool met = false;
  std::string refused;  // the pipeline refused this setting (e.g. too many degenerate triangles at these bits)
};
struct TargetReport {
  EncodeTarget target;
  int bits = 0;            // chosen
  double knob_cells = -1;  // chosen global knob (size targets with a knob codec)
  double tile_error = 0;   // per-tile error bound given to the knob search (absolute units), 0: none
  bool met = false;
  double error = -1;  // achieved, relative to the diagonal, in the target's metric (-1: not measured)
  std::vector<TargetAttempt> attempts;
  Status status;  // not met: kLimitExceeded naming achieved and target
};

struct EncodeResult {
  ReadStats read;  // read.dropped: what the input holds that scanpress does not keep (unsupported)
  std::vector<DroppedProperty> dropped_on_request;  // normals, colors and scalars the settings dropped
  Grid grid;
  AttributeLayout layout;
  QuantizeStats quantize;
  uint64_t vertices = 0;       // distinct vertices encoded (after dropping)
  uint64_t faces = 0;          // triangles encoded
  bool point_cloud = false;    // the input has vertices and no triangles: its points are encoded
  uint64_t tile_vertices = 0;  // vertices summed over tiles (border vertices count once per tile)
  uint64_t bytes = 0;          // container size
  std::vector<TileReport> tiles;
  uint32_t failed_tiles = 0;
  bool out_of_core = false;  // tile data went through scratch files
  int threads = 0;
  uint64_t peak_rss = 0;  // bytes, this process so far
  bool measured = false;
  double diagonal = 0;  // of the grid's bounding box: the vertices that triangles use (a point cloud: all)
  ErrorAccumulator forward, backward;  // over all tiles: original -> decoded, decoded -> original
  StageSeconds seconds;
  std::string codec;
  std::vector<std::string> stages;     // names, in the order they ran
  std::optional<TargetReport> target;  // when the settings had a target
  double bitsPerVertex() const { return vertices ? 8.0 * bytes / vertices : 0.0; }
};

// Observer of a running encode (progress display). Called from the pipeline's serial writer only.
class ProgressListener {
 public:
  virtual ~ProgressListener() = default;
  virtual void stage(const char* /*name*/) {}
  virtual void tiles(uint32_t /*done*/, uint32_t /*total*/, uint64_t /*triangles_done*/) {}
};

// Test hooks (tests only; not reachable from the CLI or job files).
struct PipelineHooks {
  // One more stage after the configured ones, checked against the border contract like them.
  std::function<Result<StagedTile>(const TileContext& ctx, const TileView& tile, uint32_t tile_id)> extra_stage;
  // Fault injection: a tile for which this returns an error fails with it.
  std::function<Status(uint32_t tile_id)> fail_tile;
  // Fault injection outside the tile tasks: called before a scan is read; may throw.
  std::function<void(const std::string& input)> before_survey;
  // A lossy transformation standing in for a codec's error knob: when set, the codec counts as having a knob, and
  // each tile runs this (after the stages, checked against the border contract) at the knob's value in grid
  // cells before the codec encodes it. Lets the target search be tested before a lossy codec exists.
  std::function<Result<StagedTile>(const TileContext& ctx, const TileView& tile, double cells)> knob_stage;
};

// Encodes one scan: survey, ingest, tile, encode tiles, finish (jobs/pipeline.cpp). The container is written
// even when some tiles fail (they are listed in the result); it is not written at all on a read or write error.
// Measuring uses `device` (one per job); one is created when none is given. With a target (settings.target), the
// target search of jobs/targets.h runs the encode as often as it needs; result.target tells what it chose and
// whether the target was met (a missed target removes the container and sets result.target->status).
Result<EncodeResult> encodeFile(const EncodeSettings& settings, ProgressListener* progress = nullptr,
                                std::shared_ptr<EmbreeDevice> device = nullptr, const PipelineHooks* hooks = nullptr);

// One encode at exactly these settings, ignoring `target` (the target search runs it once per attempt).
Result<EncodeResult> encodeFileOnce(const EncodeSettings& settings, ProgressListener* progress,
                                    std::shared_ptr<EmbreeDevice> device, const PipelineHooks* hooks);

// Peak memory of a tile task per triangle (measured, generously rounded up): sizes tiles and tiles in flight.
constexpr uint64_t kTileBytesPerTriangle = 160;

// The target triangles per tile that an encode with these settings uses: the configured target, lowered when a
// memory budget could not hold the tiles in flight. Independent of the thread count, so the output is too.
uint64_t effectiveTileTarget(const EncodeSettings& s);

}  // namespace scanpress
