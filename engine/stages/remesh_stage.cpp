// Stage `remesh`: piecewise regular remeshing of a tile (engine/remesh/remesh.h), rounded back to the scan's
// integer grid.
//
// A tile whose border could not be kept without the zero-area fans of remesh.cpp is returned as it is (the fans of
// two neighbouring tiles would be welded into one non-manifold seam).
//
// After remeshing, positions are rounded (grid vertices' base coordinates are integers already; heights and the
// points on relief boundaries move by at most half a cell per axis). An added vertex goes to the nearest of the 27
// grid points around it that is free and turns none of its triangles against their normal before rounding (the tiny
// triangles along relief boundaries flip otherwise), else to the nearest free one (at most 1.5 cells away), so no
// two vertices share a point (the coders refuse two corners in one cell, and welding would change the topology);
// only if all 27 are taken is it welded, and triangles that then repeat a vertex are dropped. Input vertices keep
// their points and identity, so locked vertices stay.
// Normals, colors and scalar channels: an input vertex that is kept keeps its own; any other vertex lies on an input
// triangle and takes the barycentric interpolation of that triangle's corners (normals normalised, colors rounded and
// snapped to the layout's levels). Scalar channels (issue 22 part 4): a float channel interpolates (in double,
// rounded to its type) when its corners and the result are finite; an integer channel (a count, a flag, a label,
// whose mean may mean nothing), a quantized float (texture coordinates, whose triangle may span a seam) or a
// non-finite one takes the value of the corner nearest the vertex (the largest weight, the first on ties).
#include <algorithm>
#include <bit>
#include <cmath>
#include <map>
#include <string>

#include "engine/geometry.h"
#include "engine/octahedral.h"
#include "engine/quantize.h"
#include "engine/remesh/remesh.h"
#include "engine/stages/stage.h"

