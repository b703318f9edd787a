// Shape-preserving QEM simplification (engine/simplify/simplify.cpp).
//
// Based on Ahn, Chang, Ho, "Shape-preserving progressive coding of 3-D models" (../shared/papers/
// shape-preserving-progressive-qem.md), section 2, on Garland and Heckbert's quadric error metric: edge collapses
// ordered by weighted quadric error, with the paper's weights (complex edges by their number of incident triangles;
// an edge with one boundary vertex collapses the interior vertex onto the boundary one, weighted by the boundary
// vertex's incident edges; boundary edges by 1 + the larger cosine of the dihedral angles at their ends; interior
// edges 1). Where this departs from the paper is written at the top of simplify.cpp.
//
// Pure and deterministic: the same mesh, flags and options give the same collapses, on any machine and thread
// count. Positions stay on the scan's integer grid (a placement is rounded to the grid).
#pragma once

#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "engine/mesh.h"
#include "engine/status.h"

namespace scanpress {

enum class SimplifyWeights : uint8_t {
  kShapePreserving = 1,  // the paper's weights (section 2)
  kPlain = 2,            // plain Garland-Heckbert: every edge weight 1 (for comparison)
};

struct SimplifyOptions {
  SimplifyWeights weights = SimplifyWeights::kShapePreserving;
  // Stop conditions; simplification stops at the first one met (or when no legal collapse is left).
  uint64_t target_faces = 0;  // stop when the mesh has at most this many faces (0: no face target)
  double max_error = std::numeric_limits<double>::infinity();  // grid cells: no collapse whose error exceeds it
  // Collapses are made in passes; within a pass no two collapses touch the same vertex or its neighbours (their
  // closed one-rings are disjoint), so the vertex splits that undo a pass are independent and can be coded as one
  // batch. A pass ends when it has removed this share of the faces the mesh had at its start, or when no candidate
  // is left that is legal, independent of the pass's collapses so far, and within the pass's cost bound (1.5x the
  // cost at the rank of the collapses the pass needs; the whole cost order when nothing within the bound is legal).
  // In practice the independence limits a pass to about 5% of the faces on a closed scan (igea: 41 passes to 10%).
  // Must be in (0, 1].
  double pass_fraction = 0.25;
  // Half-edge collapses only: every placement is one of the edge's endpoints (the paper's index 0/1), never the
  // midpoint or the quadric's optimum. Slightly less accurate, but a progressive coder then codes one position per
  // vertex split instead of two (pm's base-to-last-level splits use it; measured in bench/RESULTS.md).
  bool endpoints_only = false;
};

// One edge collapse (v_s, v_r) -> v'_s in the paper's notation: `removed` (v_r) disappears, `kept` (v_s) moves to
// `position` (v'_s). Vertex indices are the input mesh's. Applying a collapse to a mesh: delete every face that uses
// both vertices, replace `removed` by `kept` in every other face, set kept's position.
struct EdgeCollapse {
  uint32_t kept = 0;
  uint32_t removed = 0;
  Vec3u position{};
  uint8_t placement = 0;  // the paper's index: 0 kept's old position, 1 removed's position, 2 another position
  float error = 0;        // the collapse's error estimate, grid cells (sqrt of the unweighted quadric error)
};

struct Simplification {
  std::vector<EdgeCollapse> collapses;  // in the order they were applied
  // collapses[pass_ends[i-1], pass_ends[i]) are pass i (pass_ends[-1] = 0); the last entry is collapses.size().
  std::vector<uint32_t> pass_ends;
  // After each pass: the largest error estimate of any collapse so far (grid cells), and the face count.
  std::vector<float> pass_errors;
  std::vector<uint64_t> pass_faces;
  // The simplified mesh, with the input's vertex indices (removed vertices stay in `positions`, unused).
  QuantizedMesh mesh;
  // With corner wedges (simplify's `corner_wedges`): those of mesh.triangles, three per triangle.
  std::vector<uint32_t> corner_wedges;
};

// Simplifies `mesh` (triangles only; normals and colors are ignored and not in the result). `locked` is empty or
// has one flag per vertex: a locked vertex never moves or disappears, and an edge between two locked vertices that
// is a border edge (one incident triangle, or more than two) is never collapsed. Never flips a triangle's normal,
// never makes a manifold edge non-manifold or creates a duplicate or degenerate triangle (two corners in one grid
// cell). Input triangles that are degenerate or repeat a vertex are kept as they are (their corners are never moved
// or removed). Triangle soups must be welded by the caller (a soup has no shared edge, so nothing collapses); the
// readers weld STL. Isolated vertices, vertices sharing a position and meshes without triangles are accepted.
// kInvalidArgument for indices out of range, lock flags of the wrong size, a pass_fraction outside (0, 1] or a
// negative max_error.
//
// `corner_wedges` is empty or has three ids per triangle (its corners' wedges: the attribute values a corner shows,
// so that a vertex on a crease or a texture seam has one wedge per side). A collapse of r onto k then needs:
//  - the deleted triangles (those with k and r) pair r's and k's wedges one to one (M: r's wedge -> k's), and every
//    wedge of r is paired: r's triangles that move to k take M's wedge at their new corner, so each side of a seam
//    stays on its side, and a seam vertex leaves only along its seam;
//  - every wedge of k that M names, and the third corner's wedge of every deleted triangle, is still used after the
//    collapse: a vertex split that undoes it (codec pm) then names those wedges among the ones its vertices have.
// The result's corner_wedges are the wedges of its triangles' corners.
Result<Simplification> simplify(const QuantizedMesh& mesh, std::span<const uint8_t> locked,
                                const SimplifyOptions& options, std::span<const uint32_t> corner_wedges = {});

}  // namespace scanpress
