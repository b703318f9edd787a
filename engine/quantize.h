// The scan's global quantization grid, and quantization of meshes onto it.
//
// One grid per scan, chosen before tiling, so that a vertex shared by two tiles has the same integer coordinates
// in both. Cells are cubic: the largest bounding-box extent divided into 2^bits cells (the convention of Draco's
// -qp, so sizes compare one to one). A coordinate maps to the index of its cell, clamped to [0, 2^bits - 1], and
// decodes to the cell's center; the maximum error per axis is half a cell.
#pragma once

#include "engine/mesh.h"
#include "engine/status.h"

namespace scanpress {

constexpr int kMinGridBits = 8;
constexpr int kMaxGridBits = 24;
constexpr int kDefaultGridBits = 16;
constexpr int kDefaultNormalBits = 12;

struct BoundingBox {
  Vec3d lo{1e300, 1e300, 1e300};
  Vec3d hi{-1e300, -1e300, -1e300};
  bool empty() const { return lo[0] > hi[0]; }
  void extend(const Vec3d& p) {
    for (int a = 0; a < 3; ++a) {
      if (p[a] < lo[a]) lo[a] = p[a];
      if (p[a] > hi[a]) hi[a] = p[a];
    }
  }
  double maxExtent() const;
  double diagonal() const;
};

struct Grid {
  Vec3d origin{0, 0, 0};
  double cell = 1.0;
  int bits = kDefaultGridBits;

  uint32_t maxCoord() const { return (bits >= 32) ? 0xFFFFFFFFu : ((1u << bits) - 1); }
  Vec3u quantize(const Vec3d& p) const;
  Vec3d dequantize(const Vec3u& q) const {
    return {origin[0] + (q[0] + 0.5) * cell, origin[1] + (q[1] + 0.5) * cell, origin[2] + (q[2] + 0.5) * cell};
  }
};

// The grid for a bounding box (must be non-empty and finite) at `bits` in [kMinGridBits, kMaxGridBits].
Result<Grid> makeGrid(const BoundingBox& box, int bits);

BoundingBox boundingBox(const Mesh& mesh);
// The box of the vertices that triangles use (the grid's and the relative error's box: a vertex no triangle uses
// is dropped, and must not stretch either); of all vertices when the mesh has no triangles (a point cloud).
BoundingBox usedBoundingBox(const Mesh& mesh);

struct QuantizeStats {
  uint64_t degenerate_triangles = 0;   // triangles with two corners in one cell, dropped
  uint64_t unreferenced_vertices = 0;  // vertices used by no kept triangle, dropped
};

// A color channel's level on `bits` bits (1..8), and the 8-bit value a level stands for (both rounded; level ->
// value -> level is exact, and at 8 bits both are the identity).
inline uint8_t colorLevel(uint8_t value, int bits) {
  const int top = (1 << bits) - 1;
  return static_cast<uint8_t>((value * top + 127) / 255);
}
inline uint8_t colorOfLevel(int level, int bits) {
  const int top = (1 << bits) - 1;
  return static_cast<uint8_t>((level * 255 + top / 2) / top);
}
// A color snapped to the layout's levels (the channels the layout keeps; the identity at 8 bits).
inline Rgba8 quantizeColor(const Rgba8& c, const AttributeLayout& layout) {
  Rgba8 out = c;
  for (int k = 0; k < layout.color_channels; ++k)
    out[k] = colorOfLevel(colorLevel(c[k], layout.color_bits), layout.color_bits);
  return out;
}

// A quantized float channel (ScalarChannel::bits = b > 0): its values are multiples of 2^-b, and codecs code the
// multiple, the value's level. scalarLevel(c, w) = round(value x 2^b) (half away from zero) of the value at `w`,
// clamped to the int32 range (NaN: 0; only a hostile payload decodes to such values); scalarOfLevel writes the
// value of a level. snapScalar replaces the value at `w` with the nearest level's; false,
// leaving it, when the value is not finite or its level is beyond +-kMaxScalarLevel. Snapped values are exactly
// their level's (scalarOfLevel(c, scalarLevel(c, w)) gives w's bits back), so coding the level is lossless.
inline constexpr int64_t kMaxScalarLevel = (int64_t{1} << 31) - 1;
int64_t scalarLevel(const ScalarChannel& c, const uint32_t* words);
void scalarOfLevel(const ScalarChannel& c, int64_t level, uint32_t* words);
bool snapScalar(const ScalarChannel& c, uint32_t* words);
// Whether the value at `w` is a level's value (what snapScalar leaves).
bool onScalarLevel(const ScalarChannel& c, const uint32_t* words);
// Snaps the quantized channels of one vertex's row of values (`channels`' words); kInvalidArgument naming the
// vertex, channel and value that cannot be snapped.
Status snapScalarRow(std::span<const ScalarChannel> channels, uint32_t* row, uint64_t vertex);

// Quantizes positions onto `grid`, normals to octahedral `layout.normal_bits` bits (if the mesh has normals and
// the layout wants them), colors to the layout's levels (quantizeColor; as they are at 8 bits), the layout's
// quantized scalar channels to their levels (snapScalar; kInvalidArgument naming a value it cannot snap).
// Triangles that quantization makes degenerate and vertices no kept triangle uses are dropped and counted; the
// other vertices keep their order.
// Fails with kInvalidArgument if a triangle indexes past the vertex array or attributes do not match the layout.
// Where each of `wanted`'s channels sits in a row of `have`'s values (found by name and type): (word offset,
// words) per wanted channel; kInvalidArgument naming the first one `have` lacks.
Result<std::vector<std::pair<size_t, size_t>>> pickScalarChannels(std::span<const ScalarChannel> have,
                                                                  std::span<const ScalarChannel> wanted);

Result<QuantizedMesh> quantizeMesh(const Mesh& mesh, const Grid& grid, const AttributeLayout& layout,
                                   QuantizeStats* stats);

// Back to a float mesh: positions at cell centers, normals decoded from octahedral coordinates, or lossless ones
// (kLosslessNormalChannels) lifted out of the scalar channels.
Mesh dequantizeMesh(const QuantizedMesh& mesh, const Grid& grid, const AttributeLayout& layout);

}  // namespace scanpress
