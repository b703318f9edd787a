// One tile of a scan, as the per-tile pipeline sees it.
//
// A tile task receives a TileMesh built by spatial/tile_builder.h: the tile's triangles (those whose centroid lies
// in the tile), the vertices they use with local indices, each vertex's global index, and a border flag.
//
// THE BORDER CONTRACT. A vertex is a border vertex when some triangle of another tile also uses it. All tiles
// share the scan's one global grid, so a border vertex has the same integer coordinates in every tile that holds
// it, and the decoder welds tiles back into one crack-free mesh by those coordinates. Every stage that changes
// geometry (simplification, remeshing, any lossy coding) must therefore keep each border vertex: not move it,
// not remove it, not merge it with another vertex; and must keep the chain of border edges between them, so that
// the neighbouring tile still matches. Interior vertices are free. Codecs that are lossless after quantization
// keep everything and satisfy the contract trivially.
//
// The border flags are the lock flags of the tile's view (TileView in engine/codecs/codec.h). Stages
// (engine/stages/stage.h) are pure functions of that view: no shared mutable state, the same output at any thread
// count; the pipeline checks the contract after every stage (checkBorderContract).
#pragma once

#include <cstdint>
#include <vector>

#include "engine/mesh.h"

namespace scanpress {

struct TileMesh {
  uint32_t tile_id = 0;
  QuantizedMesh mesh;                     // local indices
  std::vector<uint32_t> local_to_global;  // per local vertex
  std::vector<uint8_t> border;            // per local vertex: 1 if another tile uses it (see the contract)
};

}  // namespace scanpress
