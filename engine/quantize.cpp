#include "engine/quantize.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "engine/octahedral.h"

namespace scanpress {

double BoundingBox::maxExtent() const {
  if (empty()) return 0.0;
  return std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
}

double BoundingBox::diagonal() const {
  if (empty()) return 0.0;
  const double dx = hi[0] - lo[0], dy = hi[1] - lo[1], dz = hi[2] - lo[2];
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

Vec3u Grid::quantize(const Vec3d& p) const {
  Vec3u q;
  const double max_coord = maxCoord();
  for (int a = 0; a < 3; ++a) {
    const double t = std::floor((p[a] - origin[a]) / cell);
    q[a] = static_cast<uint32_t>(t < 0.0 ? 0.0 : (t > max_coord ? max_coord : t));
  }
  return q;
}

Result<Grid> makeGrid(const BoundingBox& box, int bits) {
  if (bits < kMinGridBits || bits > kMaxGridBits)
    return makeError(ErrorCode::kInvalidArgument, "quantization bits must be in [" + std::to_string(kMinGridBits) +
                                                      ", " + std::to_string(kMaxGridBits) + "], got " +
                                                      std::to_string(bits));
  if (box.empty()) return makeError(ErrorCode::kMalformed, "mesh has no vertices: no bounding box for the grid");
  const double extent = box.maxExtent();
  if (!std::isfinite(extent) || !std::isfinite(box.lo[0]) || !std::isfinite(box.lo[1]) || !std::isfinite(box.lo[2]))
    return makeError(ErrorCode::kUnsupported, "bounding box is not finite");
  Grid grid;
  grid.bits = bits;
  grid.origin = box.lo;
  // A zero extent (all vertices at one point) still needs a positive cell; any tiny one decodes to the point.
  grid.cell = (extent > 0.0 ? extent : 1e-9) / double(uint64_t(1) << bits);
  return grid;
}

BoundingBox boundingBox(const Mesh& mesh) {
  BoundingBox box;
  for (const auto& p : mesh.positions) box.extend(p);
  return box;
}

BoundingBox usedBoundingBox(const Mesh& mesh) {
  if (mesh.triangles.empty()) return boundingBox(mesh);
  BoundingBox box;
  for (const Triangle& t : mesh.triangles)
    for (uint32_t v : t)
      if (v < mesh.positions.size()) box.extend(mesh.positions[v]);
  return box;
}

Result<std::vector<std::pair<size_t, size_t>>> pickScalarChannels(std::span<const ScalarChannel> have,
                                                                  std::span<const ScalarChannel> wanted) {
  std::vector<std::pair<size_t, size_t>> picks;
  for (const ScalarChannel& want : wanted) {
    size_t offset = 0;
    bool found = false;
    for (const ScalarChannel& c : have) {
      if (c == want) {
        picks.push_back({offset, size_t(scalarTypeWords(c.type))});
        found = true;
        break;
      }
      offset += size_t(scalarTypeWords(c.type));
    }
    if (!found)
      return makeError(ErrorCode::kInvalidArgument, "scalar channel '" + want.name + "' (" +
                                                        scalarTypeName(want.type) + ") is not among the mesh's");
  }
  return picks;
}

Result<QuantizedMesh> quantizeMesh(const Mesh& mesh, const Grid& grid, const AttributeLayout& layout,
                                   QuantizeStats* stats) {
  const size_t n = mesh.positions.size();
  if (layout.hasNormals() && mesh.normals.size() != n)
    return makeError(ErrorCode::kInvalidArgument, "layout has normals but the mesh has " +
                                                      std::to_string(mesh.normals.size()) + " for " +
                                                      std::to_string(n) + " vertices");
  if (layout.hasColors() && mesh.colors.size() != n)
    return makeError(ErrorCode::kInvalidArgument, "layout has colors but the mesh has " +
                                                      std::to_string(mesh.colors.size()) + " for " +
                                                      std::to_string(n) + " vertices");
  // The layout's scalar channels, each found in the mesh's by name and type.
  const size_t mesh_stride = scalarWords(mesh.scalar_channels);
  if (mesh.scalars.size() != n * mesh_stride)
    return makeError(ErrorCode::kInvalidArgument, "the mesh's scalar values do not match its vertices");
  SP_ASSIGN_OR_RETURN(const auto picks, pickScalarChannels(mesh.scalar_channels, layout.scalars));
  std::vector<Vec3u> q(n);
  for (size_t i = 0; i < n; ++i) q[i] = grid.quantize(mesh.positions[i]);

  QuantizedMesh out;
  QuantizeStats local;
  std::vector<uint32_t> remap(n, UINT32_MAX);
  out.triangles.reserve(mesh.triangles.size());
  for (const Triangle& t : mesh.triangles) {
    if (t[0] >= n || t[1] >= n || t[2] >= n)
      return makeError(ErrorCode::kInvalidArgument, "triangle index out of range");
    if (q[t[0]] == q[t[1]] || q[t[1]] == q[t[2]] || q[t[0]] == q[t[2]]) {
      ++local.degenerate_triangles;
      continue;
    }
    out.triangles.push_back(t);
    for (uint32_t v : t) remap[v] = 0;
  }
  uint32_t next = 0;
  for (size_t i = 0; i < n; ++i) {
    if (remap[i] == UINT32_MAX) {
      ++local.unreferenced_vertices;
      continue;
    }
    remap[i] = next++;
    out.positions.push_back(q[i]);
    if (layout.hasNormals()) out.normals.push_back(encodeOctahedral(mesh.normals[i], layout.normal_bits));
    if (layout.hasColors()) out.colors.push_back(quantizeColor(mesh.colors[i], layout));
    for (const auto& [offset, words] : picks)
      for (size_t w = 0; w < words; ++w) out.scalars.push_back(mesh.scalars[i * mesh_stride + offset + w]);
  }
  for (Triangle& t : out.triangles)
    for (uint32_t& v : t) v = remap[v];
  if (stats) *stats = local;
  return out;
}

Mesh dequantizeMesh(const QuantizedMesh& mesh, const Grid& grid, const AttributeLayout& layout) {
  Mesh out;
  out.positions.reserve(mesh.positions.size());
  for (const auto& q : mesh.positions) out.positions.push_back(grid.dequantize(q));
  if (layout.hasNormals())
    for (const auto& e : mesh.normals) out.normals.push_back(decodeOctahedral(e, layout.normal_bits));
  if (layout.hasColors()) {
    out.colors = mesh.colors;
    out.color_channels = layout.color_channels;
  }
  out.scalar_channels = layout.scalars;
  out.scalars = mesh.scalars;
  out.triangles = mesh.triangles;
  return out;
}

}  // namespace scanpress
