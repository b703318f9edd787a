// Stage `smooth`: Taubin's lambda|mu smoothing of the unlocked vertices (see SmoothOptions in stage.h).
//
// Each step moves every unlocked vertex by factor * (mean of its edge neighbours - its position), with factor
// lambda, then mu, `iterations` times; positions are kept in double between steps and rounded to the grid at the
// end. Departures from the paper: the umbrella operator with equal weights (the paper's simplest choice), and
// locked vertices fixed (tile borders: the border contract). A vertex whose rounded move would make one of its
// triangles degenerate (two corners in one grid cell, which the coders refuse) keeps its position, so the
// connectivity is the input's, unchanged.
#include <algorithm>
#include <cmath>

#include "engine/stages/stage.h"

namespace scanpress {

Result<StagedTile> smoothStage(const TileContext& ctx, const TileView& tile, const StageSpec& spec) {
  SP_RETURN_IF_ERROR(validateStage(spec).withContext("smooth"));
  const SmoothOptions& o = spec.smooth;
  const QuantizedMesh& in = tile.mesh;
  const size_t n = in.positions.size();
  StagedTile out;
  out.mesh = in;
  out.locked.assign(n, 0);
  if (tile.locked.size() == n) out.locked.assign(tile.locked.begin(), tile.locked.end());

  // Neighbours by edges (each once), as offsets into one array.
  std::vector<std::pair<uint32_t, uint32_t>> edges;
  edges.reserve(6 * in.triangles.size());
  for (const auto& t : in.triangles)
    for (int k = 0; k < 3; ++k) {
      edges.push_back({t[k], t[(k + 1) % 3]});
      edges.push_back({t[(k + 1) % 3], t[k]});
    }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  std::vector<uint32_t> start(n + 1, 0);
  for (const auto& e : edges) ++start[e.first + 1];
  for (size_t v = 0; v < n; ++v) start[v + 1] += start[v];

  std::vector<Vec3d> p;
  p.reserve(n);
  for (const Vec3u& q : in.positions) p.push_back({double(q[0]), double(q[1]), double(q[2])});
  std::vector<Vec3d> next = p;
  for (int it = 0; it < 2 * o.iterations; ++it) {
    const double factor = it % 2 == 0 ? o.lambda : o.mu;
    for (size_t v = 0; v < n; ++v) {
      next[v] = p[v];
      const uint32_t b = start[v], e = start[v + 1];
      if (out.locked[v] || b == e) continue;
      Vec3d mean{0, 0, 0};
      for (uint32_t i = b; i < e; ++i)
        for (int a = 0; a < 3; ++a) mean[a] += p[edges[i].second][a];
      for (int a = 0; a < 3; ++a) next[v][a] += factor * (mean[a] / (e - b) - p[v][a]);
    }
    p.swap(next);
  }
  const double max_coord = double((uint64_t(1) << ctx.bits) - 1);
  for (size_t v = 0; v < n; ++v) {
    if (out.locked[v]) continue;
    for (int a = 0; a < 3; ++a)
      out.mesh.positions[v][a] = static_cast<uint32_t>(std::clamp(std::round(p[v][a]), 0.0, max_coord));
  }
  undoDegenerateMoves(in, out.mesh);
  return out;
}

}  // namespace scanpress
