#include "jobs/commands.h"

#include <chrono>
#include <cmath>

#include "jobs/container_file.h"
#include "jobs/file_io.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "spatial/weld.h"

namespace scanpress {
namespace {

class Stopwatch {
 public:
  double lap() {
    const auto now = std::chrono::steady_clock::now();
    const double s = std::chrono::duration<double>(now - last_).count();
    last_ = now;
    return s;
  }

 private:
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

}  // namespace

Result<EncodeResult> encodeFile(const EncodeSettings& settings) {
  const CodecInfo* codec = findCodec(settings.codec);
  if (!codec) return makeError(ErrorCode::kInvalidArgument, "unknown codec '" + settings.codec + "'");
  if (settings.normal_bits < 4 || settings.normal_bits > 16)
    return makeError(ErrorCode::kInvalidArgument, "normal bits must be in [4, 16]");
  EncodeResult result;
  result.codec = codec->name;
  Stopwatch clock;
  SP_ASSIGN_OR_RETURN(Mesh mesh, readMeshFile(settings.input, &result.read));
  result.seconds.read = clock.lap();

  if (settings.keep_normals && !mesh.normals.empty()) result.layout.normal_bits = static_cast<uint8_t>(settings.normal_bits);
  if (settings.keep_colors && !mesh.colors.empty()) result.layout.color_channels = mesh.color_channels;
  auto grid = makeGrid(boundingBox(mesh), settings.bits);
  if (!grid.isOk()) return grid.status().withContext(settings.input);
  result.grid = *grid;
  SP_ASSIGN_OR_RETURN(QuantizedMesh q, quantizeMesh(mesh, result.grid, result.layout, &result.quantize));
  mesh = Mesh();  // free the float mesh before coding
  result.seconds.quantize = clock.lap();

  // One tile for now: tiling comes with the parallel pipeline.
  TileContext ctx{result.grid.bits, result.layout};
  std::vector<uint8_t> payload;
  SP_RETURN_IF_ERROR(codec->encode(ctx, q, payload).withContext(settings.input));
  result.seconds.encode = clock.lap();

  SP_ASSIGN_OR_RETURN(auto file, AtomicFile::create(settings.output));
  ContainerWriter writer(*file, result.grid, result.layout);
  SP_RETURN_IF_ERROR(writer.begin());
  SP_RETURN_IF_ERROR(writer.addTile(0, *codec, q, payload));
  SP_RETURN_IF_ERROR(writer.finish());
  SP_RETURN_IF_ERROR(file->commit());
  result.seconds.write = clock.lap();
  result.vertices = q.positions.size();
  result.faces = q.triangles.size();
  result.bytes = writer.bytesWritten();
  result.tiles = 1;
  return result;
}

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
  std::vector<QuantizedMesh> decoded;
  decoded.reserve(chosen.size());
  for (const TileEntry* e : chosen) {
    SP_ASSIGN_OR_RETURN(QuantizedMesh m, file.decodeTile(*e));
    decoded.push_back(std::move(m));
  }
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
