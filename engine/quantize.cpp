#include "engine/quantize.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
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

namespace {
// round(value x 2^bits), unclamped (NaN for NaN).
double rawLevel(const ScalarChannel& c, const uint32_t* words) {
  return std::round(std::ldexp(floatChannelValue(c, words), c.bits));
}
bool levelInRange(double level) { return std::fabs(level) <= double(kMaxScalarLevel); }  // false for NaN
}  // namespace

int64_t scalarLevel(const ScalarChannel& c, const uint32_t* words) {
  const double x = rawLevel(c, words);
  if (std::isnan(x)) return 0;
  return int64_t(std::clamp(x, -double(kMaxScalarLevel) - 1, double(kMaxScalarLevel)));
}

void scalarOfLevel(const ScalarChannel& c, int64_t level, uint32_t* words) {
  const double x = std::ldexp(double(level), -int(c.bits));  // exact: |level| < 2^53
  if (c.type == ScalarType::kFloat64) {
    const uint64_t b = std::bit_cast<uint64_t>(x);
    words[0] = uint32_t(b), words[1] = uint32_t(b >> 32);
  } else {
    words[0] = std::bit_cast<uint32_t>(float(x));
  }
}

bool onScalarLevel(const ScalarChannel& c, const uint32_t* words) {
  if (!levelInRange(rawLevel(c, words))) return false;
  const int64_t level = scalarLevel(c, words);
  uint32_t back[2] = {0, 0};
  scalarOfLevel(c, level, back);
  return back[0] == words[0] && (c.type != ScalarType::kFloat64 || back[1] == words[1]);
}

bool snapScalar(const ScalarChannel& c, uint32_t* words) {
  // A float32 level beyond 2^24 rounds to a float whose own level differs (a multiple of a coarser power of two):
  // snap twice, then check that the result is a level's value.
  uint32_t w[2] = {words[0], c.type == ScalarType::kFloat64 ? words[1] : 0};
  for (int pass = 0; pass < 2; ++pass) {
    if (!levelInRange(rawLevel(c, w))) return false;
    scalarOfLevel(c, scalarLevel(c, w), w);
  }
  if (!onScalarLevel(c, w)) return false;
  words[0] = w[0];
  if (c.type == ScalarType::kFloat64) words[1] = w[1];
  return true;
}

Result<std::vector<std::pair<size_t, size_t>>> pickScalarChannels(std::span<const ScalarChannel> have,
                                                                  std::span<const ScalarChannel> wanted) {
  std::vector<std::pair<size_t, size_t>> picks;
  for (const ScalarChannel& want : wanted) {
    size_t offset = 0;
    bool found = false;
    for (const ScalarChannel& c : have) {
      if (c.sameValues(want)) {
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

Status snapScalarRow(std::span<const ScalarChannel> channels, uint32_t* row, uint64_t vertex) {
  for (const ScalarChannel& c : channels) {
    if (c.bits && !snapScalar(c, row)) {
      char value[32] = "?";
      if (isFloatScalar(c.type)) std::snprintf(value, sizeof value, "%.9g", floatChannelValue(c, row));
      return makeError(ErrorCode::kInvalidArgument,
                       "vertex " + std::to_string(vertex) + " (counting texture seams' wedges): " + c.name + " = " +
                           std::string(value) + " cannot be kept at " + std::to_string(int(c.bits)) +
                           " bits (a finite value below 2^" + std::to_string(31 - int(c.bits)) +
                           " in magnitude); encode without --uv-bits to keep it " + "as it is");
    }
    row += scalarTypeWords(c.type);
  }
  return Status::ok();
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
    const size_t row = out.scalars.size();
    for (const auto& [offset, words] : picks)
      for (size_t w = 0; w < words; ++w) out.scalars.push_back(mesh.scalars[i * mesh_stride + offset + w]);
    SP_RETURN_IF_ERROR(snapScalarRow(layout.scalars, out.scalars.data() + row, i));
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
  // Lossless normals: the channels nx, ny, nz become the mesh's normals, bit for bit.
  const size_t stride = scalarWords(layout.scalars);
  if (const auto word = losslessNormalsWord(layout.scalars);
      word && !layout.hasNormals() && mesh.scalars.size() == mesh.positions.size() * stride) {
    const size_t n = mesh.positions.size();
    out.normals.resize(n);
    ScalarValues rest;
    rest.reserve(n * (stride - 3));
    for (size_t v = 0; v < n; ++v) {
      const uint32_t* row = mesh.scalars.data() + v * stride;
      for (int k = 0; k < 3; ++k) out.normals[v][size_t(k)] = std::bit_cast<float>(row[*word + size_t(k)]);
      appendWordsBesideLosslessNormals(row, stride, *word, rest);
    }
    out.scalars = std::move(rest);
    out.scalar_channels = channelsBesideLosslessNormals(layout.scalars, *word);
  }
  return out;
}

}  // namespace scanpress
