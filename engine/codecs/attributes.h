// Per-vertex normals and colors of a tile's lossless level, predicted from what the decoder already holds (format
// version 2 of kdtree, octree and edgebreaker; version 1 wrote them raw, codeRawAttributes in hierarchy.h). Coded
// after the positions and triangles, in vertex order:
//
// - Normals: predicted from the decoded geometry, the angle-weighted normal of the vertex's triangles (scans'
//   normals are mostly computed so: on gargo and parasaurolophus it halves the normals' bytes against the
//   area-weighted sum of cross products, and it is a little better on rs1), projected onto the octahedral square in
//   integer arithmetic, so that encoder and decoder agree on every machine. A flip bit says when the scan's normal points away from the prediction (normals
//   pointing inward); a vertex without triangles is predicted by the previous vertex's normal. When the prediction
//   lies in the folded lower half of the square, prediction and normal are both mirrored through the z = 0 plane
//   (the fold), which maps the lower hemisphere onto the unfolded diamond, so that normals on either side of the
//   square's folded border stay close; the few border codes that two codes of one direction fold onto carry an index
//   among them, so that the code itself comes back, not only its direction. The residual of each component,
//   modulo the 2^bits - 1 codes, is coded as a bit-length class (adaptive, context: the mean class of the vertex's
//   decoded neighbours, and for the second component the first's class), a sign, a modelled top bit and raw bits.
// - Colors: each channel predicted by the mean of the decoded neighbours (lower vertex numbers; the previous vertex
//   when there is none). Green's residual is coded first; red's and blue's after subtracting green's (colors of
//   scans are mostly grey or brown, their channel residuals move together); alpha on its own. Classes as for normals.
//
// Draco predicts normals the same way (its geometric normal predictor with the canonicalised octahedral transform);
// the integer projection, the neighbour-activity contexts and the exact code round trip are ours.
#pragma once

#include <cmath>
#include <optional>
#include <span>
#include <vector>

#include "engine/codecs/hierarchy.h"
#include "engine/quantize.h"

