#include "engine/codecs/attributes.h"

#include <cmath>

namespace scanpress::hierarchy {

VertexFaces::VertexFaces(u32 n, std::span<const Triangle> tris) : start(size_t(n) + 1, 0) {
  for (const auto& t : tris)
    for (u32 v : t) ++start[v + 1];
  for (u32 v = 0; v < n; ++v) start[v + 1] += start[v];
  faces.resize(start[n]);
  std::vector<u32> fill(start.begin(), start.end() - 1);
  for (u32 i = 0; i < u32(tris.size()); ++i)
    for (u32 v : tris[i]) faces[fill[v]++] = i;
}

namespace {

// atan2(y, x) for y >= 0, in [0, pi]: a polynomial (Abramowitz and Stegun 4.4.49 form, error below 1e-5 rad) in
// basic operations, the same on every machine.
double arctangent(double y, double x) {
  const double ax = std::fabs(x);
  if (y == 0 && ax == 0) return 0;
  const bool steep = y > ax;
  const double a = steep ? ax / y : y / ax, a2 = a * a;
  double r = a * (0.9998660 + a2 * (-0.3302995 + a2 * (0.1801410 + a2 * (-0.0851330 + a2 * 0.0208351))));
  if (steep) r = 1.5707963267948966 - r;
  if (x < 0) r = 3.141592653589793 - r;
  return r;
}

i128 absolute(i128 x) { return x < 0 ? -x : x; }
// round(num / den) for den > 0, halves away from zero.
int roundDiv(i128 num, i128 den) { return num >= 0 ? int((num + den / 2) / den) : -int((-num + den / 2) / den); }
}  // namespace

Sum3 angleWeightedNormal(const std::vector<Vec3u>& pos, const std::vector<Triangle>& tris, std::span<const u32> faces,
                         u32 v) {
  double sum[3] = {0, 0, 0};
  for (u32 t : faces) {
    const Triangle& tri = tris[t];
    const int k = tri[0] == v ? 0 : tri[1] == v ? 1 : 2;
    const Vec3u& p = pos[tri[k]];
    const Vec3u& q = pos[tri[(k + 1) % 3]];
    const Vec3u& r = pos[tri[(k + 2) % 3]];
    int64_t a[3], b[3];
    for (int i = 0; i < 3; ++i) a[i] = int64_t(q[i]) - p[i], b[i] = int64_t(r[i]) - p[i];
    // Exact in int64 (coordinates below 2^24) and in double (below 2^53).
    const double c[3] = {double(a[1] * b[2] - a[2] * b[1]), double(a[2] * b[0] - a[0] * b[2]),
                         double(a[0] * b[1] - a[1] * b[0])};
    const double dot = double(a[0] * b[0] + a[1] * b[1] + a[2] * b[2]);
    const double len = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    if (len == 0) continue;  // a zero-area triangle has no normal
    const double w = arctangent(len, dot) / len;
    for (int i = 0; i < 3; ++i) sum[i] += c[i] * w;
  }
  // At most pi per triangle: far inside i128 after the scaling.
  return {i128(std::ldexp(sum[0], 60)), i128(std::ldexp(sum[1], 60)), i128(std::ldexp(sum[2], 60))};
}

std::array<int, 2> octahedralOfSum(const Sum3& s, int bits) {
  const i128 m = (i128(1) << (bits - 1)) - 1;
  const i128 l1 = absolute(s[0]) + absolute(s[1]) + absolute(s[2]);
  if (s[2] >= 0) return {roundDiv(s[0] * m, l1), roundDiv(s[1] * m, l1)};
  return {(s[0] >= 0 ? 1 : -1) * roundDiv((l1 - absolute(s[1])) * m, l1),
          (s[1] >= 0 ? 1 : -1) * roundDiv((l1 - absolute(s[0])) * m, l1)};
}

int foldPreimages(std::array<int, 2> f, int m, std::array<std::array<int, 2>, 4>& out) {
  const std::array<int, 2> g = foldCode(f, m);
  int count = 0;
  for (int su : {1, -1})
    for (int sv : {1, -1}) {
      const std::array<int, 2> c{su * std::abs(g[0]), sv * std::abs(g[1])};
      if (foldCode(c, m) != f) continue;
      bool seen = false;
      for (int i = 0; i < count; ++i) seen |= out[i] == c;
      if (!seen) out[count++] = c;
    }
  return count;
}

AttributeModels::AttributeModels(const AttributeLayout& layout) {
  if (layout.hasNormals()) {
    const u32 classes = layout.normal_bits;  // |residual| <= 2^(bits-1) - 1
    normal_u.assign(kActivity, SymbolModel(classes));
    normal_v.assign(kActivity * 5, SymbolModel(classes));
  }
  if (layout.hasColors()) color.assign(kActivity * 4 * 4, SymbolModel(9));  // |residual| <= 128
}

}  // namespace scanpress::hierarchy
