// Error and size targets (issue 19, part 3): the search that turns "this scan at 1e-4 of its diagonal" or "this
// scan in 2 MB" into quantization bits and, for a codec with an error knob, how far each tile departs from the
// quantized tile. Every choice is verified by measuring (error) or by the container's size: a prediction only
// picks where the search starts. A target that cannot be met is a failure (kLimitExceeded), never a silent miss.
#pragma once

#include <memory>

#include "jobs/pipeline.h"

namespace scanpress {

// Of an error target's budget, the share a codec with an error knob leaves to quantization: the rest goes to
// simplification, which saves far more bytes per unit of error than a coarser grid does (a bit less per
// coordinate saves 3 bits per vertex; simplifying to half the vertices saves half of everything). A quarter:
// quantization errors and simplification errors add roughly in quadrature (independent), so sqrt(1 - 1/16) =
// 97% of the RMS budget is still left to the simplification.
constexpr double kKnobQuantizationShare = 0.25;

// The margin an error target keeps below E: a candidate is accepted when its measured error is at most
// (1 - margin) * E. The measurement is an estimate from samples: the RMS of some 10^5 samples moves by about 1%
// with another seed, the max (a maximum over samples, vertices included) by a few percent on a quantized mesh
// (a sphere at 12 bits: 9.65e-5 against 1.003e-4 with another seed) and by up to about 10% on a simplified one
// (pm on the bunny at max 5e-4: accepted at most 4.7e-4, another seed found 5.13e-4). The margins (2% RMS, 12% max)
// keep an independent measurement of the result within E.
double measureMargin(ErrorMetric metric);

// The fewest grid bits whose uniform quantization is predicted to keep the error within `share * max_error`
// (relative to the diagonal), for a scan whose largest box extent is `extent_over_diagonal` of its diagonal
// (1/sqrt(3) for a cube, 1 for a flat strip; 1 is the safe guess before the scan is read). Uniform quantization
// moves a vertex by up to half a cell per axis, uniformly: along any unit direction (the surface normal) the RMS
// is cell/sqrt(12) at a vertex (cell/sqrt(24) averaged over a triangle) and the worst case half the cell's
// diagonal, cell*sqrt(3)/2. Clamped to [kMinGridBits, kMaxGridBits].
int predictBits(double max_error, ErrorMetric metric, double extent_over_diagonal, double share = 1.0);

// The search (called by encodeFile when settings.target is active):
//   error target, lossless codec: bits from predictBits, then measured passes: while a pass meets the target one
//     bit fewer is tried, while it misses one bit more, so the chosen bits are the fewest that measure within the
//     target (one fewer measured a miss, or is below kMinGridBits).
//   error target, codec with an error knob: bits predicted for kKnobQuantizationShare of the budget; every tile
//     searches its knob (the pipeline's searchKnob) to meet the target; a bit is added while a tile misses, and
//     a bit fewer is kept while it still meets the target with fewer bytes.
//   size target, lossless codec: bisection of the bits for the most that fit the budget (the next finer missed).
//   size target, codec with an error knob: one global knob for all tiles, at the bits as set, bisected for the
//     least that fits the budget.
// With fixed bits (target.fixed_bits) the bits are never changed. Each pass writes its own temporary container
// next to the output; the chosen one is renamed into place, the others are removed.
Result<EncodeResult> encodeToTarget(const EncodeSettings& settings, ProgressListener* progress,
                                    std::shared_ptr<EmbreeDevice> device, const PipelineHooks* hooks);

}  // namespace scanpress
