// Relief construction, the first step of piecewise regular remeshing (engine/remesh/relief.cpp).
//
// Szymczak, Rossignac, King, "Piecewise Regular Meshes: Construction and Compression"
// (../shared/papers/prm-piecewise-regular-meshes.md), section 2.1: the surface is split into *reliefs*, regions
// whose triangles all face one of six defining vectors (the coordinate axes), with smooth boundaries. Each relief is
// a height field over the plane normal to its vector (locally: projections of distant parts of one relief may
// overlap). The boundaries come from a farthest-point Voronoi diagram of geodesic distance fields, and triangles
// are split along them. Departures from the paper are written at the top of relief.cpp.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <unordered_set>
#include <vector>

#include "engine/mesh.h"
#include "engine/status.h"

namespace scanpress {

// The six defining vectors, by relief id: +x, -x, +y, -y, +z, -z. The axis of relief r is r / 2, its sign
// + for even r.
constexpr int kReliefCount = 6;
inline int reliefAxis(int relief) { return relief / 2; }
inline double reliefSign(int relief) { return relief % 2 == 0 ? 1.0 : -1.0; }
// The component of a vector along relief r's defining vector.
inline double alongRelief(const Vec3d& v, int relief) { return reliefSign(relief) * v[size_t(reliefAxis(relief))]; }

struct ReliefOptions {
  // The regularisation parameter tau, in (0, 1/sqrt(3)). A relief's triangles face its defining vector with a
  // cosine of at least tau; smaller tau gives smoother boundaries and steeper reliefs (the paper's Fig. 2; it
  // found 0.1 to 0.3 a good compromise).
  double tau = 0.2;
};

// The input surface refined along the relief boundaries.
struct ReliefLayout {
  // The input's vertices first (same indices, as doubles), then the points added on edges and inside triangles.
  std::vector<Vec3d> positions;
  std::vector<Triangle> triangles;  // the refined triangles, oriented as their input triangles
  std::vector<uint8_t> relief;      // per refined triangle: its relief id (0..5)
  std::vector<uint32_t> source;     // per refined triangle: the input triangle it is part of
  // Statistics: input triangles split along a boundary, and refined triangles given the relief they face most
  // because the one their corners' distances chose faced it with a cosine below tau.
  uint64_t split_triangles = 0;
  uint64_t refaced_triangles = 0;
};

// Splits `mesh` (triangles on the integer grid; normals and colors ignored) into reliefs. `locked` is empty or has
// one flag per vertex: an edge between two locked vertices on the tile's border (used by one triangle or by more
// than two) is never cut, so it stays an edge. Zero-area triangles are cut like the others (their pieces have zero
// area); triangles that repeat a vertex are kept whole. Isolated vertices are kept (in `positions`, unused); an
// empty mesh gives an empty layout. kInvalidArgument for tau outside (0, 1/sqrt(3)), indices out of range, lock
// flags of the wrong size or coordinates beyond 2^25.
Result<ReliefLayout> buildReliefs(const QuantizedMesh& mesh, std::span<const uint8_t> locked,
                                  const ReliefOptions& options);

// The tile border edges of `mesh`: edges between two locked vertices used by one triangle or by more than two, as
// (lower index << 32 | higher index). Empty when `locked` does not have one flag per vertex.
std::unordered_set<uint64_t> tileBorderEdges(const QuantizedMesh& mesh, std::span<const uint8_t> locked);

// The connected components of each relief: triangles of one relief joined across shared edges (an edge used by
// more than two triangles joins them all). One id per refined triangle, numbered from 0 in triangle order.
std::vector<uint32_t> reliefComponents(const ReliefLayout& layout, uint32_t* count);

}  // namespace scanpress
