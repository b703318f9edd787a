// Mesh types shared by every layer.
//
// Mesh: what readers produce and writers consume (double positions, optional per-vertex normals and colors,
// triangles). QuantizedMesh: a mesh on the scan's global integer grid, which is what codecs see. Vertex indices
// are 32-bit: a scan or tile has at most 2^32-1 vertices (readers enforce it).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

namespace scanpress {

using Vec3d = std::array<double, 3>;
using Vec3f = std::array<float, 3>;
using Vec3u = std::array<uint32_t, 3>;
using Rgba8 = std::array<uint8_t, 4>;
using Triangle = std::array<uint32_t, 3>;
using OctNormal = std::array<uint16_t, 2>;

// Which per-vertex attributes a scan carries, and at what precision they are stored.
struct AttributeLayout {
  uint8_t normal_bits = 0;     // 0: no normals; else octahedral bits per component (4..16)
  uint8_t color_channels = 0;  // 0: no colors; 3: RGB; 4: RGBA (8 bits per channel)
  // Levels per color channel: 2^color_bits (1..8). Below 8 the colors are snapped to those levels (quantize.h's
  // quantizeColor) and codecs that predict them code levels; the mesh keeps their 8-bit values.
  uint8_t color_bits = 8;
  bool hasNormals() const { return normal_bits != 0; }
  bool hasColors() const { return color_channels != 0; }
  bool operator==(const AttributeLayout&) const = default;
};

struct Mesh {
  std::vector<Vec3d> positions;
  std::vector<Vec3f> normals;  // empty, or one per vertex
  std::vector<Rgba8> colors;   // empty, or one per vertex (alpha 255 when the source has no alpha)
  uint8_t color_channels = 0;  // 3 or 4 when colors are present
  std::vector<Triangle> triangles;
};

struct QuantizedMesh {
  std::vector<Vec3u> positions;
  std::vector<OctNormal> normals;  // empty, or one per vertex
  std::vector<Rgba8> colors;       // empty, or one per vertex
  std::vector<Triangle> triangles;
};

}  // namespace scanpress
