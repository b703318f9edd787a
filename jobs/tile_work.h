// One tile's work, apart from the rest of a scan's encode (jobs/pipeline.cpp): for a built TileMesh, the stages,
// the codec, the per-tile error knob search and the measurement. The pipeline's flow graph runs it on its own
// threads; the MPI build's worker ranks (mpi/) run it on tiles that rank 0 built and sent them
// (jobs/remote_tiles.h). A tile's result depends only on the tile and the settings, never on where it ran: that
// is what keeps a distributed encode byte-identical to a local one.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "engine/codecs/codec.h"
#include "engine/metro.h"
#include "engine/quantize.h"
#include "engine/tile.h"
#include "jobs/pipeline.h"

namespace scanpress {

class EmbreeDevice;

// What a tile's work yields, for the container writer and the report.
struct TileResult {
  uint32_t tile = 0;
  Status status;
  EncodedTile encoded;
  uint32_t border = 0;
  uint32_t input_vertices = 0, input_faces = 0;  // of the tile as built (a failed tile reports what it lost)
  ErrorAccumulator forward, backward;
  double knob_cells = -1;
  bool target_met = true;
  uint32_t knob_trials = 0;
};

// A tile as built, before its work: its id, counts and border, and `status` (a failed build: what the tile lost,
// for the report).
TileResult tileAsBuilt(const TileMesh& tm, Status status = Status::ok());

// What a tile's work needs to know of its scan, beyond the settings.
struct TileScanFacts {
  Grid grid;
  AttributeLayout layout;
  bool measured = false;  // each tile is decoded and measured against its original triangles
  double diagonal = 0;    // of the grid's box: per-tile error targets are relative to it
  double density = 0;     // measurement samples per unit area (samplingDensity)
};

// Runs tiles' work for one scan. Thread-safe: many tiles at once.
class TileEncoder {
 public:
  // `device`: for measuring (needed when scan.measured). `hooks`: tests only, else nullptr.
  TileEncoder(const EncodeSettings& settings, const CodecInfo& codec, const TileScanFacts& scan,
              std::shared_ptr<EmbreeDevice> device, const PipelineHooks* hooks);

  // The tile's result: its counts and border, then its work; a failure (status or exception) is in r.status and
  // leaves no payload.
  TileResult run(const TileMesh& tm, const std::vector<Vec3d>& originals) const;

 private:
  Status encodeTile(const TileMesh& tm, const std::vector<Vec3d>& originals, TileResult& r) const;
  Status encodeAt(const TileContext& ctx, const TileView& tile, double cells, TileResult& r) const;
  Status measureTile(const TileContext& ctx, const TileMesh& tm, const std::vector<Vec3d>& originals,
                     TileResult& r) const;
  double tileError(const TileResult& r) const;
  Status searchKnob(const TileContext& ctx, const TileView& tile, const TileMesh& tm,
                    const std::vector<Vec3d>& originals, TileResult& r) const;

  const EncodeSettings& s_;
  const CodecInfo& codec_;
  TileScanFacts scan_;
  std::shared_ptr<EmbreeDevice> device_;
  const PipelineHooks* hooks_;
};

}  // namespace scanpress
