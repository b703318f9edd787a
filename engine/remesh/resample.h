// Relief resampling, the second step of piecewise regular remeshing (engine/remesh/resample.cpp).
//
// Szymczak, Rossignac, King, "Piecewise Regular Meshes: Construction and Compression"
// (../shared/papers/prm-piecewise-regular-meshes.md), section 2.2: a relief (a height field over the plane normal to
// its defining vector, engine/remesh/relief.h) is sliced by the three line families of a hexagonal grid in that
// plane, then every vertex that is not a grid vertex is removed by edge collapses that keep the relief's boundary,
// never cross a grid edge and never flip a triangle. Interior triangles end up projecting onto grid triangles
// (regular triangles); irregular ones remain along the boundary. Points the grid lines added on the boundary are
// then collapsed along it where they can, so that neighbouring reliefs meet along the input's boundary edges. Departures from the paper are written at the top of
// resample.cpp.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "engine/mesh.h"
#include "engine/status.h"

namespace scanpress {

// The hexagonal grid of a relief's plane, on the scan's integer grid: lattice point (i, j) has base coordinates
// (i * spacing + j * spacing / 2, j * row), row = round(spacing * sqrt(3) / 2). Spacing is even, so every lattice
// point is an integer point (its triangles are equilateral to within 1 / (2 row)). The three line families are
// s = const, t = const and s + t = const in lattice coordinates (s, t).
struct HexLattice {
  uint32_t spacing = 0;  // even, >= 2
  uint32_t row = 0;
  static HexLattice withSpacing(uint32_t spacing);
};

// Base coordinates of a point in relief r's plane, ordered so that a triangle facing r is counterclockwise, and its
// height along r's defining vector.
std::array<double, 2> reliefBase(const Vec3d& p, int relief);
double reliefHeight(const Vec3d& p, int relief);
// Lattice coordinates (s, t) of base coordinates.
std::array<double, 2> latticeCoordinates(const HexLattice& lattice, const std::array<double, 2>& base);

enum ResampledVertex : uint8_t {
  kFreeVertex = 0,     // neither on a grid line nor fixed (none is left inside a relief once collapses end)
  kOnGridLine = 1,     // on one grid line
  kLatticeVertex = 2,  // a grid vertex (on all three lines)
  kFixedVertex = 4,    // flag: on the relief's boundary or fixed by the caller; never moved or removed
};

struct ResampledRelief {
  // The vertices the resampled triangles use: input vertices and added ones, in order of first use.
  std::vector<Vec3d> positions;
  std::vector<uint32_t> input_vertex;  // per vertex: its index in the input, or UINT32_MAX for an added one
  // Per vertex: for an added vertex on an input edge, that edge's input vertices; else UINT32_MAX twice. Points
  // added on the relief's boundary are collapsed along it where no triangle flips; those left are named here.
  std::vector<std::array<uint32_t, 2>> input_edge;
  // Per vertex: for an added vertex, the input triangle (index into `triangles`) it lies in; else UINT32_MAX.
  std::vector<uint32_t> source_triangle;
  std::vector<Triangle> triangles;
  std::vector<uint8_t> regular;                    // per triangle: 1 if it projects onto a grid triangle
  std::vector<uint8_t> kind;                       // per vertex: ResampledVertex, kFixedVertex or'ed in
  std::vector<std::array<int32_t, 2>> lattice_ij;  // per vertex: lattice coordinates (i, j) of a lattice vertex
  uint64_t collapses = 0;
  // Points on a tile's border edge removed by triangulating the hole they leave (where no collapse could go).
  uint64_t retriangulated = 0;
};

// Flags per input position (resampleRelief's `fixed`).
enum ResampleFlag : uint8_t {
  kFixedByCaller = 1,   // never moved or removed (a tile's locked vertex)
  kSharedBoundary = 2,  // on a boundary shared with another relief: no new edge joins two such vertices
};

// Resamples one relief: `triangles` over `positions` (grid units, as relief.h's layout gives them), all facing
// `relief` (projected area >= 0; zero-area triangles are sliced, their pieces never collapsed). `fixed` is empty or has ResampleFlags
// per position. A vertex is fixed when the flags say so or when it is on the relief's boundary: an edge used by
// one triangle or by more than two, or a vertex whose triangles do not form one fan. Triangles that repeat a vertex are kept as they are.
// kInvalidArgument for a spacing that is odd or below 2, a relief id outside 0..5, indices out of range, corners
// beyond 2^25 grid units, or a triangle facing away from the relief (beyond the rounding noise of its orientation).
// How the inside of a relief is resampled. kDirect: cells that only good triangles cover (no boundary, no
// fixed or zero-area triangle, one layer) get their grid triangle straight from their corners' heights on the input,
// which is what slicing and collapsing them leaves, and only the triangles over the other cells are sliced; it falls
// back to kSliceAll when overlapping layers meet at a corner it would fill. kSliceAll: every triangle is sliced and
// collapsed, as the paper does (tests compare the two).
enum class ResampleMethod : uint8_t { kDirect, kSliceAll };

Result<ResampledRelief> resampleRelief(std::span<const Vec3d> positions, std::span<const Triangle> triangles,
                                       int relief, const HexLattice& lattice, std::span<const uint8_t> fixed,
                                       ResampleMethod method = ResampleMethod::kDirect);

}  // namespace scanpress
