// Piecewise regular remeshing: reliefs (relief.h), each resampled over its hexagonal grid (resample.h), merged back
// into one mesh (engine/remesh/remesh.cpp).
//
// Szymczak, Rossignac, King, "Piecewise Regular Meshes: Construction and Compression"
// (../shared/papers/prm-piecewise-regular-meshes.md), sections 2.1 to 2.3. Departures from the paper's merging are
// written at the top of remesh.cpp.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "engine/mesh.h"
#include "engine/remesh/resample.h"
#include "engine/status.h"

namespace scanpress {

struct RemeshOptions {
  double tau = 0.2;      // relief.h's ReliefOptions::tau
  uint32_t spacing = 0;  // grid spacing in grid units: even, >= 2
  // The paper's collapse of relief-boundary vertices onto grid vertices after merging (remesh.cpp).
  bool collapse_onto_grid = true;
  // Then the paper's area-reducing edge flips between irregular triangles (remesh.cpp).
  bool flip_edges = true;
  // Cells inside a relief straight from their corners' heights, or every triangle sliced (resample.h).
  ResampleMethod resample = ResampleMethod::kDirect;
};

struct Remeshed {
  std::vector<Vec3d> positions;  // grid units, not yet rounded to the integer grid
  std::vector<Triangle> triangles;
  std::vector<uint8_t> relief;         // per triangle: the relief (0..5) it was resampled in
  std::vector<uint8_t> regular;        // per triangle: 1 if it projects onto a triangle of its relief's grid
  std::vector<uint32_t> input_vertex;  // per vertex: its index in the input mesh, or UINT32_MAX
  // Per vertex that is not an input vertex: an input triangle it lies on (to carry attributes); else UINT32_MAX.
  std::vector<uint32_t> source_triangle;
  uint32_t reliefs = 0;         // relief components resampled
  uint64_t merge_splits = 0;    // triangles split so that two reliefs meet vertex to vertex
  uint64_t border_fans = 0;     // tile border edges closed by a fan of zero-area triangles
  uint64_t grid_collapses = 0;  // vertices off the grid collapsed onto a grid vertex after merging
  uint64_t edge_flips = 0;      // edges between irregular triangles flipped to reduce area
};

// Remeshes `mesh` (a tile: triangles on the integer grid; `locked` empty or one flag per vertex). Locked vertices
// keep their positions and the tile's border edges (between locked vertices, used by one triangle or more than
// two) stay edges. The result covers the same surface up to the resampling (grid vertices lie on the input
// surface; the mesh's own boundaries are the input's polylines, and so are the boundaries between reliefs before the
// collapses and edge flips of the irregular band straighten them). Where the input is
// a manifold the result is one. kInvalidArgument for bad options, indices or lock flags; kLimitExceeded when the
// grid is so fine that resampling would make more than about 64 pieces per input triangle (plus 2^20 per call).
Result<Remeshed> remeshPiecewiseRegular(const QuantizedMesh& mesh, std::span<const uint8_t> locked,
                                        const RemeshOptions& options);

}  // namespace scanpress
