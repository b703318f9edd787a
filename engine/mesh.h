// Mesh types shared by every layer.
//
// Mesh: what readers produce and writers consume (double positions, optional per-vertex normals, colors and scalar
// channels, triangles). QuantizedMesh: a mesh on the scan's global integer grid, which is what codecs see. Vertex indices
// are 32-bit: a scan or tile has at most 2^32-1 vertices (readers enforce it).
#pragma once

#include <array>
#include <bit>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace scanpress {

using Vec3d = std::array<double, 3>;
using Vec3f = std::array<float, 3>;
using Vec3u = std::array<uint32_t, 3>;
using Rgba8 = std::array<uint8_t, 4>;
using Triangle = std::array<uint32_t, 3>;
using OctNormal = std::array<uint16_t, 2>;

// The type of a per-vertex scalar channel: PLY's scalar types, kept exactly (a scanner's confidence, intensity or
// quality comes back bit for bit).
enum class ScalarType : uint8_t { kInt8 = 1, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };
inline bool validScalarType(uint8_t t) { return t >= 1 && t <= 8; }
inline int scalarTypeBytes(ScalarType t) {
  switch (t) {
    case ScalarType::kInt8:
    case ScalarType::kUint8: return 1;
    case ScalarType::kInt16:
    case ScalarType::kUint16: return 2;
    case ScalarType::kFloat64: return 8;
    default: return 4;
  }
}
// 32-bit words a value takes in ScalarValues: two for float64.
inline int scalarTypeWords(ScalarType t) { return t == ScalarType::kFloat64 ? 2 : 1; }
// PLY's names: char, uchar, short, ushort, int, uint, float, double.
inline const char* scalarTypeName(ScalarType t) {
  static constexpr const char* kNames[] = {"?", "char", "uchar", "short", "ushort", "int", "uint", "float", "double"};
  return kNames[validScalarType(uint8_t(t)) ? uint8_t(t) : 0];
}

// A scalar channel's name: 1 to 255 printable ASCII bytes, no space (a PLY property name).
inline bool validScalarName(const std::string& name) {
  if (name.empty() || name.size() > 255) return false;
  for (char c : name)
    if (c <= ' ' || c > '~') return false;
  return true;
}

// A per-vertex scalar channel: its name (the PLY property's, at most 255 bytes), type and precision.
struct ScalarChannel {
  std::string name;
  ScalarType type = ScalarType::kFloat32;
  // 0: lossless. 1..kMaxScalarBits (float types only): values are multiples of 2^-bits (`--uv-bits`; quantize.h's
  // snapScalar), and codecs code the multiple. Readers make lossless channels; an encode's layout sets the bits.
  uint8_t bits = 0;
  bool operator==(const ScalarChannel&) const = default;
  bool sameValues(const ScalarChannel& o) const { return name == o.name && type == o.type; }  // bits aside
};
inline constexpr int kMaxScalarBits = 24;
inline bool isFloatScalar(ScalarType t) { return t == ScalarType::kFloat32 || t == ScalarType::kFloat64; }

// 32-bit words per vertex of these channels' values (ScalarValues' stride).
inline size_t scalarWords(std::span<const ScalarChannel> channels) {
  size_t w = 0;
  for (const ScalarChannel& c : channels) w += size_t(scalarTypeWords(c.type));
  return w;
}

// The values of a mesh's scalar channels, vertex after vertex: each value's bit pattern, zero-extended to 32 bits
// (float64: low word, then high word). `stride` words per vertex (the channels' scalarTypeWords).
using ScalarValues = std::vector<uint32_t>;

// The value of float channel `c` whose first word is `words[0]`.
inline double floatChannelValue(const ScalarChannel& c, const uint32_t* words) {
  if (c.type == ScalarType::kFloat64) return std::bit_cast<double>(uint64_t(words[0]) | uint64_t(words[1]) << 32);
  return double(std::bit_cast<float>(words[0]));
}

// Texture coordinates (issue 22) are a pair of float channels: indices of the pair, and their first word in a
// vertex's scalar words.
struct TexcoordChannels {
  size_t u = 0, v = 0;
  size_t u_word = 0, v_word = 0;
};

// The first pair of float channels named (u, v), (s, t), (texture_u, texture_v) or (texture_s, texture_t).
inline std::optional<TexcoordChannels> findTexcoords(std::span<const ScalarChannel> channels) {
  static constexpr std::array<std::array<const char*, 2>, 4> kNames = {
      {{"u", "v"}, {"s", "t"}, {"texture_u", "texture_v"}, {"texture_s", "texture_t"}}};
  for (const auto& names : kNames) {
    TexcoordChannels tc;
    bool found_u = false, found_v = false;
    size_t word = 0;
    for (size_t i = 0; i < channels.size(); ++i) {
      const ScalarChannel& c = channels[i];
      if (!found_u && c.name == names[0] && isFloatScalar(c.type)) tc.u = i, tc.u_word = word, found_u = true;
      if (!found_v && c.name == names[1] && isFloatScalar(c.type)) tc.v = i, tc.v_word = word, found_v = true;
      word += size_t(scalarTypeWords(c.type));
    }
    if (found_u && found_v) return tc;
  }
  return std::nullopt;
}

