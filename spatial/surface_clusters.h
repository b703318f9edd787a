// closestMany's lower bounds over the clusters' plane records, kLanes triangles at a time, and the two ways a run
// takes its candidates (in place, or copied out). Inline: closestMany runs them per run and per point.
#pragma once

#include <algorithm>
#include <cstddef>
#include <limits>
#include <span>
#include <vector>
#if defined(__SSE__)
#include <xmmintrin.h>
#endif

#include "engine/geometry.h"
#include "spatial/surface_index_internal.h"

namespace scanpress::surface {

typedef float Lanes __attribute__((vector_size(4 * kLanes), aligned(4)));
typedef int LaneInts __attribute__((vector_size(4 * kLanes), aligned(4)));

constexpr float kEps = std::numeric_limits<float>::epsilon();

// Grows the box [lo, hi] to take in [add_lo, add_hi] if the result's half-diagonal stays within `half`; false
// (box unchanged) otherwise.
inline bool growWithin(Vec3d& lo, Vec3d& hi, const Vec3d& add_lo, const Vec3d& add_hi, double half) {
  Vec3d l2, h2;
  for (int a = 0; a < 3; ++a) l2[a] = std::min(lo[a], add_lo[a]), h2[a] = std::max(hi[a], add_hi[a]);
  const Vec3d d = vsub(h2, l2);
  if (!(0.25 * vdot(d, d) <= half * half)) return false;
  lo = l2, hi = h2;
  return true;
}

// Lane `at` of blocks of plane records (16 rows of kLanes floats): the record's component r is result[r * kLanes].
template <typename Float>
inline Float* laneOf(Float* rows, size_t at) {
  return rows + (at / kLanes) * 16 * kLanes + at % kLanes;
}

// Copies the record of lane `from` into lane `to`, or, without `from`, makes `to` unused: plane offset -inf, a
// bound of +inf (its triangle is never tested).
inline void setLane(float* to, const float* from) {
  for (size_t a = 0; a < 16; ++a)
    to[a * kLanes] = from ? from[a * kLanes] : a == 3 ? -std::numeric_limits<float>::infinity() : 0.f;
}

// Squared lower bounds of the distance from p = (x, y, z) (relative to the origin) to the kLanes triangles of one
// block of plane records: the distance to the plane and, within the plane, beyond the farthest of the edge lines.
inline Lanes blockBounds2(const Lanes* r, Lanes x, Lanes y, Lanes z) {
  const Lanes h = r[0] * x + r[1] * y + r[2] * z - r[3];
  const Lanes e0 = r[4] * x + r[5] * y + r[6] * z - r[7];
  const Lanes e1 = r[8] * x + r[9] * y + r[10] * z - r[11];
  const Lanes e2 = r[12] * x + r[13] * y + r[14] * z - r[15];
  Lanes e = e0 > e1 ? e0 : e1;
  e = e > e2 ? e : e2;
  e = e > Lanes{} ? e : Lanes{};
  return h * h + e * e;
}
// blockBounds2 for `blocks` blocks.
inline void lowerBounds2(const float* rows, size_t blocks, const float* p, float* __restrict out) {
  const Lanes* r = reinterpret_cast<const Lanes*>(rows);
  const Lanes x = Lanes{} + p[0], y = Lanes{} + p[1], z = Lanes{} + p[2];
  for (size_t b = 0; b < blocks; ++b, r += 16, out += kLanes)
    *reinterpret_cast<Lanes*>(out) = blockBounds2(r, x, y, z);
}

// Bit l set where a[l] <= b[l]: one movmskps on x86 (GCC does not find it in the portable loop).
inline unsigned lanesAtMost(Lanes a, Lanes b) {
  const LaneInts m = a <= b;
#if defined(__SSE__)
  return unsigned(_mm_movemask_ps(reinterpret_cast<__m128>(m)));
#else
  unsigned bits = 0;
  for (size_t l = 0; l < kLanes; ++l) bits |= unsigned(m[l] & 1) << l;
  return bits;
#endif
}

// The bounds of the `count` blocks of plane records at rows[0], rows[1], ... (at least one), and the index of the
// least bound (the first of equals), in one pass.
inline size_t boundsAndLeast(const float* const* rows, size_t count, const float* p, float* __restrict out) {
  const Lanes x = Lanes{} + p[0], y = Lanes{} + p[1], z = Lanes{} + p[2];
  Lanes* v = reinterpret_cast<Lanes*>(out);
  Lanes low = v[0] = blockBounds2(reinterpret_cast<const Lanes*>(rows[0]), x, y, z);
  for (size_t b = 1; b < count; ++b) {
    v[b] = blockBounds2(reinterpret_cast<const Lanes*>(rows[b]), x, y, z);
    low = v[b] < low ? v[b] : low;
  }
  float least = low[0];
  for (size_t l = 1; l < kLanes; ++l) least = low[l] < least ? low[l] : least;
  for (size_t b = 0; b < count; ++b)
    if (const unsigned bits = lanesAtMost(v[b], Lanes{} + least)) return b * kLanes + __builtin_ctz(bits);
  return 0;  // NaN bounds only
}

// A run's candidates, in place: the blocks of its clusters as they are (unused lanes are never nearest). Appends
// the blocks to `blocks` and each lane's slot to `slots`; returns the number of lanes.
inline size_t candidatesInPlace(const ClusterSet& set, std::span<const uint32_t> clusters,
                                std::vector<const float*>& blocks, uint32_t* slots) {
  size_t count = 0;
  for (uint32_t k : clusters)
    for (size_t b = set.first[k]; b < set.first[k + 1]; ++b) {
      blocks.push_back(&set.rows[b * 16 * kLanes]);
      for (size_t l = 0; l < kLanes; ++l) slots[count++] = uint32_t(b * kLanes + l);
    }
  return count;
}

// A run's candidates, copied out: the triangles of its clusters whose squared bound from c (relative to the
// origin, in float) is at most `within`, their records into blocks of `rows` (the last block's rest unused) and
// their slots into `slots`; prefetches their corners. Appends the blocks to `blocks`; returns the number of lanes.
inline size_t candidatesCopiedOut(const ClusterSet& set, std::span<const uint32_t> clusters, const float* c,
                                  float within, float* rows, std::vector<const float*>& blocks, uint32_t* slots) {
  size_t count = 0;
  for (uint32_t k : clusters) {
    const size_t b0 = set.first[k], b1 = set.first[k + 1];
    Lanes near[kClusterSize / kLanes];
    lowerBounds2(&set.rows[b0 * 16 * kLanes], b1 - b0, c, reinterpret_cast<float*>(near));
    for (size_t b = b0; b < b1; ++b)
      for (unsigned bits = lanesAtMost(near[b - b0], Lanes{} + within); bits; bits &= bits - 1) {
        const size_t slot = b * kLanes + __builtin_ctz(bits);  // not an unused lane: its bound is infinite
        setLane(laneOf(rows, count), laneOf(set.rows.data(), slot));
        slots[count++] = uint32_t(slot);
        const char* corners = reinterpret_cast<const char*>(&set.corners[3 * slot]);
        __builtin_prefetch(corners);
        __builtin_prefetch(corners + 3 * sizeof(Vec3d) - 1);
      }
  }
  for (size_t lanes = count; lanes % kLanes; ++lanes) setLane(laneOf(rows, lanes), nullptr);  // the rest
  for (size_t b = 0; b * kLanes < count; ++b) blocks.push_back(&rows[b * 16 * kLanes]);
  return count;
}

}  // namespace scanpress::surface
