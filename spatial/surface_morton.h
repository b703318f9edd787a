// The Morton order of a batch of points, for SurfaceIndex::closestMany (std only).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "engine/mesh.h"

namespace scanpress::surface {

// The points in Morton order of their cells, the points not finite last, ties in index order, as one word each:
// the cell's Morton key, then the point's index in the lowest `index_bits` bits; bit 63 set for a point not
// finite. Cells are cubes of size 1 / inv_cell from the finite points' lower corner, larger if the batch spans more
// than the 2^b cells per axis that fit (b = (63 - index_bits) / 3, at most 21). `scratch` is the radix sort's.
void mortonOrder(std::span<const Vec3d> points, double inv_cell, int index_bits, std::vector<uint64_t>& order,
                 std::vector<uint64_t>& scratch);

}  // namespace scanpress::surface
