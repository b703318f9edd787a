#include "spatial/tile_builder.h"

#include <algorithm>
#include <bit>

namespace scanpress {

Status buildTileMesh(uint32_t tile, std::span<const Triangle> tris, const VertexSource& vertices,
                     const AttributeLayout& layout, TileMesh& out, std::vector<Vec3d>* originals) {
  // Local ids in order of first use: an open-addressing hash from global to local id.
  size_t cap = 16;
  while (cap < 3 * tris.size()) cap <<= 1;  // load factor <= 1/2 even if every corner is a distinct vertex
  const int shift = 64 - std::countr_zero(cap);
  std::vector<uint32_t> keys(cap, UINT32_MAX), vals(cap);
  std::vector<uint32_t>& ids = out.local_to_global;
  ids.clear();
  QuantizedMesh& m = out.mesh;
  m.triangles.resize(tris.size());
  std::vector<uint32_t> local_valence;
  for (size_t t = 0; t < tris.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      const uint32_t g = tris[t][k];
      size_t h = static_cast<size_t>((uint64_t(g) * 0x9E3779B97F4A7C15ull) >> shift);
      while (keys[h] != UINT32_MAX && keys[h] != g) h = (h + 1) & (cap - 1);
      if (keys[h] == UINT32_MAX) {
        keys[h] = g;
        vals[h] = static_cast<uint32_t>(ids.size());
        ids.push_back(g);
        local_valence.push_back(0);
      }
      m.triangles[t][k] = vals[h];
      ++local_valence[vals[h]];
    }
  // Read the records in global order, then scatter them to their local slots.
  std::vector<std::pair<uint32_t, uint32_t>> order(ids.size());
  for (uint32_t i = 0; i < ids.size(); ++i) order[i] = {ids[i], i};
  std::sort(order.begin(), order.end());
  std::vector<uint32_t> sorted(ids.size());
  for (size_t i = 0; i < order.size(); ++i) sorted[i] = order[i].first;
  std::vector<VertexRecord> records;
  SP_RETURN_IF_ERROR(vertices.read(sorted, records));
  const size_t stride = size_t(layout.scalarStride());
  ScalarValues rows;
  if (stride) SP_RETURN_IF_ERROR(vertices.readScalars(sorted, stride, rows));
  m.scalars.resize(ids.size() * stride);
  out.tile_id = tile;
  m.positions.resize(ids.size());
  if (layout.hasNormals()) m.normals.resize(ids.size());
  if (layout.hasColors()) m.colors.resize(ids.size());
  out.border.resize(ids.size());
  if (originals) originals->resize(ids.size());
  for (size_t i = 0; i < order.size(); ++i) {
    const uint32_t local = order[i].second;
    const VertexRecord& r = records[i];
    if (originals) (*originals)[local] = {r.original[0], r.original[1], r.original[2]};
    m.positions[local] = r.q;
    if (layout.hasNormals()) m.normals[local] = r.normal;
    if (layout.hasColors()) m.colors[local] = r.color;
    std::copy_n(rows.begin() + ptrdiff_t(i * stride), stride, m.scalars.begin() + ptrdiff_t(local * stride));
    out.border[local] = local_valence[local] < r.valence ? 1 : 0;
  }
  return Status::ok();
}

}  // namespace scanpress