namespace scanpress::hierarchy {

using i128 = __int128;
using Sum3 = std::array<i128, 3>;

// For each vertex, the triangles that use it (a triangle once per corner naming it).
struct VertexFaces {
  std::vector<u64> start;  // n + 1 entries (a hostile edgebreaker tile may claim more than 2^32 / 3 triangles)
  std::vector<u32> faces;
  VertexFaces(u32 n, std::span<const Triangle> tris);
  std::span<const u32> of(u32 v) const { return {faces.data() + start[v], faces.data() + start[v + 1]}; }
};

// The octahedral code (signed units, each in [-M, M], M = 2^(bits-1) - 1) of the direction s != 0: the projection of
// encodeOctahedral, in exact integer arithmetic with rounding half away from zero.
std::array<int, 2> octahedralOfSum(const Sum3& s, int bits);

// The z-mirror of a signed octahedral code: the fold between the upper diamond and the lower corners.
inline std::array<int, 2> foldCode(std::array<int, 2> c, int m) {
  return {(m - std::abs(c[1])) * (c[0] >= 0 ? 1 : -1), (m - std::abs(c[0])) * (c[1] >= 0 ? 1 : -1)};
}

// The direction of a signed code as an integer vector on the octahedron |x| + |y| + |z| = m (exact).
inline std::array<int64_t, 3> octahedralVector(std::array<int, 2> c, int m) {
  const int z = m - std::abs(c[0]) - std::abs(c[1]);
  if (z >= 0) return {c[0], c[1], z};
  const auto f = foldCode(c, m);
  return {f[0], f[1], z};
}

// The codes that fold onto `f` (one, or two to four on the square's border), in a fixed order.
int foldPreimages(std::array<int, 2> f, int m, std::array<std::array<int, 2>, 4>& out);

struct AttributeModels {
  static constexpr int kActivity = 8;  // bins of the neighbours' mean residual class (0: no decoded neighbour)
  explicit AttributeModels(const AttributeLayout& layout);
  std::vector<SymbolModel> normal_u, normal_v;  // [activity], [activity][min(class u, 4)]
  BitModel normal_sign[2], normal_top[2][17], flip[2];
  std::vector<SymbolModel> color;  // [activity][channel][min(class of green, 3)]
  BitModel color_sign[4], color_top[4][9];
  struct Scalar {
    std::vector<SymbolModel> cls;  // [activity]: the residual's bit length, 0..8 x bytes
    BitModel sign, top[65];
  };
  std::vector<Scalar> scalar;  // per scalar channel
};

inline int activityBin(u32 sum, u32 count) {
  if (count == 0) return 0;
  const u32 m = 2 * sum / count;  // the mean class, in halves
  static constexpr u32 kEdges[] = {1, 2, 4, 6, 9, 14};
  int bin = 1;
  while (bin < AttributeModels::kActivity - 1 && m >= kEdges[bin - 1]) ++bin;
  return bin;
}

inline int bitLength(u32 v) { return v == 0 ? 0 : 32 - __builtin_clz(v); }

// A residual r as class (bit length of |r|), sign, top bit below the leading one, raw bits. Returns r; `cls` gets
// its class.
template <class Io>
int codeResidual(Io& io, SymbolModel& class_model, BitModel& sign, BitModel* top, int r, int& cls) {
  const u32 mag_in = u32(std::abs(r));
  const int k = int(io.sym(class_model, u32(bitLength(mag_in))));
  cls = k;
  if (k == 0) return 0;
  u32 mag = 1u << (k - 1);
  if (k >= 2) mag |= u32(io.bit(top[k], int((mag_in >> (k - 2)) & 1))) << (k - 2);
  if (k >= 3) mag |= io.bits(mag_in & ((1u << (k - 2)) - 1), k - 2);
  return io.bit(sign, r < 0) ? -int(mag) : int(mag);
}

// (a mod q) in [-(q-1)/2, (q-1)/2] for odd q (normals), in [-(q/2 - 1), q/2] for even q (color levels).
inline int wrapCentered(int a, int q) {
  const int h = (q - 1) / 2;
  a %= q;
  if (a > h) a -= q;
  if (a < -h) a += q;
  return a;
}

// The angle-weighted normals of the vertices (Thürmer and Wüthrich 1998: each triangle's unit normal weighted by its
// angle at the vertex), unscaled, in one pass over the triangles in their order. In double arithmetic with basic
// operations and sqrt only (IEEE-exact everywhere; attributes.cpp is compiled without floating-point contraction)
// and an arctangent of our own, so that encoder and decoder agree on every machine and C library.
std::vector<std::array<double, 3>> angleWeightedNormals(const std::vector<Vec3u>& pos,
                                                        const std::vector<Triangle>& tris);
// The same sum at one vertex v, over `faces` (v's triangles, each once), in their order (pm: the summation order
// differs from angleWeightedNormals', so a codec uses one or the other on both sides).
std::array<double, 3> angleWeightedNormalAt(const std::vector<Vec3u>& pos, const std::vector<Triangle>& tris,
                                            std::span<const u32> faces, u32 v);
// A sum of at most pi per triangle, scaled by 2^60 to integers: far inside i128.
inline Sum3 scaledSum(const std::array<double, 3>& d) {
  return {i128(std::ldexp(d[0], 60)), i128(std::ldexp(d[1], 60)), i128(std::ldexp(d[2], 60))};
}

// One normal, predicted by the signed code `pred`; `actual` is the truth's signed code (encoder; anything when
// decoding). `bin` is the context; `activity` gets the residual's classes. Returns the decoded code.
template <class Io>
OctNormal codeNormal(Io& io, AttributeModels& models, int bits, std::array<int, 2> pred, std::array<int, 2> actual,
                     bool encoding, int bin, int& activity) {
  const int m = (1 << (bits - 1)) - 1, q = 2 * m + 1;
  const bool mirror = std::abs(pred[0]) + std::abs(pred[1]) > m;
  std::array<int, 2> target = actual;
  if (mirror) pred = foldCode(pred, m), target = foldCode(actual, m);
  int ku = 0, kv = 0;
  const int ru = codeResidual(io, models.normal_u[bin], models.normal_sign[0], models.normal_top[0],
                              wrapCentered(target[0] - pred[0], q), ku);
  const int rv = codeResidual(io, models.normal_v[bin * 5 + std::min(ku, 4)], models.normal_sign[1],
                              models.normal_top[1], wrapCentered(target[1] - pred[1], q), kv);
  std::array<int, 2> code{wrapCentered(pred[0] + ru, q), wrapCentered(pred[1] + rv, q)};
  if (mirror) {
    std::array<std::array<int, 2>, 4> pre;
    const int count = foldPreimages(code, m, pre);
    u32 index = 0;
    if (encoding)
      while (index + 1 < u32(count) && pre[index] != actual) ++index;
    if (count > 1) index = io.uniform(index, u32(count));
    code = pre[index];
  }
  activity = ku + kv;
  return {uint16_t(code[0] + m), uint16_t(code[1] + m)};
}

// One color in levels (2^color_bits per channel), predicted by `pred` (levels); `actual` is the truth's 8-bit color
// (encoder; null when decoding). Green first, red and blue after green's residual, alpha on its own. Returns the
// decoded levels; `activity` gets the residuals' classes.
template <class Io>
Rgba8 codeColorLevels(Io& io, AttributeModels& models, const AttributeLayout& layout, const int (&pred)[4],
                      const Rgba8* actual, int bin, int& activity) {
  const int channels = layout.color_channels, cb = layout.color_bits, levels = 1 << cb;
  const auto cm = [&](int channel, int green_class) -> SymbolModel& {
    return models.color[(bin * 4 + channel) * 4 + std::min(green_class, 3)];
  };
  auto res = [&](int c) { return actual ? wrapCentered(int(colorLevel((*actual)[c], cb)) - pred[c], levels) : 0; };
  int kg = 0, kr = 0, kb = 0, ka = 0;
  const int rg = codeResidual(io, cm(1, 0), models.color_sign[1], models.color_top[1], res(1), kg);
  const int rr =
      codeResidual(io, cm(0, kg), models.color_sign[0], models.color_top[0], wrapCentered(res(0) - rg, levels), kr);
  const int rb =
      codeResidual(io, cm(2, kg), models.color_sign[2], models.color_top[2], wrapCentered(res(2) - rg, levels), kb);
  Rgba8 lv{0, 0, 0, 0};
  const auto wrap = [&](int x) { return u8(((x % levels) + levels) % levels); };
  lv[1] = wrap(pred[1] + rg);
  lv[0] = wrap(pred[0] + rg + rr);
  lv[2] = wrap(pred[2] + rg + rb);
  if (channels == 4) {
    const int ra = codeResidual(io, cm(3, 0), models.color_sign[3], models.color_top[3], res(3), ka);
    lv[3] = wrap(pred[3] + ra);
  }
  activity = kg + kr + kb + ka;
  return lv;
}

// The 8-bit color of levels `lv` (channels beyond the layout's: 255).
inline Rgba8 colorOfLevels(const Rgba8& lv, const AttributeLayout& layout) {
  Rgba8 out{0, 0, 0, 255};
  for (int c = 0; c < layout.color_channels; ++c) out[c] = colorOfLevel(lv[c], layout.color_bits);
  return out;
}

// Scalar channels, lossless at their type. A value is coded as its ordered integer: integers as they are (signed
// ones sign-extended), floats as sign and magnitude of their bit pattern (-1 - magnitude when negative), so that
// close values are close integers and every bit pattern (NaNs, -0) comes back. The residual from the prediction,
// modulo 2^(8 x bytes), is coded as a class (its bit length; adaptive, context: the decoded neighbours' mean class),
// a top bit below the leading one, raw bits and a sign.
inline int scalarBits(ScalarType t) { return 8 * scalarTypeBytes(t); }

inline int64_t scalarOrdered(ScalarType t, const uint32_t* w) {
  switch (t) {
    case ScalarType::kInt8: return int8_t(w[0]);
    case ScalarType::kInt16: return int16_t(w[0]);
    case ScalarType::kInt32: return int32_t(w[0]);
    case ScalarType::kFloat32: return (w[0] >> 31) ? -1 - int64_t(w[0] & 0x7FFFFFFFu) : int64_t(w[0]);
    case ScalarType::kFloat64: {
      const uint64_t b = uint64_t(w[0]) | (uint64_t(w[1]) << 32);
      return (b >> 63) ? -1 - int64_t(b & 0x7FFFFFFFFFFFFFFFull) : int64_t(b);
    }
    default: return int64_t(w[0]);  // unsigned
  }
}

inline void scalarFromOrdered(ScalarType t, int64_t x, uint32_t* w) {
  switch (t) {
    case ScalarType::kFloat32: w[0] = x < 0 ? 0x80000000u | uint32_t(-1 - x) : uint32_t(x); break;
    case ScalarType::kFloat64: {
      const uint64_t b = x < 0 ? (uint64_t{1} << 63) | uint64_t(-1 - x) : uint64_t(x);
      w[0] = uint32_t(b), w[1] = uint32_t(b >> 32);
      break;
    }
    default: w[0] = uint32_t(uint64_t(x) & ((uint64_t{1} << scalarBits(t)) - 1)); break;
  }
}

// What a channel codes: a quantized channel's level (ScalarChannel::bits; quantize.h's scalarLevel), wrapped as an
// int32, else the value's ordered integer at its type.
inline ScalarType codedType(const ScalarChannel& c) { return c.bits ? ScalarType::kInt32 : c.type; }
inline int64_t channelOrdered(const ScalarChannel& c, const uint32_t* w) {
  return c.bits ? scalarLevel(c, w) : scalarOrdered(c.type, w);
}
inline void channelFromOrdered(const ScalarChannel& c, int64_t x, uint32_t* w) {
  if (c.bits) scalarOfLevel(c, x, w);
  else scalarFromOrdered(c.type, x, w);
}

// Texture coordinates (levels of a quantized pair) of vertex v predicted from a triangle (v, a, b), in its winding
// order, whose a and b are decoded: v's position projected onto the line a-b gives its share t along the edge and
// its height over it, which the prediction keeps in texture space: ta + t (tb - ta) + height x the edge turned a
// quarter, to the left for `orientation` +1 (the chart keeps the triangles' winding), to the right for -1 (it
// mirrors them). False when a and b share a position. (Draco's texture coordinate predictor, with the orientation
// taken from decoded triangles instead of coded; in attributes.cpp, compiled without floating-point contraction.)
bool predictTexcoord(const Vec3u& pv, const Vec3u& pa, const Vec3u& pb, const std::array<int64_t, 2>& ta,
                     const std::array<int64_t, 2>& tb, int orientation, std::array<double, 2>& out);
// The same from a decoded triangle (a, b, c): v's position in the affine frame of a, b, c (projected onto their
// plane), carried to texture space by the affine map that takes a, b, c to their coordinates. Exact wherever the
// texture map is affine over the two triangles (it reduces to the parallelogram rule when v, a, b, c form one);
// it needs no orientation. False when a, b, c are (nearly) collinear.
bool predictTexcoordAffine(const Vec3u& pv, const Vec3u& pa, const Vec3u& pb, const Vec3u& pc,
                           const std::array<int64_t, 2>& ta, const std::array<int64_t, 2>& tb,
                           const std::array<int64_t, 2>& tc, std::array<double, 2>& out);

// x wrapped into the type's range of ordered integers: [0, 2^b) for unsigned types, [-2^(b-1), 2^(b-1)) otherwise.
inline int64_t wrapOrdered(ScalarType t, int64_t x) {
  const int b = scalarBits(t);
  if (b == 64) return x;
  const uint64_t mask = (uint64_t{1} << b) - 1, u = uint64_t(x) & mask;
  const bool is_unsigned = t == ScalarType::kUint8 || t == ScalarType::kUint16 || t == ScalarType::kUint32;
  if (is_unsigned) return int64_t(u);
  return (u >> (b - 1)) ? int64_t(u) - int64_t(mask) - 1 : int64_t(u);
}

// One value of channel `c` predicted by the ordered integer `pred`; `actual` its ordered integer (encoder). Returns
// the decoded ordered integer; `cls` gets the residual's class.
template <class Io>
int64_t codeScalar(Io& io, AttributeModels::Scalar& m, ScalarType t, int64_t pred, int64_t actual, int bin, int& cls) {
  const int b = scalarBits(t);
  // The residual modulo 2^b, centred: in [-2^(b-1), 2^(b-1)).
  uint64_t r = uint64_t(actual) - uint64_t(pred);
  if (b < 64) {
    r &= (uint64_t{1} << b) - 1;
    if (r >> (b - 1)) r |= ~((uint64_t{1} << b) - 1);
  }
  const int64_t rs = int64_t(r);
  const uint64_t mag_in = rs < 0 ? uint64_t(0) - uint64_t(rs) : uint64_t(rs);
  const int k = int(io.sym(m.cls[bin], u32(mag_in == 0 ? 0 : 64 - __builtin_clzll(mag_in))));
  cls = k;
  if (k == 0) return pred;
  uint64_t mag = uint64_t{1} << (k - 1);
  if (k >= 2) mag |= uint64_t(io.bit(m.top[k], int((mag_in >> (k - 2)) & 1))) << (k - 2);
  for (int rest = k - 2; rest > 0;) {  // raw bits below the top one, 32 at a time, high first
    const int n = std::min(rest, 32);
    rest -= n;
    mag |= uint64_t(io.bits(u32((mag_in >> rest) & ((uint64_t{1} << n) - 1)), n)) << rest;
  }
  const bool negative = io.bit(m.sign, rs < 0);
  return wrapOrdered(t, int64_t(uint64_t(pred) + (negative ? uint64_t(0) - mag : mag)));
}

// The scalar channels of the vertices v in [first, n) that are not known(v), in vertex order, each channel on its
// own: predicted by the rounded mean of the decoded neighbours' values (as codePredictedRange's colors), else the
// previous vertex's, else 0. A quantized texture coordinate pair (both channels at the same bits) with the
// positions `pos` is coded together, vertex by vertex, each of v's triangles (v, a, b) whose a and b are decoded
// giving a prediction: predictTexcoordAffine from the first decoded triangle across a-b, else predictTexcoord,
// oriented by the sign of the decoded triangles' texture-space areas at a and b (else of all decoded triangles so
// far, else +1). The mean of the affine predictions, else of the others; the neighbours' mean when no triangle
// gives one. Measured (bench/RESULTS.md, "Quantized texture coordinates"): the affine rule is the one that
// counts; the other alone was worse than the neighbours' mean on a UV sphere. `truth` (encoder): values by
// vertex; `values` holds the known vertices' and gets the coded ones' (stride words per vertex).
inline constexpr size_t kAcross = 16;

template <class Io, class FacesOf, class Known>
void codeScalarRange(Io& io, const AttributeLayout& layout, AttributeModels& models, u32 first, u32 n,
                     const std::vector<Triangle>& tris, const FacesOf& faces_of, const Known& known,
                     const ScalarValues* truth, ScalarValues& values, const std::vector<Vec3u>* pos = nullptr) {
  const auto decoded = [&](u32 w, u32 v) { return w < v || known(w); };
  const size_t stride = size_t(layout.scalarStride());
  values.resize(size_t(n) * stride);
  std::vector<u8> activity(n, 0);
  std::optional<TexcoordChannels> tc = findTexcoords(layout.scalars);
  if (tc && (!pos || !layout.scalars[tc->u].bits || layout.scalars[tc->u].bits != layout.scalars[tc->v].bits))
    tc.reset();
  const auto rounded_mean = [](i128 sum, u32 count) {  // half away from zero, in i128: 64-bit values do not overflow
    const i128 c = count;
    return int64_t(sum >= 0 ? (sum + c / 2) / c : -((-sum + c / 2) / c));
  };
  if (tc) {
    const ScalarChannel &cu = layout.scalars[tc->u], &cv = layout.scalars[tc->v];
    const auto uv = [&](const ScalarValues& vals, u32 v) {
      return std::array<int64_t, 2>{channelOrdered(cu, vals.data() + v * stride + tc->u_word),
                                    channelOrdered(cv, vals.data() + v * stride + tc->v_word)};
    };
    // The decoded vertices' levels (those of vertices before `first` and known ones now, the others as coded).
    std::vector<std::array<int64_t, 2>> level(n);
    for (u32 w = 0; w < n; ++w)
      if (w < first || known(w)) level[w] = uv(values, w);
    // Texture-space orientation votes: per vertex, the sum of the signs of its decoded triangles' areas.
    std::vector<int32_t> votes(n, 0);
    int64_t all_votes = 0;
    const auto vote = [&](u32 v) {
      for (u32 f : faces_of(v)) {
        const Triangle& t = tris[f];
        bool complete = true;
        for (u32 w : t) complete &= w == v || decoded(w, v);
        if (!complete) continue;
        const auto &p0 = level[t[0]], &p1 = level[t[1]], &p2 = level[t[2]];
        const i128 area = i128(p1[0] - p0[0]) * (p2[1] - p0[1]) - i128(p1[1] - p0[1]) * (p2[0] - p0[0]);
        const int s = area > 0 ? 1 : area < 0 ? -1 : 0;
        if (s == 0) continue;
        all_votes += s;
        for (u32 w : t) votes[w] = std::clamp(votes[w] + s, -(1 << 20), 1 << 20);
      }
    };
    std::vector<u8> activity_v(n, 0);
    for (u32 v = first; v < n; ++v) {
      if (known(v)) continue;
      double psum[2] = {0, 0}, asum[2] = {0, 0};
      u32 predictions = 0, affine_predictions = 0;
      i128 nsum[2] = {0, 0};
      u32 count = 0, active_u = 0, active_v = 0;
      for (u32 f : faces_of(v)) {
        const Triangle& t = tris[f];
        const int k = t[0] == v ? 0 : t[1] == v ? 1 : 2;
        const u32 a = t[(k + 1) % 3], b = t[(k + 2) % 3];
        for (u32 w : {a, b})
          if (w != v && decoded(w, v)) {
            const auto& q = level[w];
            nsum[0] += q[0], nsum[1] += q[1], active_u += activity[w], active_v += activity_v[w], ++count;
          }
        if (a == v || b == v || !decoded(a, v) || !decoded(b, v)) continue;
        // The decoded triangle across a-b, if any: the affine prediction. Sought among the first kAcross entries
        // of the shorter of a's and b's triangle lists (a's on a tie; both ascend by triangle), so that a hub vertex
        // (a fan's centre) costs no more than any other.
        bool affine = false;
        const auto fa = faces_of(a), fb = faces_of(b);
        const auto across = fa.size() <= fb.size() ? fa : fb;
        for (u32 g : across.first(std::min<size_t>(across.size(), kAcross))) {
          const Triangle& o = tris[g];
          if (g == f || (o[0] != a && o[1] != a && o[2] != a) || (o[0] != b && o[1] != b && o[2] != b)) continue;
          const u32 c = o[0] != a && o[0] != b ? o[0] : o[1] != a && o[1] != b ? o[1] : o[2];
          if (c == v || c == a || c == b || !decoded(c, v)) continue;
          std::array<double, 2> p;
          if (predictTexcoordAffine((*pos)[v], (*pos)[a], (*pos)[b], (*pos)[c], level[a], level[b], level[c], p)) {
            asum[0] += p[0], asum[1] += p[1], ++affine_predictions;
            affine = true;
            break;
          }
        }
        if (affine) continue;
        const int64_t local = int64_t(votes[a]) + votes[b];
        const int orientation = local != 0 ? (local > 0 ? 1 : -1) : all_votes < 0 ? -1 : 1;
        std::array<double, 2> p;
        if (predictTexcoord((*pos)[v], (*pos)[a], (*pos)[b], level[a], level[b], orientation, p))
          psum[0] += p[0], psum[1] += p[1], ++predictions;
      }
      std::array<int64_t, 2> pred{0, 0};
      if (affine_predictions) psum[0] = asum[0], psum[1] = asum[1], predictions = affine_predictions;
      if (predictions) {
        for (int c = 0; c < 2; ++c)
          pred[c] = int64_t(std::clamp(std::round(psum[c] / predictions), -double(kMaxScalarLevel),
                                       double(kMaxScalarLevel)));
      } else if (count) {
        pred = {rounded_mean(nsum[0], count), rounded_mean(nsum[1], count)};
      } else if (v > 0) {
        pred = level[v - 1];
      }
      const std::array<int64_t, 2> actual = truth ? uv(*truth, v) : std::array<int64_t, 2>{0, 0};
      int cls_u = 0, cls_v = 0;
      const int64_t x = codeScalar(io, models.scalar[tc->u], ScalarType::kInt32, pred[0], actual[0],
                                   activityBin(active_u, count), cls_u);
      const int64_t y = codeScalar(io, models.scalar[tc->v], ScalarType::kInt32, pred[1], actual[1],
                                   activityBin(active_v, count), cls_v);
      channelFromOrdered(cu, x, values.data() + v * stride + tc->u_word);
      channelFromOrdered(cv, y, values.data() + v * stride + tc->v_word);
      level[v] = uv(values, v);  // (the value's level: the coded one, except where a hostile level wrapped)
      activity[v] = u8(cls_u), activity_v[v] = u8(cls_v);
      vote(v);
    }
  }
  size_t offset = 0;
  for (size_t ch = 0; ch < layout.scalars.size(); ++ch) {
    const ScalarChannel& c = layout.scalars[ch];
    const size_t words = size_t(scalarTypeWords(c.type));
    if (tc && (ch == tc->u || ch == tc->v)) {
      offset += words;
      continue;
    }
    AttributeModels::Scalar& m = models.scalar[ch];
    const auto at = [&](const ScalarValues& vals, u32 v) {
      return channelOrdered(c, vals.data() + v * stride + offset);
    };
    std::fill(activity.begin(), activity.end(), u8(0));
    for (u32 v = first; v < n; ++v) {
      if (known(v)) continue;
      i128 sum = 0;
      u32 count = 0, active = 0;
      for (u32 f : faces_of(v))
        for (u32 w : tris[f])
          if (w != v && decoded(w, v)) sum += at(values, w), active += activity[w], ++count;
      int64_t pred = 0;
      if (count) pred = rounded_mean(sum, count);
      else if (v > 0) pred = at(values, v - 1);
      int cls = 0;
      const int64_t x =
          codeScalar(io, m, codedType(c), pred, truth ? at(*truth, v) : 0, activityBin(active, count), cls);
      channelFromOrdered(c, x, values.data() + v * stride + offset);
      activity[v] = u8(cls);
    }
    offset += words;
  }
}

// Payload versions of the attribute coding: raw before kPredictedAttributes, predicted from it on; from
// kCoarseAttributes (kdtree and octree) coded through the levels too (CoarseAttributes below).
constexpr uint16_t kPredictedAttributes = 2;
constexpr uint16_t kCoarseAttributes = 3;

// The octahedral code of the direction of `s` (not zero), or of -s: a bit (`flip`'s model) says which is nearer
// `actual`, the truth's code (encoder; compared in integers, so that every machine writes the same bytes).
// `flipped` gets the bit.
template <class Io>
std::array<int, 2> flippedPrediction(Io& io, BitModel& flip, const Sum3& s, int bits, std::array<int, 2> actual,
                                     bool encoding, int& flipped) {
  const int m = (1 << (bits - 1)) - 1;
  const std::array<int, 2> pred = octahedralOfSum(s, bits);
  int bit = 0;
  if (encoding) {
    const auto a = octahedralVector(actual, m), p = octahedralVector(pred, m);
    bit = a[0] * p[0] + a[1] * p[1] + a[2] * p[2] < 0;
  }
  flipped = io.bit(flip, bit);
  return flipped ? octahedralOfSum(Sum3{-s[0], -s[1], -s[2]}, bits) : pred;
}

// The predicted coding of the vertices v in [first, n) that are not known(v), in vertex order. A vertex w's
// attributes count as decoded when v's are coded if w < v or known(w) (its activity: 0 when it was not coded here). faces_of(v): v's triangles (indices into
// `tris`, a triangle once per corner naming v); geometric(v): v's angle-weighted normal sum. `truth` (encoder):
// attributes by vertex; `normals` and `colors` hold the known vertices' and get the coded ones' (n of each).
template <class Io, class FacesOf, class Geometric, class Known>
void codePredictedRange(Io& io, const AttributeLayout& layout, u32 first, u32 n, const std::vector<Triangle>& tris,
                        const FacesOf& faces_of, const Geometric& geometric, const Known& known, const Points* truth,
                        std::vector<OctNormal>& normals, std::vector<Rgba8>& colors, ScalarValues* scalars = nullptr,
                        const std::vector<Vec3u>* pos = nullptr) {
  const auto decoded = [&](u32 w, u32 v) { return w < v || known(w); };
  AttributeModels models(layout);
  if (layout.hasScalars() && scalars)
    codeScalarRange(io, layout, models, first, n, tris, faces_of, known, truth ? &truth->scalars : nullptr, *scalars,
                    pos);
  std::vector<u8> activity(n, 0);  // per vertex: its residuals' classes (the context of its later neighbours)
  if (layout.hasNormals()) {
    const int bits = layout.normal_bits, m = (1 << (bits - 1)) - 1;
    normals.resize(n);
    int last_flip = 0;
    for (u32 v = first; v < n; ++v) {
      if (known(v)) continue;
      const Sum3 s = scaledSum(geometric(v));
      std::array<int, 2> pred{0, 0};
      const std::array<int, 2> actual =
          truth ? std::array<int, 2>{int(truth->normals[v][0]) - m, int(truth->normals[v][1]) - m}
                : std::array<int, 2>{0, 0};
      if (s[0] != 0 || s[1] != 0 || s[2] != 0) {
        pred = flippedPrediction(io, models.flip[last_flip], s, bits, actual, truth != nullptr, last_flip);
      } else if (v > 0) {
        pred = {int(normals[v - 1][0]) - m, int(normals[v - 1][1]) - m};
      }
      // The mean class of the vertex's decoded neighbours, as a context bin.
      u32 sum = 0, count = 0;
      for (u32 t : faces_of(v))
        for (u32 w : tris[t])
          if (w != v && decoded(w, v)) sum += activity[w], ++count;
      int act = 0;
      normals[v] = codeNormal(io, models, bits, pred, actual, truth != nullptr, activityBin(sum, count), act);
      activity[v] = u8(act);
    }
  }
  if (layout.hasColors()) {
    // In levels (2^color_bits of them; at 8 bits the values themselves).
    const int channels = layout.color_channels, cb = layout.color_bits, levels = 1 << cb;
    colors.resize(n, Rgba8{0, 0, 0, 255});
    std::vector<Rgba8> level(n, Rgba8{0, 0, 0, 0});
    for (u32 v = 0; v < n; ++v)
      if (v < first || known(v))
        for (int c = 0; c < channels; ++c) level[v][c] = u8(colorLevel(colors[v][c], cb));
    std::fill(activity.begin(), activity.end(), u8(0));
    for (u32 v = first; v < n; ++v) {
      if (known(v)) continue;
      // One pass over the decoded neighbours: their levels (the prediction) and activity (the context).
      u32 sum[4] = {0, 0, 0, 0}, count = 0, active = 0;
      for (u32 t : faces_of(v))
        for (u32 w : tris[t])
          if (w != v && decoded(w, v)) {
            for (int c = 0; c < channels; ++c) sum[c] += level[w][c];
            active += activity[w];
            ++count;
          }
      int pred[4];
      for (int c = 0; c < 4; ++c)
        pred[c] = count    ? int((sum[c] + count / 2) / count)
                  : v > 0  ? level[v - 1][c]
                  : c == 3 ? levels - 1
                           : levels / 2;
      int act = 0;
      level[v] = codeColorLevels(io, models, layout, pred, truth ? &truth->colors[v] : nullptr,
                                 activityBin(active, count), act);
      colors[v] = colorOfLevels(level[v], layout);
      activity[v] = u8(std::min(act, 255));
    }
  }
}

// Normals and colors of the n vertices at positions `pos` with triangles `tris`; `truth`
// (encoder) holds them in the vertices' order. `known` (version 3): vertices whose attributes are already in
// `normals` and `colors` (coded at a coarse level); they are not coded again and count as decoded neighbours
// wherever they are in the order.
template <class Io>
void codePredictedAttributes(Io& io, const AttributeLayout& layout, const std::vector<Vec3u>& pos,
                             const std::vector<Triangle>& tris, const Points* truth, std::vector<OctNormal>& normals,
                             std::vector<Rgba8>& colors, ScalarValues& scalars,
                             const std::vector<u8>* known = nullptr) {
  if (!layout.hasNormals() && !layout.hasColors() && !layout.hasScalars()) return;
  const u32 n = u32(pos.size());
  const VertexFaces vf(n, tris);
  std::vector<std::array<double, 3>> geometric;
  if (layout.hasNormals()) geometric = angleWeightedNormals(pos, tris);
  codePredictedRange(
      io, layout, 0, n, tris, [&](u32 v) { return vf.of(v); }, [&](u32 v) { return geometric[v]; },
      [&](u32 v) { return known && (*known)[v] != 0; }, truth, normals, colors, &scalars, &pos);
}

// Version 3 of kdtree and octree: coarse levels show the scan's own attributes. Every vertex of a coarse level
// stands for the points it will split into and shows the attributes of one of them, its representative: the point
// it keeps through all its splits (kdtree: its cell's first point; octree: its range's first point), so a vertex's
// attributes never change once it shows its own. While a level has at most coarseLimit(n) vertices, the end of its
// segment codes the attributes of the vertices born in it, each predicted from its decoded neighbours' at the level
// (else its parent's; the context: how coarse the level is); a vertex born later shows its parent's
// representative's until the last level, whose segment codes every point not coded yet as version 2 does, with the
// coded ones as known neighbours. Each point's attributes are coded once, so coarse levels cost only the weaker
// prediction of the few coded early (measured in bench/RESULTS.md).
// The paper (attributes-selective-refinement §3.4) merges the attributes of contracted vertices into new values;
// copying one of them keeps every level's attributes the scan's own and codes no value twice.
inline u32 coarseLimit(u32 n) { return std::max<u32>(64, n / 16); }

class CoarseAttributes {
 public:
  static constexpr u32 kNone = UINT32_MAX;
  CoarseAttributes(const AttributeLayout& layout, uint16_t version, u32 n)
      : layout_(layout),
        models_(layout),
        n_(n),
        active_(version >= kCoarseAttributes && (layout.hasNormals() || layout.hasColors() || layout.hasScalars())) {
    if (!active_) return;
    shown_.assign(n, kNone);
    coded_.assign(n, 0);
  }
  bool active() const { return active_; }
  // The point whose attributes vertex v shows (kNone: none yet).
  u32 shown(u32 v) const { return active_ ? shown_[v] : kNone; }
  // Vertex v appears at a split of `parent` (kNone: v is the root).
  void birth(u32 v, u32 parent) {
    if (active_) born_.push_back({v, parent});
  }
  // The end of a coarse level's segment, which leaves `vertices` vertices of cell size 2^`coarseness` grid cells.
  // `truth` (encoder): attributes by vertex. `normals` and `colors` are by vertex (n of them).
  template <class Io, class Neighbours>
  void endLevel(Io& io, u32 vertices, int coarseness, const Points* truth, std::vector<OctNormal>& normals,
                std::vector<Rgba8>& colors, ScalarValues& scalars, const Neighbours& neighbours) {
    if (!active_) return;
    if (vertices > coarseLimit(n_)) {
      for (const auto& [v, p] : born_) shown_[v] = p == kNone ? kNone : shown_[p];
      born_.clear();
      return;
    }
    const int bin = std::clamp(coarseness, 0, AttributeModels::kActivity - 1);
    const int nb = layout_.normal_bits, m = layout_.hasNormals() ? (1 << (nb - 1)) - 1 : 0;
    const int levels = 1 << layout_.color_bits;
    if (layout_.hasNormals()) normals.resize(n_);
    if (layout_.hasColors()) colors.resize(n_, Rgba8{0, 0, 0, 255});
    const size_t stride = size_t(layout_.scalarStride());
    scalars.resize(size_t(n_) * stride);
    for (const auto& [v, p] : born_) {
      const u32 from = p == kNone ? kNone : shown_[p];
      // The neighbours at this level whose attributes are decoded (not those born later in this segment).
      Sum3 sum{0, 0, 0};
      u32 csum[4] = {0, 0, 0, 0}, count = 0;
      for (u32 w : neighbours(v)) {
        const u32 r = shown_[w];
        if (r == kNone) continue;
        ++count;
        if (layout_.hasNormals()) {
          const auto d = octahedralVector({int(normals[r][0]) - m, int(normals[r][1]) - m}, m);
          for (int a = 0; a < 3; ++a) sum[a] += d[a];
        }
        if (layout_.hasColors())
          for (int c = 0; c < 4; ++c) csum[c] += colorLevel(colors[r][c], layout_.color_bits);
      }
      int act = 0;
      if (layout_.hasNormals()) {
        std::array<int, 2> pred = from == kNone
                                      ? std::array<int, 2>{0, 0}
                                      : std::array<int, 2>{int(normals[from][0]) - m, int(normals[from][1]) - m};
        if (sum[0] != 0 || sum[1] != 0 || sum[2] != 0) pred = octahedralOfSum(sum, nb);
        const std::array<int, 2> actual =
            truth ? std::array<int, 2>{int(truth->normals[v][0]) - m, int(truth->normals[v][1]) - m}
                  : std::array<int, 2>{0, 0};
        normals[v] = codeNormal(io, models_, nb, pred, actual, truth != nullptr, bin, act);
      }
      if (layout_.hasColors()) {
        int pred[4];
        for (int c = 0; c < 4; ++c)
          pred[c] = count > 0       ? int((csum[c] + count / 2) / count)
                    : from != kNone ? int(colorLevel(colors[from][c], layout_.color_bits))
                    : c == 3        ? levels - 1
                                    : levels / 2;
        colors[v] =
            colorOfLevels(codeColorLevels(io, models_, layout_, pred, truth ? &truth->colors[v] : nullptr, bin, act),
                          layout_);
      }
      // Scalars: the rounded mean of the decoded neighbours' representatives', else the parent's representative's.
      size_t offset = 0;
      for (size_t ch = 0; ch < layout_.scalars.size(); ++ch) {
        const ScalarChannel& c = layout_.scalars[ch];
        i128 sum = 0;
        u32 count_s = 0;
        for (u32 w : neighbours(v))
          if (const u32 r = shown_[w]; r != kNone)
            sum += channelOrdered(c, scalars.data() + r * stride + offset), ++count_s;
        int64_t pred = from != kNone ? channelOrdered(c, scalars.data() + from * stride + offset) : 0;
        if (count_s) {
          const i128 c = count_s;
          pred = int64_t(sum >= 0 ? (sum + c / 2) / c : -((-sum + c / 2) / c));
        }
        int cls = 0;
        const int64_t x = codeScalar(io, models_.scalar[ch], codedType(c), pred,
                                     truth ? channelOrdered(c, truth->scalars.data() + v * stride + offset) : 0, bin,
                                     cls);
        channelFromOrdered(c, x, scalars.data() + v * stride + offset);
        offset += size_t(scalarTypeWords(c.type));
      }
      shown_[v] = v;
      coded_[v] = 1;
    }
    born_.clear();
  }
  // Whether every vertex id(i) of a coarse level (of `count`) shows a representative (not at the root level).
  template <class Id>
  bool showable(u32 count, const Id& id) const {
    if (!active_) return false;
    for (u32 i = 0; i < count; ++i)
      if (shown_[id(i)] == kNone) return false;
    return true;
  }
  // A coarse level's attributes: its vertex i (of `count`) is vertex id(i) and shows its representative's, from
  // `normals` and `colors` (by vertex), appended to `m`. False, and nothing appended, unless showable: the caller
  // derives them.
  template <class Id>
  bool show(u32 count, const Id& id, const std::vector<OctNormal>& normals, const std::vector<Rgba8>& colors,
            const ScalarValues& scalars, QuantizedMesh& m) const {
    if (!showable(count, id)) return false;
    const size_t stride = size_t(layout_.scalarStride());
    for (u32 i = 0; i < count; ++i) {
      const u32 r = shown_[id(i)];
      if (layout_.hasNormals()) m.normals.push_back(normals[r]);
      if (layout_.hasColors()) m.colors.push_back(colors[r]);
      m.scalars.insert(m.scalars.end(), scalars.begin() + r * stride, scalars.begin() + (r + 1) * stride);
    }
    return true;
  }
  // Per point: coded at a coarse level (the `known` of codePredictedAttributes).
  const std::vector<u8>* coded() const { return active_ ? &coded_ : nullptr; }

