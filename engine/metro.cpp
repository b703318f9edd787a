#include "engine/metro.h"

#include <cmath>

#include "engine/geometry.h"

namespace scanpress {
namespace {

uint64_t mix(uint64_t h) {
  h ^= h >> 33;
  h *= 0xFF51AFD7ED558CCDull;
  h ^= h >> 33;
  h *= 0xC4CEB9FE1A85EC53ull;
  h ^= h >> 33;
  return h;
}

double unit(uint64_t h) { return double(h >> 11) / double(1ull << 53); }

// Point of the triangle for (u, v) in the unit square, folding the upper half back into the triangle.
Vec3d onTriangle(const Vec3d& a, const Vec3d& b, const Vec3d& c, double u, double v) {
  if (u + v > 1) u = 1 - u, v = 1 - v;
  return vadd(a, vadd(vmul(vsub(b, a), u), vmul(vsub(c, a), v)));
}

}  // namespace

double ErrorAccumulator::rms() const { return count ? std::sqrt(sum_sq / count) : 0.0; }

double surfaceArea(std::span<const Vec3d> p, std::span<const Triangle> t) {
  double area = 0;
  for (const auto& tri : t) area += triangleArea(p[tri[0]], p[tri[1]], p[tri[2]]);
  return area;
}

SurfaceSampler::SurfaceSampler(const SampleOptions& opt)
    : opt_(opt), base_(mix(opt.seed * 0x9E3779B97F4A7C15ull ^ mix(opt.stream + 0x51ED27))) {}

void SurfaceSampler::sample(std::span<const Vec3d> p, std::span<const Triangle> tris, std::vector<Vec3d>& out) {
  // Rank-1 lattice generator for n points: the R2 sequence (plastic number), good 2D stratification for any n.
  constexpr double kA1 = 0.7548776662466927, kA2 = 0.5698402909980532;
  for (size_t i = 0; i < tris.size(); ++i) {
    const uint64_t t = next_triangle_++;
    const Vec3d& a = p[tris[i][0]];
    const Vec3d& b = p[tris[i][1]];
    const Vec3d& c = p[tris[i][2]];
    const double want = opt_.density * triangleArea(a, b, c) + carry_;
    const uint64_t n = want > 0 ? static_cast<uint64_t>(want) : 0;
    carry_ = want - double(n);
    if (n == 0) continue;
    uint64_t h = mix(base_ ^ (t * 0xD1B54A32D192ED03ull));
    const double off_u = unit(h), off_v = unit(mix(h + 1));
    for (uint64_t k = 0; k < n; ++k) {
      double u, v;
      if (opt_.stratified) {
        u = std::fmod(off_u + kA1 * double(k), 1.0);
        v = std::fmod(off_v + kA2 * double(k), 1.0);
      } else {
        h = mix(h + 0x9E3779B97F4A7C15ull);
        u = unit(h);
        v = unit(mix(h ^ 0xABCDEF));
      }
      out.push_back(onTriangle(a, b, c, u, v));
    }
  }
}

void sampleSurface(std::span<const Vec3d> p, std::span<const Triangle> tris, const SampleOptions& opt,
                   std::vector<Vec3d>& out) {
  SurfaceSampler(opt).sample(p, tris, out);
  if (opt.vertices) sampleVertices(p, tris, out);
}

void sampleVertices(std::span<const Vec3d> p, std::span<const Triangle> tris, std::vector<Vec3d>& out) {
  std::vector<uint8_t> used(p.size(), 0);
  for (const auto& tri : tris)
    for (uint32_t v : tri) used[v] = 1;
  for (size_t v = 0; v < p.size(); ++v)
    if (used[v]) out.push_back(p[v]);
}

}  // namespace scanpress