namespace scanpress {
namespace {

using u32 = uint32_t;
constexpr u32 kNone = UINT32_MAX;

Vec3d toDouble(const Vec3u& q) { return {double(q[0]), double(q[1]), double(q[2])}; }

Vec3d decodeVec(const OctNormal& code, int bits) {
  const Vec3f c = decodeOctahedral(code, bits);
  return {c[0], c[1], c[2]};
}

// Barycentric coordinates of p's projection onto the plane of (a, b, c), clamped to the triangle (weights >= 0,
// summing to 1); a zero-area triangle gives its first corner.
std::array<double, 3> barycentric(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  const Vec3d ab = vsub(b, a), ac = vsub(c, a), ap = vsub(p, a);
  const double d00 = vdot(ab, ab), d01 = vdot(ab, ac), d11 = vdot(ac, ac), d20 = vdot(ap, ab), d21 = vdot(ap, ac);
  const double den = d00 * d11 - d01 * d01;
  if (!(den > 0)) return {1, 0, 0};
  double v = (d11 * d20 - d01 * d21) / den, w = (d00 * d21 - d01 * d20) / den;
  v = std::clamp(v, 0.0, 1.0);
  w = std::clamp(w, 0.0, 1.0);
  if (v + w > 1) {
    const double sum = v + w;
    v /= sum;
    w /= sum;
  }
  return {1 - v - w, v, w};
}

// The scalar row at `out` of a point with barycentric weights `w` on input triangle `t` (see the header).
void interpolateScalars(std::span<const ScalarChannel> channels, const ScalarValues& in, size_t stride,
                        const Triangle& t, const std::array<double, 3>& w, uint32_t* out) {
  const int nearest = w[1] > w[0] && w[1] >= w[2] ? 1 : w[2] > w[0] && w[2] > w[1] ? 2 : 0;
  size_t word = 0;
  for (const ScalarChannel& c : channels) {
    const size_t words = size_t(scalarTypeWords(c.type));
    const uint32_t* corner[3];
    for (int k = 0; k < 3; ++k) corner[k] = in.data() + size_t(t[size_t(k)]) * stride + word;
    std::copy_n(corner[nearest], words, out + word);
    const bool same = std::equal(corner[0], corner[0] + words, corner[1]) &&
                      std::equal(corner[0], corner[0] + words, corner[2]);
    if (c.bits == 0 && isFloatScalar(c.type) && !same) {  // (a constant stays bit for bit, -0 included)
      double value[3];
      for (int k = 0; k < 3; ++k) {
        if (c.type == ScalarType::kFloat32) {
          value[k] = double(std::bit_cast<float>(corner[k][0]));
        } else {
          value[k] = std::bit_cast<double>(uint64_t(corner[k][0]) | uint64_t(corner[k][1]) << 32);
        }
      }
      double sum = 0;
      for (int k = 0; k < 3; ++k) sum += w[size_t(k)] * value[k];
      const bool finite = std::isfinite(value[0]) && std::isfinite(value[1]) && std::isfinite(value[2]);
      if (c.type == ScalarType::kFloat32) {
        const float f = float(sum);
        if (finite && std::isfinite(f)) out[word] = std::bit_cast<uint32_t>(f);
      } else if (finite && std::isfinite(sum)) {
        const uint64_t b = std::bit_cast<uint64_t>(sum);
        out[word] = uint32_t(b), out[word + 1] = uint32_t(b >> 32);
      }
    }
    word += words;
  }
}

}  // namespace

uint32_t remeshSpacing(const RemeshStageOptions& options, int bits) {
  const double cells = options.grid * std::ldexp(1.0, bits);
  const double even = 2 * std::round(cells / 2);
  return uint32_t(std::clamp(even, 2.0, 2.0 * double(1u << 30)));
}

Result<StagedTile> remeshStage(const TileContext& ctx, const TileView& tile, const StageSpec& spec) {
  SP_RETURN_IF_ERROR(validateStage(spec).withContext("remesh"));
  return remeshTile(ctx, tile, spec.remesh.tau, remeshSpacing(spec.remesh, ctx.bits));
}

Result<StagedTile> remeshTile(const TileContext& ctx, const TileView& tile, double tau, uint32_t spacing) {
  const QuantizedMesh& in = tile.mesh;
  if (!tile.locked.empty() && tile.locked.size() != in.positions.size())
    return makeError(ErrorCode::kInvalidArgument, "remesh: " + std::to_string(tile.locked.size()) + " lock flags for " +
                                                      std::to_string(in.positions.size()) + " vertices");
  const bool has_flags = !tile.locked.empty();
  SP_ASSIGN_OR_RETURN(Remeshed r, remeshPiecewiseRegular(in, has_flags ? tile.locked : std::span<const uint8_t>(),
                                                         RemeshOptions{.tau = tau, .spacing = spacing}));
  // A tile border edge closed by a fan of zero-area triangles would meet the neighbouring tile's fan on the same
  // grid points (the grid is the scan's), and the decoder would weld four triangles onto one edge: such a tile is
  // kept as it is.
  if (r.border_fans > 0) return StagedTile{in, std::vector<uint8_t>(tile.locked.begin(), tile.locked.end())};
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
  // Each remeshed vertex's triangles, their normals before rounding, and where the vertices are so far (rounded
  // once placed): a point is placed where none of its triangles turns against its normal before rounding, if one
  // of the candidates allows it (tiny triangles along relief boundaries would flip otherwise).
  std::vector<u32> start(r.positions.size() + 1, 0), around;
  for (const Triangle& t : r.triangles)
    for (u32 v : t) ++start[v + 1];
  for (size_t v = 0; v < r.positions.size(); ++v) start[v + 1] += start[v];
  around.resize(start.back());
  {
    std::vector<u32> fill(start.begin(), start.end() - 1);
    for (u32 t = 0; t < r.triangles.size(); ++t)
      for (u32 v : r.triangles[t]) around[fill[v]++] = t;
  }
  const auto normalOf = [](const std::vector<Vec3d>& p, const Triangle& t) {
    return vcross(vsub(p[t[1]], p[t[0]]), vsub(p[t[2]], p[t[0]]));
  };
  std::vector<Vec3d> before(r.triangles.size());
  for (size_t t = 0; t < r.triangles.size(); ++t) before[t] = normalOf(r.positions, r.triangles[t]);
  std::vector<Vec3d> where = r.positions;
  std::vector<std::pair<double, Vec3u>> candidates;
  for (u32 v : order) {
    Vec3u q;
    if (r.input_vertex[v] != kNone) {
      q = in.positions[r.input_vertex[v]];
    } else {
      // The free grid points among the 27 around the rounded position (a taken one would weld two vertices: a
      // change of topology), nearest first; the first that flips none of the vertex's triangles, else the nearest.
      const Vec3d& p = r.positions[v];
      Vec3u base;
      for (int k = 0; k < 3; ++k) base[size_t(k)] = u32(std::clamp(std::round(p[size_t(k)]), 0.0, top));
      candidates.clear();
      for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dz = -1; dz <= 1; ++dz) {
            const int64_t c[3] = {int64_t(base[0]) + dx, int64_t(base[1]) + dy, int64_t(base[2]) + dz};
            if (c[0] < 0 || c[1] < 0 || c[2] < 0 || c[0] > int64_t(top) || c[1] > int64_t(top) || c[2] > int64_t(top))
              continue;
            const Vec3u cand{u32(c[0]), u32(c[1]), u32(c[2])};
            if (!at.count(cand))
              candidates.push_back({vlen(vsub(p, {double(c[0]), double(c[1]), double(c[2])})), cand});
          }
      if (candidates.empty()) {  // all 27 taken: weld onto the rounded one
        id[v] = at.at(base);
        ++welded;
        continue;
      }
      std::sort(candidates.begin(), candidates.end());
      q = candidates[0].second;
      for (const auto& [d, cand] : candidates) {
        where[v] = toDouble(cand);
        bool flips = false;
        for (u32 k = start[v]; k < start[v + 1] && !flips; ++k) {
          const Vec3d& n = before[around[k]];
          flips = vdot(n, n) > 0 && !(vdot(normalOf(where, r.triangles[around[k]]), n) > 0);
        }
        if (!flips) {
          q = cand;
          break;
        }
      }
    }
    where[v] = toDouble(q);
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

  // Attributes: a kept input vertex keeps its own; another takes the interpolation, at its exact (unrounded)
  // position, of the input triangle it lies on.
  const bool normals = ctx.layout.hasNormals() && in.normals.size() == in.positions.size();
  const bool colors = ctx.layout.hasColors() && in.colors.size() == in.positions.size();
  const size_t stride = size_t(ctx.layout.scalarStride());
  if (stride && in.scalars.size() != in.positions.size() * stride)
    return makeError(ErrorCode::kInvalidArgument, "remesh: the tile lacks the layout's scalar values");
  const bool scalars = stride > 0;
  if (normals) out.mesh.normals.resize(out.mesh.positions.size());
  if (colors) out.mesh.colors.resize(out.mesh.positions.size());
  if (scalars) out.mesh.scalars.resize(out.mesh.positions.size() * stride);
  std::vector<u32> first(out.mesh.positions.size(), kNone);  // a remeshed vertex that became each output vertex
  for (u32 v = 0; v < id.size(); ++v)
    if (first[id[v]] == kNone) first[id[v]] = v;
  for (size_t o = 0; o < out.mesh.positions.size() && (normals || colors || scalars); ++o) {
    if (source[o] != kNone) {
      if (normals) out.mesh.normals[o] = in.normals[source[o]];
      if (colors) out.mesh.colors[o] = in.colors[source[o]];
      if (scalars)
        std::copy_n(in.scalars.begin() + ptrdiff_t(size_t(source[o]) * stride), stride,
                    out.mesh.scalars.begin() + ptrdiff_t(o * stride));
      continue;
    }
    const u32 v = first[o];
    if (r.source_triangle[v] >= in.triangles.size())
      return makeError(ErrorCode::kInternal, "remesh: an added vertex without its input triangle");
    const Triangle& t = in.triangles[r.source_triangle[v]];
    const std::array<double, 3> w = barycentric(r.positions[v], toDouble(in.positions[t[0]]),
                                                toDouble(in.positions[t[1]]), toDouble(in.positions[t[2]]));
    if (normals) {
      Vec3d n{0, 0, 0};
      for (int k = 0; k < 3; ++k) {
        const Vec3f c = decodeOctahedral(in.normals[t[size_t(k)]], ctx.layout.normal_bits);
        n = vadd(n, vmul(Vec3d{c[0], c[1], c[2]}, w[size_t(k)]));
      }
      const double len = vlen(n);
      if (len > 1e-9) n = vmul(n, 1 / len);
      else n = decodeVec(in.normals[t[0]], ctx.layout.normal_bits);  // opposite normals cancel: take a corner's
      out.mesh.normals[o] = encodeOctahedral({float(n[0]), float(n[1]), float(n[2])}, ctx.layout.normal_bits);
    }
    if (colors) {
      Rgba8 c{};
      for (int ch = 0; ch < 4; ++ch) {
        double sum = 0;
        for (int k = 0; k < 3; ++k) sum += w[size_t(k)] * in.colors[t[size_t(k)]][size_t(ch)];
        c[size_t(ch)] = uint8_t(std::clamp(std::lround(sum), 0l, 255l));
      }
      out.mesh.colors[o] = quantizeColor(c, ctx.layout);
    }
    if (scalars)
      interpolateScalars(ctx.layout.scalars, in.scalars, stride, t, w, out.mesh.scalars.data() + o * stride);
  }
  return out;
}

}  // namespace scanpress