 private:
  AttributeLayout layout_;
  AttributeModels models_;
  u32 n_;
  bool active_;
  std::vector<u32> shown_;
  std::vector<u8> coded_;
  std::vector<std::array<u32, 2>> born_;
};

// The attribute coding of a payload version (from kCoarseAttributes without the points in `known`).
template <class Io>
void codeTileAttributes(Io& io, uint16_t version, const AttributeLayout& layout, const std::vector<Vec3u>& pos,
                        const std::vector<Triangle>& tris, const Points* truth, std::vector<OctNormal>& normals,
                        std::vector<Rgba8>& colors, ScalarValues& scalars, const std::vector<u8>* known = nullptr) {
  if (version >= kPredictedAttributes) {
    codePredictedAttributes(io, layout, pos, tris, truth, normals, colors, scalars, known);
    return;
  }
  codeRawAttributes(io, layout, u32(pos.size()), truth, normals, colors);
  // Version 1 payloads predate scalar channels (this build writes none with them); a hostile one in a container
  // that has them reads them raw, each value at its type's width (so that no value holds bits above it).
  const size_t words = size_t(pos.size()) * size_t(layout.scalarStride());
  scalars.resize(words);
  for (size_t i = 0; i < words;)
    for (const ScalarChannel& c : layout.scalars) {
      const int bits = std::min(32, scalarBits(c.type));
      scalars[i] = io.bits(truth ? truth->scalars[i] : 0, bits), ++i;
      if (c.type == ScalarType::kFloat64) scalars[i] = io.bits(truth ? truth->scalars[i] : 0, 32), ++i;
    }
}

}  // namespace scanpress::hierarchy
