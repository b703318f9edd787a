// The Morton order of a batch of points (surface_morton.h).
#include "spatial/surface_morton.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

namespace scanpress::surface {

namespace {

// The bits of v (21 of them) two apart: one axis of a 63-bit Morton key.
uint64_t spreadBits(uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffULL;
  v = (v | v << 16) & 0x1f0000ff0000ffULL;
  v = (v | v << 8) & 0x100f00f00f00f00fULL;
  v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
  v = (v | v << 2) & 0x1249249249249249ULL;
  return v;
}

}  // namespace

// A stable radix sort of the words on the bytes where they differ: a batch of nearby points shares most of its
// keys' bits.
void mortonOrder(std::span<const Vec3d> points, double inv_cell, int index_bits, std::vector<uint64_t>& order,
                 std::vector<uint64_t>& scratch) {
  const size_t n = points.size();
  order.resize(n);
  scratch.resize(n);
  auto finite = [](const Vec3d& p) { return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]); };
  Vec3d lo, hi;
  for (int a = 0; a < 3; ++a) lo[a] = std::numeric_limits<double>::infinity(), hi[a] = -lo[a];
  for (const Vec3d& p : points)
    if (finite(p))
      for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
  const int bits = std::min(21, (63 - index_bits) / 3);
  const double top = double((1 << bits) - 1);
  double scale = inv_cell;
  for (int a = 0; a < 3; ++a)
    if ((hi[a] - lo[a]) * scale > top) scale = top / (hi[a] - lo[a]);
  for (size_t i = 0; i < n; ++i) {
    const Vec3d& p = points[i];
    if (!finite(p)) {
      order[i] = uint64_t(1) << 63 | i;
      continue;
    }
    uint64_t key = 0;
    for (int a = 0; a < 3; ++a) {  // NaN (an infinite span times a zero scale) counts as 0; the conversion floors
      const double g = (p[a] - lo[a]) * scale;
      key |= spreadBits(uint64_t(g > 0 ? std::min(g, top) : 0.0)) << (2 - a);
    }
    order[i] = key << index_bits | i;
  }
  uint64_t vary = 0;
  for (size_t i = 1; i < n; ++i) vary |= order[i] ^ order[0];
  uint64_t* from = order.data();
  uint64_t* to = scratch.data();
  for (int shift = index_bits; shift < 64; shift += 8) {
    if (((vary >> shift) & 0xff) == 0) continue;  // the same byte in every word
    uint32_t start[257] = {};
    for (size_t k = 0; k < n; ++k) ++start[((from[k] >> shift) & 0xff) + 1];
    for (size_t d = 1; d < 257; ++d) start[d] += start[d - 1];
    for (size_t k = 0; k < n; ++k) to[start[(from[k] >> shift) & 0xff]++] = from[k];
    std::swap(from, to);
  }
  if (from != order.data()) order.swap(scratch);
}

}  // namespace scanpress::surface
