#include "jobs/commands.h"

#include <oneapi/tbb/parallel_for.h>

#include <cmath>

#include "jobs/container_file.h"
#include "jobs/file_io.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "spatial/weld.h"

namespace scanpress {
Result<QuantizedMesh> decodeContainer(const std::string& path, const std::optional<std::vector<uint32_t>>& tiles,
                                      ContainerHeader* header) {
  SP_ASSIGN_OR_RETURN(ContainerFile file, ContainerFile::open(path));
  std::vector<const TileEntry*> chosen;
  if (tiles) {
    for (uint32_t id : *tiles) {
      const TileEntry* e = file.findTile(id);
      if (!e) return makeError(ErrorCode::kInvalidArgument, path + ": no tile with id " + std::to_string(id));
      chosen.push_back(e);
    }
  } else {
    for (const auto& e : file.tiles()) chosen.push_back(&e);
  }
  // Tiles decode independently: in parallel, then welded in index order (deterministic).
  std::vector<QuantizedMesh> decoded(chosen.size());
  std::vector<Status> errors(chosen.size());
  tbb::parallel_for(size_t(0), chosen.size(), [&](size_t i) {
    auto m = file.decodeTile(*chosen[i]);
    if (m.isOk()) decoded[i] = std::move(m).value();
    else errors[i] = m.status();
  });
  for (const Status& e : errors) SP_RETURN_IF_ERROR(e);
  if (header) *header = file.header();
  if (decoded.empty()) return QuantizedMesh();
  return weldTiles(decoded);
}

bool floatPositionsSuffice(const QuantizedMesh& mesh, const Grid& grid) {
  // One axis at a time through a float variable: GCC 12 -O3 vectorized the three-lane form of this check and
  // dropped two of the double->float roundings, so the check passed where float did not suffice.
  const double max_coord = grid.maxCoord();
  for (const auto& q : mesh.positions)
    for (int a = 0; a < 3; ++a) {
      const float f = static_cast<float>(grid.origin[a] + (q[a] + 0.5) * grid.cell);
      const double t = std::floor((static_cast<double>(f) - grid.origin[a]) / grid.cell);
      if ((t < 0.0 ? 0.0 : (t > max_coord ? max_coord : t)) != q[a]) return false;
    }
  return true;
}

Result<DecodeResult> decodeFile(const DecodeSettings& settings) {
  ContainerHeader header;
  SP_ASSIGN_OR_RETURN(QuantizedMesh q, decodeContainer(settings.input, settings.tiles, &header));
  DecodeResult result;
  result.vertices = q.positions.size();
  result.faces = q.triangles.size();
  result.tiles = settings.tiles ? static_cast<uint32_t>(settings.tiles->size()) : header.tile_count;
  result.double_positions = !floatPositionsSuffice(q, header.grid);
  const Mesh mesh = dequantizeMesh(q, header.grid, header.layout);
  SP_RETURN_IF_ERROR(writeMeshFile(settings.output, mesh, WriteOptions{result.double_positions}));
  return result;
}

}  // namespace scanpress
