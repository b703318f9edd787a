// Stage `remesh`: piecewise regular remeshing of a tile (engine/remesh/remesh.h), rounded back to the scan's
// integer grid.
//
// After remeshing, positions are rounded (grid vertices' base coordinates are integers already; heights and the
// points on relief boundaries move by at most half a cell per axis). An added vertex whose grid point is taken
// goes to the nearest free one of the 27 around it (at most 1.5 cells away), so no two vertices share a point
// (the coders refuse two corners in one cell, and welding would change the topology); only if all 27 are taken
// is it welded, and triangles that then repeat a vertex are dropped. Input vertices keep their points and
// identity, so locked vertices stay.
// Normals: an input vertex that is kept keeps its normal; other vertices get the area-weighted normal of the
// remeshed surface, turned to the input's convention (the input's normals mostly agree with its triangles'
// orientation, or mostly oppose it). Colors are not carried through remeshing yet: a tile with colors is refused.
#include <algorithm>
#include <cmath>
#include <map>
#include <string>

#include "engine/geometry.h"
#include "engine/octahedral.h"
#include "engine/remesh/remesh.h"
#include "engine/stages/stage.h"

namespace scanpress {
namespace {

using u32 = uint32_t;
constexpr u32 kNone = UINT32_MAX;

// Area-weighted vertex normals (unnormalised sums of the triangles' cross products).
std::vector<Vec3d> vertexNormalSums(const std::vector<Vec3d>& p, const std::vector<Triangle>& triangles) {
  std::vector<Vec3d> n(p.size(), Vec3d{0, 0, 0});
  for (const Triangle& t : triangles) {
    const Vec3d c = vcross(vsub(p[t[1]], p[t[0]]), vsub(p[t[2]], p[t[0]]));
    for (u32 v : t) n[v] = vadd(n[v], c);
  }
  return n;
}

std::vector<Vec3d> doubles(const std::vector<Vec3u>& q) {
  std::vector<Vec3d> p;
  p.reserve(q.size());
  for (const Vec3u& v : q) p.push_back({double(v[0]), double(v[1]), double(v[2])});
  return p;
}

}  // namespace

uint32_t remeshSpacing(const RemeshStageOptions& options, int bits) {
  const double cells = options.grid * std::ldexp(1.0, bits);
  const double even = 2 * std::round(cells / 2);
  return uint32_t(std::clamp(even, 2.0, 2.0 * double(1u << 30)));
}

Result<StagedTile> remeshStage(const TileContext& ctx, const TileView& tile, const StageSpec& spec) {
  SP_RETURN_IF_ERROR(validateStage(spec).withContext("remesh"));
  const QuantizedMesh& in = tile.mesh;
  if (ctx.layout.hasColors())
    return makeError(ErrorCode::kInvalidArgument,
                     "remesh: colors are not carried through remeshing yet (encode without them, --no-colors)");
  const bool has_flags = tile.locked.size() == in.positions.size();
  SP_ASSIGN_OR_RETURN(Remeshed r,
                      remeshPiecewiseRegular(in, has_flags ? tile.locked : std::span<const uint8_t>(),
                                             RemeshOptions{.tau = spec.remesh.tau,
                                                           .spacing = remeshSpacing(spec.remesh, ctx.bits)}));
  // Round, and weld added vertices onto vertices already at their cell (input vertices first).
  const double top = std::ldexp(1.0, ctx.bits) - 1;
  std::vector<u32> order(r.positions.size());
  for (u32 v = 0; v < order.size(); ++v) order[v] = v;
  std::stable_partition(order.begin(), order.end(), [&](u32 v) { return r.input_vertex[v] != kNone; });
  std::map<Vec3u, u32> at;
  std::vector<u32> id(r.positions.size(), kNone);
  StagedTile out;
  std::vector<u32> source;  // per output vertex: the input vertex, or kNone
  uint64_t welded = 0;
  for (u32 v : order) {
    Vec3u q;
    if (r.input_vertex[v] != kNone) {
      q = in.positions[r.input_vertex[v]];
    } else {
      // The nearest free grid point among the 27 around the rounded position (a taken one would weld two
      // vertices: a change of topology).
      const Vec3d& p = r.positions[v];
      Vec3u base;
      for (int k = 0; k < 3; ++k) base[size_t(k)] = u32(std::clamp(std::round(p[size_t(k)]), 0.0, top));
      double best = INFINITY;
      bool found = false;
      for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dz = -1; dz <= 1; ++dz) {
            const int64_t c[3] = {int64_t(base[0]) + dx, int64_t(base[1]) + dy, int64_t(base[2]) + dz};
            if (c[0] < 0 || c[1] < 0 || c[2] < 0 || c[0] > int64_t(top) || c[1] > int64_t(top) || c[2] > int64_t(top))
              continue;
            const Vec3u cand{u32(c[0]), u32(c[1]), u32(c[2])};
            const double d = vlen(vsub(p, {double(c[0]), double(c[1]), double(c[2])}));
            if (d < best && !at.count(cand)) {
              best = d;
              q = cand;
              found = true;
            }
          }
      if (!found) {  // all 27 taken: weld onto the rounded one
        id[v] = at.at(base);
        ++welded;
        continue;
      }
    }
    id[v] = u32(out.mesh.positions.size());
    at.emplace(q, id[v]);
    out.mesh.positions.push_back(q);
    source.push_back(r.input_vertex[v]);
  }
  for (const Triangle& t : r.triangles) {
    const Triangle m = {id[t[0]], id[t[1]], id[t[2]]};
    if (welded && (m[0] == m[1] || m[1] == m[2] || m[0] == m[2])) continue;
    out.mesh.triangles.push_back(m);
  }
  out.locked.assign(out.mesh.positions.size(), 0);
  for (size_t v = 0; v < source.size(); ++v)
    if (source[v] != kNone && has_flags) out.locked[v] = tile.locked[source[v]];

  if (ctx.layout.hasNormals() && in.normals.size() == in.positions.size()) {
    // The input's convention: its normals along or against its triangles' orientation.
    const std::vector<Vec3d> in_sums = vertexNormalSums(doubles(in.positions), in.triangles);
    int64_t agree = 0;
    for (size_t v = 0; v < in.positions.size(); ++v) {
      const Vec3f n = decodeOctahedral(in.normals[v], ctx.layout.normal_bits);
      const double d = in_sums[v][0] * n[0] + in_sums[v][1] * n[1] + in_sums[v][2] * n[2];
      agree += d > 0 ? 1 : d < 0 ? -1 : 0;
    }
    const double sign = agree >= 0 ? 1.0 : -1.0;
    const std::vector<Vec3d> sums = vertexNormalSums(doubles(out.mesh.positions), out.mesh.triangles);
    out.mesh.normals.resize(out.mesh.positions.size());
    for (size_t v = 0; v < out.mesh.positions.size(); ++v) {
      if (source[v] != kNone) {
        out.mesh.normals[v] = in.normals[source[v]];
        continue;
      }
      const double len = vlen(sums[v]);
      const Vec3d n = len > 0 ? vmul(sums[v], sign / len) : Vec3d{0, 0, 1};
      out.mesh.normals[v] = encodeOctahedral({float(n[0]), float(n[1]), float(n[2])}, ctx.layout.normal_bits);
    }
  }
  return out;
}

}  // namespace scanpress
