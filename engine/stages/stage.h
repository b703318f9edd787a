// Geometry stages: what a tile goes through before its coder (engine/codecs/codec.h).
//
// A tile runs zero or more stages in order (simplify, remesh, smooth, ...) and then one coder; a codec such as a
// simplifying progressive coder may be a stage and a coder in one. A stage is a pure function of the tile view:
// the quantized tile mesh and its lock flags in, a new mesh with lock flags out; no shared state, the same output
// at any thread count. Stages must keep the border contract of engine/tile.h; the pipeline checks it after every
// stage with checkBorderContract, and a violation is a tile error, never a silently cracked mesh.
//
// Adding a stage: its options struct here (in StageSpec), its function in its own file, a line in kStages
// (stage.cpp), its keys in jobs/config.cpp and configs/REFERENCE.md, and tests that run it through
// checkBorderContract.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "engine/codecs/codec.h"
#include "engine/mesh.h"
#include "engine/status.h"

namespace scanpress {

// A stage's output: the mesh and one lock flag per vertex (locked vertices of the input stay locked).
struct StagedTile {
  QuantizedMesh mesh;
  std::vector<uint8_t> locked;
  TileView view() const { return TileView{mesh, locked}; }
};

enum class StageKind : uint8_t {
  kSmooth = 1,
  kRemesh = 2,
};

// Taubin's lambda|mu smoothing (Taubin, "A signal processing approach to fair surface design", SIGGRAPH 1995):
// alternating shrinking (lambda > 0) and inflating (mu < -lambda) Laplacian steps, which remove scanner noise
// without the shrinkage of plain Laplacian smoothing. Unlocked vertices only; the connectivity is unchanged.
constexpr int kMaxSmoothIterations = 1000;
struct SmoothOptions {
  int iterations = 10;   // lambda and mu steps, each
  double lambda = 0.33;  // in (0, 1)
  double mu = -0.34;     // in (-1, -lambda)
};

// Piecewise regular remeshing (engine/remesh/remesh.h; Szymczak, Rossignac, King, "Piecewise Regular Meshes"):
// the tile is split into six axis reliefs and resampled on hexagonal grids of spacing `grid`, a fraction of the
// quantization grid's extent (2^bits cells, the scan's longest side), at least 2 cells.
struct RemeshStageOptions {
  double grid = 0.005;  // in (0, 1]
  double tau = 0.2;     // relief regularisation, in (0, 1/sqrt(3))
};

struct StageSpec {
  StageKind kind = StageKind::kSmooth;
  SmoothOptions smooth;
  RemeshStageOptions remesh;
};

using StageFunction = Result<StagedTile> (*)(const TileContext& ctx, const TileView& tile, const StageSpec& spec);

struct StageInfo {
  StageKind kind;
  std::string_view name;
  StageFunction run;
};

// Checks a stage's options (kInvalidArgument naming the option); runStage checks them too.
Status validateStage(const StageSpec& spec);

std::span<const StageInfo> allStages();
const StageInfo* findStage(StageKind kind);
const StageInfo* findStage(std::string_view name);
// "smooth, ...": for messages.
std::string stageNames();

// Runs one stage and checks the border contract on its output (thorough: also the mesh's validity).
Result<StagedTile> runStage(const TileContext& ctx, const TileView& tile, const StageSpec& spec, bool thorough);

// The border contract between a stage's input and output: every locked vertex of `before` is kept (a vertex at the
// same position, locked, in `after`), and every border edge of `before` is kept (an edge of `after` between the
// same positions). A border edge is an edge between two locked vertices that is not interior to the tile: used
// by one triangle of the tile, or by more than two. `thorough` also validates `after` (indices, grid, flags).
// Returns kInternal naming the first violation (a stage that breaks the contract is a bug).
Status checkBorderContract(const TileContext& ctx, const TileView& before, const TileView& after, bool thorough);

// For stages that move vertices of `before` (same vertices, same triangles) into `after`: undoes the moves that made a
// triangle degenerate (two corners in one grid cell, which the coders refuse), until none does. Ends because
// `before` has no degenerate triangle.
void undoDegenerateMoves(const QuantizedMesh& before, QuantizedMesh& after);

// `smooth` (smooth.cpp).
Result<StagedTile> smoothStage(const TileContext& ctx, const TileView& tile, const StageSpec& spec);
// `remesh` (remesh_stage.cpp).
Result<StagedTile> remeshStage(const TileContext& ctx, const TileView& tile, const StageSpec& spec);
// The remesh stage at a spacing of `spacing` grid cells (even, >= 2), as the `prm` codec runs it.
Result<StagedTile> remeshTile(const TileContext& ctx, const TileView& tile, double tau, uint32_t spacing);
// The remesh stage's grid spacing in grid cells: `grid` times 2^bits, rounded to an even number, at least 2.
uint32_t remeshSpacing(const RemeshStageOptions& options, int bits);

}  // namespace scanpress
