// `scanpress synth`: deterministic scan-like meshes of any size, written in a streaming way, for testing and
// benchmarking 10M-100M+ triangles.
//
// A base mesh (a scan given with `from`, or a built-in bumpy icosphere) is subdivided with m segments per edge
// (each base triangle becomes m^2 triangles, edge and interior points shared exactly between neighbours) and
// every new point is displaced along the interpolated vertex normal by multi-scale value noise (octaves from
// four base edges down to two sub-edges, amplitude proportional to wavelength), which gives the surface the
// fine, slightly noisy detail of a real scan. m is the smallest with F m^2 >= N; the first base triangles are
// emitted whole and the next one partly, so the mesh has exactly N triangles, and only points that some emitted
// triangle uses are written (no unreferenced vertices). The same N, seed and base give the same bytes.
//
// Memory: the base mesh and its edge map; the output is written through a 1 MiB buffer (PLY binary LE, float).
#pragma once

#include <cstdint>
#include <string>

#include "engine/status.h"

namespace scanpress {

struct SynthSettings {
  std::string output;
  uint64_t triangles = 1000000;
  uint64_t seed = 1;
  std::string from;  // base scan; empty: built-in icosphere
};

struct SynthResult {
  uint64_t vertices = 0, triangles = 0;
  uint32_t segments = 0;  // m
  uint64_t base_triangles = 0;
};

Result<SynthResult> synthesize(const SynthSettings& settings);

}  // namespace scanpress
