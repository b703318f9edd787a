#include "engine/codecs/attributes.h"

#include <cmath>

namespace scanpress::hierarchy {

VertexFaces::VertexFaces(u32 n, std::span<const Triangle> tris) : start(size_t(n) + 1, 0) {
  for (const auto& t : tris)
    for (u32 v : t) ++start[v + 1];
  for (u32 v = 0; v < n; ++v) start[v + 1] += start[v];
  faces.resize(start[n]);
  std::vector<u64> fill(start.begin(), start.end() - 1);
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

namespace {
// Triangle t's cross product `c` (from its first corner; exact) and, per corner k, the weight w[k] that makes
// c * w[k] the unit normal times the angle at corner k. False for a zero-area triangle (no normal).
bool normalTerms(const std::vector<Vec3u>& pos, const Triangle& t, double (&c)[3], double (&w)[3]) {
  int64_t e[3][3];  // e[k]: from corner k to corner k + 1
  for (int k = 0; k < 3; ++k)
    for (int i = 0; i < 3; ++i) e[k][i] = int64_t(pos[t[(k + 1) % 3]][i]) - pos[t[k]][i];
  // Exact in int64 (coordinates below 2^24) and in double (below 2^53); the same from every corner.
  c[0] = double(e[0][1] * -e[2][2] - e[0][2] * -e[2][1]);
  c[1] = double(e[0][2] * -e[2][0] - e[0][0] * -e[2][2]);
  c[2] = double(e[0][0] * -e[2][1] - e[0][1] * -e[2][0]);
  const double len = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
  if (len == 0) return false;
  for (int k = 0; k < 3; ++k) {
    const int64_t* a = e[k];            // to the next corner
    const int64_t* b = e[(k + 2) % 3];  // from the previous corner: the edge to it is -b
    const double dot = -double(a[0] * b[0] + a[1] * b[1] + a[2] * b[2]);
    w[k] = arctangent(len, dot) / len;
  }
  return true;
}
}  // namespace

std::vector<std::array<double, 3>> angleWeightedNormals(const std::vector<Vec3u>& pos,
                                                        const std::vector<Triangle>& tris) {
  std::vector<std::array<double, 3>> sum(pos.size(), {0.0, 0.0, 0.0});
  double c[3], w[3];
  for (const Triangle& t : tris) {
    if (!normalTerms(pos, t, c, w)) continue;
    for (int k = 0; k < 3; ++k)
      for (int i = 0; i < 3; ++i) sum[t[k]][i] += c[i] * w[k];
  }
  return sum;
}

std::array<double, 3> angleWeightedNormalAt(const std::vector<Vec3u>& pos, const std::vector<Triangle>& tris,
                                            std::span<const u32> faces, u32 v) {
  std::array<double, 3> sum{0.0, 0.0, 0.0};
  double c[3], w[3];
  for (u32 f : faces) {
    const Triangle& t = tris[f];
    if (!normalTerms(pos, t, c, w)) continue;
    for (int k = 0; k < 3; ++k)
      if (t[k] == v)
        for (int i = 0; i < 3; ++i) sum[i] += c[i] * w[k];
  }
  return sum;
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
  scalar.resize(layout.scalars.size());
  for (size_t c = 0; c < layout.scalars.size(); ++c)
    scalar[c].cls.assign(kActivity, SymbolModel(u32(scalarBits(codedType(layout.scalars[c]))) + 1));
}

bool predictTexcoord(const Vec3u& pv, const Vec3u& pa, const Vec3u& pb, const std::array<int64_t, 2>& ta,
                     const std::array<int64_t, 2>& tb, int orientation, std::array<double, 2>& out) {
  double e[3], w[3], ee = 0, we = 0;
  for (int k = 0; k < 3; ++k) {
    e[k] = double(pb[k]) - double(pa[k]), w[k] = double(pv[k]) - double(pa[k]);
    ee += e[k] * e[k], we += w[k] * e[k];
  }
  if (ee == 0) return false;
  const double t = we / ee;
  double hh = 0;
  for (int k = 0; k < 3; ++k) {
    const double r = w[k] - t * e[k];
    hh += r * r;
  }
  const double h = std::sqrt(hh / ee) * orientation;  // the height over a-b, in units of |b - a|
  const double du = double(tb[0] - ta[0]), dv = double(tb[1] - ta[1]);
  out[0] = double(ta[0]) + t * du - h * dv;
  out[1] = double(ta[1]) + t * dv + h * du;
  return std::isfinite(out[0]) && std::isfinite(out[1]);
}

bool predictTexcoordAffine(const Vec3u& pv, const Vec3u& pa, const Vec3u& pb, const Vec3u& pc,
                           const std::array<int64_t, 2>& ta, const std::array<int64_t, 2>& tb,
                           const std::array<int64_t, 2>& tc, std::array<double, 2>& out) {
  // pv - pc = x (pa - pc) + y (pb - pc) in least squares (pv projected onto the plane of a, b, c).
  double e[3], f[3], w[3];
  for (int k = 0; k < 3; ++k)
    e[k] = double(pa[k]) - double(pc[k]), f[k] = double(pb[k]) - double(pc[k]), w[k] = double(pv[k]) - double(pc[k]);
  double ee = 0, ef = 0, ff = 0, we = 0, wf = 0;
  for (int k = 0; k < 3; ++k)
    ee += e[k] * e[k], ef += e[k] * f[k], ff += f[k] * f[k], we += w[k] * e[k], wf += w[k] * f[k];
  const double det = ee * ff - ef * ef;
  if (!(det > 1e-9 * ee * ff)) return false;  // a, b, c (nearly) collinear
  const double x = (we * ff - wf * ef) / det, y = (wf * ee - we * ef) / det;
  for (int k = 0; k < 2; ++k) out[k] = double(tc[k]) + x * double(ta[k] - tc[k]) + y * double(tb[k] - tc[k]);
  return std::isfinite(out[0]) && std::isfinite(out[1]);
}

}  // namespace scanpress::hierarchy
