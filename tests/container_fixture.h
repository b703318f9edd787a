// A small in-memory container for the container tests of the engine and jobs layers: an octahedron with normals
// and colors (4 channels), quantized at 12 bits, `tile_count` copies of it as tiles, coded with `store`.
#pragma once

#include <vector>

#include "engine/container/container.h"
#include "engine/quantize.h"
#include "test_util.h"

namespace scanpress::testing {

struct ContainerFixture {
  Grid grid;
  AttributeLayout layout{12, 4};
  std::vector<QuantizedMesh> tiles;
  std::vector<uint8_t> bytes;
};

inline ContainerFixture makeContainerFixture(int tile_count = 2) {
  ContainerFixture f;
  Mesh m = octahedron(2.0);
  for (size_t i = 0; i < m.positions.size(); ++i) {
    const auto& p = m.positions[i];
    m.normals.push_back({static_cast<float>(p[0] / 2), static_cast<float>(p[1] / 2), static_cast<float>(p[2] / 2)});
    m.colors.push_back({static_cast<uint8_t>(40 * i), 7, 200, 255});
  }
  m.color_channels = 4;
  f.grid = *makeGrid(boundingBox(m), 12);
  auto q = quantizeMesh(m, f.grid, f.layout, nullptr);
  for (int t = 0; t < tile_count; ++t) f.tiles.push_back(*q);
  f.bytes = *encodeContainer(f.grid, f.layout, *findCodec(CodecId::kStore), f.tiles);
  return f;
}

}  // namespace scanpress::testing