// Lossless normals (`encode --lossless-normals`): three float32 channels nx, ny, nz, the normals' bits, in a layout
// without octahedral normals; dequantizeMesh gives them back as the mesh's normals.
inline const std::array<ScalarChannel, 3> kLosslessNormalChannels = {
    {{"nx", ScalarType::kFloat32}, {"ny", ScalarType::kFloat32}, {"nz", ScalarType::kFloat32}}};
// The word offset of the lossless normal channels (consecutive, in order, lossless), if the channels have them.
inline std::optional<size_t> losslessNormalsWord(std::span<const ScalarChannel> channels) {
  size_t word = 0;
  for (size_t i = 0; i + 3 <= channels.size(); ++i) {
    if (channels[i] == kLosslessNormalChannels[0] && channels[i + 1] == kLosslessNormalChannels[1] &&
        channels[i + 2] == kLosslessNormalChannels[2])
      return word;
    word += size_t(scalarTypeWords(channels[i].type));
  }
  return std::nullopt;
}

// What is left when the lossless normals at `word` (losslessNormalsWord) are lifted out as the mesh's normals, as
// dequantizeMesh and the streamed decode do: the other channels, and a vertex's other words (appended to `out`).
inline std::vector<ScalarChannel> channelsBesideLosslessNormals(std::span<const ScalarChannel> channels, size_t word) {
  std::vector<ScalarChannel> out;
  for (size_t i = 0, w = 0; i < channels.size(); w += size_t(scalarTypeWords(channels[i++].type)))
    if (w < word || w >= word + 3) out.push_back(channels[i]);
  return out;
}
inline void appendWordsBesideLosslessNormals(const uint32_t* row, size_t stride, size_t word, ScalarValues& out) {
  out.insert(out.end(), row, row + word);
  out.insert(out.end(), row + word + 3, row + stride);
}

// The names a mesh file gives its look, kept through encode and decode (container v3; empty: none): OBJ's `mtllib`
// arguments (space-separated, each library once) and the `usemtl` name that every face shares; PLY's `comment
// TextureFile` name (MeshLab's and Metashape's texture image). OBJ writes the first two, PLY the third.
struct MaterialNames {
  std::string library, material, texture;
  bool empty() const { return library.empty() && material.empty() && texture.empty(); }
  bool operator==(const MaterialNames&) const = default;
};

// Which per-vertex attributes a scan carries, and at what precision they are stored.
struct AttributeLayout {
  uint8_t normal_bits = 0;     // 0: no normals; else octahedral bits per component (4..16)
  uint8_t color_channels = 0;  // 0: no colors; 3: RGB; 4: RGBA (8 bits per channel)
  // Levels per color channel: 2^color_bits (1..8). Below 8 the colors are snapped to those levels (quantize.h's
  // quantizeColor) and codecs that predict them code levels; the mesh keeps their 8-bit values.
  uint8_t color_bits = 8;
  // Scalar channels, coded losslessly at their type (none: the container is version 1).
  std::vector<ScalarChannel> scalars = {};
  bool hasNormals() const { return normal_bits != 0; }
  bool hasColors() const { return color_channels != 0; }
  bool hasScalars() const { return !scalars.empty(); }
  // 32-bit words of scalar values per vertex.
  int scalarStride() const { return int(scalarWords(scalars)); }
  bool operator==(const AttributeLayout&) const = default;
};

struct Mesh {
  std::vector<Vec3d> positions;
  std::vector<Vec3f> normals;  // empty, or one per vertex
  std::vector<Rgba8> colors;   // empty, or one per vertex (alpha 255 when the source has no alpha)
  uint8_t color_channels = 0;  // 3 or 4 when colors are present
  std::vector<ScalarChannel> scalar_channels;
  ScalarValues scalars;  // empty, or stride (scalar_channels' words) per vertex
  std::vector<Triangle> triangles;
};

struct QuantizedMesh {
  std::vector<Vec3u> positions;
  std::vector<OctNormal> normals;  // empty, or one per vertex
  std::vector<Rgba8> colors;       // empty, or one per vertex
  ScalarValues scalars;            // empty, or the layout's scalarStride() words per vertex
  std::vector<Triangle> triangles;
};

}  // namespace scanpress
