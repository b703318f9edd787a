#include "engine/codecs/attributes.h"

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
i128 absolute(i128 x) { return x < 0 ? -x : x; }
// round(num / den) for den > 0, halves away from zero.
int roundDiv(i128 num, i128 den) {
  return num >= 0 ? int((num + den / 2) / den) : -int((-num + den / 2) / den);
}
}  // namespace

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
