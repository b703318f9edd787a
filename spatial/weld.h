// Welding decoded tiles back into one mesh.
//
// All tiles of a container use the scan's one global grid, so a vertex that lies on a border between tiles has
// the same integer coordinates in every tile that holds it. weldTiles concatenates tiles and merges vertices of
// different tiles that share a position (the first tile in the given order keeps its vertex and attributes).
// Vertices that share a position inside one tile are left as the codec returned them: welding must not change
// what a single tile decodes to.
#pragma once

#include <span>

#include "engine/mesh.h"

namespace scanpress {

QuantizedMesh weldTiles(std::span<const QuantizedMesh> tiles);

}  // namespace scanpress
