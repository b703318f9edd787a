#include "jobs/commands.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <tuple>

#include "jobs/container_file.h"
#include "jobs/file_io.h"
#include "jobs/mesh_io/gltf_writer.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs/mesh_io/texcoords.h"
#include "jobs/stream_decode.h"
#include "spatial/weld.h"

namespace scanpress {
namespace {

// The tiles whose bounds meet `box` (the bounds are closed: a tile touching the box is chosen).
Result<std::vector<const TileEntry*>> tilesInBox(const ContainerFile& file, const std::string& path,
                                                 const std::array<double, 6>& box) {
  for (int a = 0; a < 3; ++a)
    if (!(box[a] <= box[a + 3]))
      return makeError(ErrorCode::kInvalidArgument, "--box: min must not exceed max on every axis");
  std::vector<const TileEntry*> chosen;
  for (const auto& e : file.tiles()) {
    if (e.vertices == 0) continue;
    const auto b = tileWorldBounds(e, file.header().grid);
    bool meets = true;
    for (int a = 0; a < 3; ++a) meets &= b[a] <= box[a + 3] && box[a] <= b[a + 3];
    if (meets) chosen.push_back(&e);
  }
  if (chosen.empty())
    return makeError(ErrorCode::kInvalidArgument, path + ": no tile meets the box (`info` lists the tiles' bounds)");
  return chosen;
}

// Keeps the triangles wholly inside `box` (a point cloud: the points inside) and the vertices they use.
QuantizedMesh cropToBox(const QuantizedMesh& q, const Grid& grid, const std::array<double, 6>& box) {
  std::vector<uint8_t> inside(q.positions.size());
  for (size_t v = 0; v < q.positions.size(); ++v) {
    inside[v] = insideBox(grid.dequantize(q.positions[v]), box);
  }
  std::vector<uint32_t> remap(q.positions.size(), UINT32_MAX);
  QuantizedMesh out;
  const size_t stride = q.positions.empty() ? 0 : q.scalars.size() / q.positions.size();
  auto keep = [&](uint32_t v) {
    if (remap[v] == UINT32_MAX) {
      remap[v] = static_cast<uint32_t>(out.positions.size());
      out.positions.push_back(q.positions[v]);
      if (!q.normals.empty()) out.normals.push_back(q.normals[v]);
      if (!q.colors.empty()) out.colors.push_back(q.colors[v]);
      out.scalars.insert(out.scalars.end(), q.scalars.begin() + ptrdiff_t(v * stride),
                         q.scalars.begin() + ptrdiff_t((v + 1) * stride));
    }
    return remap[v];
  };
  if (q.triangles.empty()) {
    for (uint32_t v = 0; v < q.positions.size(); ++v)
      if (inside[v]) keep(v);
    return out;
  }
  for (const auto& t : q.triangles)
    if (inside[t[0]] && inside[t[1]] && inside[t[2]]) out.triangles.push_back({keep(t[0]), keep(t[1]), keep(t[2])});
  return out;
}

Result<std::vector<const TileEntry*>> chooseTiles(const ContainerFile& file, const std::string& path,
                                                  const std::optional<std::vector<uint32_t>>& tiles) {
  std::vector<const TileEntry*> chosen;
  if (tiles) {
    // A tile named twice would be decoded twice and welded with itself: refused rather than guessed at.
    std::vector<uint32_t> sorted = *tiles;
    std::sort(sorted.begin(), sorted.end());
    if (auto dup = std::adjacent_find(sorted.begin(), sorted.end()); dup != sorted.end())
      return makeError(ErrorCode::kInvalidArgument, path + ": tile " + std::to_string(*dup) + " is named twice");
    for (uint32_t id : *tiles) {
      const TileEntry* e = file.findTile(id);
      if (!e) return makeError(ErrorCode::kInvalidArgument, path + ": no tile with id " + std::to_string(id));
      chosen.push_back(e);
    }
  } else {
    for (const auto& e : file.tiles()) chosen.push_back(&e);
  }
  return chosen;
}

// Payload bytes each level needs over the chosen tiles (index = level number, 0 to the last level of any chosen
// tile); a tile needs its first level's bytes for levels coarser than that, its last level's for levels past it.
Result<std::vector<uint64_t>> levelBytes(const ContainerFile& file, const std::vector<const TileEntry*>& chosen) {
  std::vector<std::vector<CodecLevel>> per_tile;
  uint32_t last = 0;
  for (const TileEntry* e : chosen) {
    SP_ASSIGN_OR_RETURN(auto levels, file.tileLevels(*e));
    if (levels.empty())
      return makeError(ErrorCode::kInvalidArgument,
                       file.path() + ": tile " + std::to_string(e->tile_id) + " uses codec " + codecName(e->codec) +
                           ", which is single-rate: it has no levels to choose from (decode it without --level or "
                           "--bytes)");
    last = std::max(last, levels.back().level);
    per_tile.push_back(std::move(levels));
  }
  std::vector<uint64_t> total(size_t(last) + 1, 0);
  for (const auto& levels : per_tile) addLevelBytes(levels, total);
  return total;
}

// Decodes the chosen tiles (at `level` when given) and welds them. Tiles decoded at a coarse level weld by position
// (their vertices' attributes differ between tiles along a seam): a welded vertex keeps its first tile's attributes
// when that tile has its own (kdtree and octree from version 3), else gets them derived from the welded mesh.
// `drop_scalars`: the tiles' scalar channels are cleared before they are welded (an output that writes none; the
// streamed decode does the same then), and the result has none.
Result<QuantizedMesh> decodeChosen(const ContainerFile& file, const std::vector<const TileEntry*>& chosen,
                                   std::optional<uint32_t> level, bool drop_scalars = false) {
  // Tiles decode independently: in parallel, then welded in index order (deterministic).
  SP_ASSIGN_OR_RETURN(auto tiles, decodeTiles(file, chosen, level));
  std::vector<QuantizedMesh> decoded;
  decoded.reserve(tiles.size());
  bool all_complete = true;
  std::vector<uint8_t> own;
  for (DecodedTile& t : tiles)
    decoded.push_back(std::move(t.mesh)), all_complete &= t.complete, own.push_back(t.own_attributes);
  tiles.clear();
  if (drop_scalars)
    for (QuantizedMesh& m : decoded) m.scalars.clear();
  AttributeLayout layout = file.header().layout;
  if (drop_scalars) layout.scalars.clear();
  if (decoded.empty()) return QuantizedMesh();
  if (all_complete && decoded.size() == 1) return std::move(decoded[0]);  // what weldTiles would copy
  if (all_complete) return weldTiles(decoded);
  if (std::find(own.begin(), own.end(), 0) == own.end()) return weldTiles(decoded, WeldBy::kPosition);
  std::vector<uint32_t> owner;
  QuantizedMesh welded = weldTiles(decoded, WeldBy::kPosition, &owner);
  std::vector<uint8_t> keep(owner.size());
  for (size_t v = 0; v < owner.size(); ++v) keep[v] = own[owner[v]];
  deriveAttributes(welded, layout, keep);
  return welded;
}

}  // namespace

Result<QuantizedMesh> decodeContainer(const std::string& path, const std::optional<std::vector<uint32_t>>& tiles,
                                      ContainerHeader* header, std::optional<uint32_t> level) {
  SP_ASSIGN_OR_RETURN(ContainerFile file, ContainerFile::open(path));
  SP_ASSIGN_OR_RETURN(auto chosen, chooseTiles(file, path, tiles));
  if (header) *header = file.header();
  return decodeChosen(file, chosen, level);
}

std::array<double, 6> tileWorldBounds(const TileEntry& tile, const Grid& grid) {
  std::array<double, 6> b{};
  for (int a = 0; a < 3; ++a) {
    b[a] = grid.origin[a] + tile.lo[a] * grid.cell;
    b[a + 3] = grid.origin[a] + (double(tile.hi[a]) + 1) * grid.cell;
  }
  return b;
}

Result<MergeResult> mergeContainers(const std::vector<std::string>& parts, const std::string& output) {
  if (parts.empty()) return makeError(ErrorCode::kInvalidArgument, "merge needs the parts");
  SP_RETURN_IF_ERROR(checkContainerName(output));
  SP_RETURN_IF_ERROR(checkOutputPath(output, parts));
  std::vector<ContainerFile> files;
  for (const std::string& p : parts) {
    SP_ASSIGN_OR_RETURN(ContainerFile f, ContainerFile::open(p));
    files.push_back(std::move(f));
  }
  const ContainerHeader& first = files[0].header();
  if (!first.partial())
    return makeError(ErrorCode::kInvalidArgument, parts[0] + ": a whole container, not a part (encode --subset i/N)");
  const uint16_t n = first.subset_count;
  std::vector<const ContainerFile*> by_index(n, nullptr);
  for (const ContainerFile& f : files) {
    const ContainerHeader& h = f.header();
    if (!h.partial())
      return makeError(ErrorCode::kInvalidArgument, f.path() + ": a whole container, not a part (encode --subset i/N)");
    if (h.subset_count != n)
      return makeError(ErrorCode::kInvalidArgument, f.path() + ": part " + std::to_string(h.subset_index) + " of " +
                                                        std::to_string(h.subset_count) + ", not of " +
                                                        std::to_string(n) + " as " + parts[0]);
    if (h.grid.bits != first.grid.bits || h.grid.cell != first.grid.cell || h.grid.origin != first.grid.origin ||
        h.layout != first.layout || h.materials != first.materials)
      return makeError(ErrorCode::kInvalidArgument, f.path() + ": another grid or attribute layout than " + parts[0] +
                                                        ": parts of different scans or settings");
    if (by_index[h.subset_index])
      return makeError(ErrorCode::kInvalidArgument, f.path() + ": part " + std::to_string(h.subset_index) +
                                                        " is given twice (also " + by_index[h.subset_index]->path() +
                                                        ")");
    by_index[h.subset_index] = &f;
  }
  for (uint16_t i = 0; i < n; ++i)
    if (!by_index[i])
      return makeError(ErrorCode::kInvalidArgument, "part " + std::to_string(i) + " of " + std::to_string(n) +
                                                        " is missing (encode --subset " + std::to_string(i) + "/" +
                                                        std::to_string(n) + ")");
  // Every tile in tile order, from the part whose share it is.
  std::vector<std::pair<const TileEntry*, const ContainerFile*>> tiles;
  for (const ContainerFile& f : files)
    for (const TileEntry& e : f.tiles()) {
      if (e.tile_id % n != f.header().subset_index)
        return makeError(ErrorCode::kMalformed, f.path() + ": tile " + std::to_string(e.tile_id) + " is not of part " +
                                                    std::to_string(f.header().subset_index) + "'s share");
      tiles.push_back({&e, &f});
    }
  std::sort(tiles.begin(), tiles.end(), [](auto& a, auto& b) { return a.first->tile_id < b.first->tile_id; });
  SP_ASSIGN_OR_RETURN(auto out, AtomicFile::create(output));
  ContainerWriter writer(*out, first.grid, first.layout);
  SP_RETURN_IF_ERROR(writer.setMaterial(first.materials));
  SP_RETURN_IF_ERROR(writer.begin());
  std::vector<uint8_t> chunk;
  for (const auto& [e, f] : tiles) {
    const CodecInfo* codec = findCodec(e->codec);
    if (!codec || e->codec_version == 0 || e->codec_version > codec->version)
      return makeError(ErrorCode::kUnsupported, f->path() + ": tile " + std::to_string(e->tile_id) +
                                                    " was coded by a codec version this build does not know");
    SP_ASSIGN_OR_RETURN(auto payload, f->readPayload(*e, chunk));
    // Parts from an older build keep their tiles' versions (every version still decodes).
    SP_RETURN_IF_ERROR(writer.addTile(e->tile_id, *codec, TileSummary{e->vertices, e->faces, e->lo, e->hi}, payload,
                                      e->codec_version));
  }
  SP_RETURN_IF_ERROR(writer.finish());
  SP_RETURN_IF_ERROR(out->commit());
  return MergeResult{n, static_cast<uint32_t>(tiles.size()), writer.bytesWritten()};
}

bool floatPositionSuffices(const Vec3u& q, const Grid& grid) {
  // One axis at a time through a float variable: GCC 12 -O3 vectorized the three-lane form of this check and
  // dropped two of the double->float roundings, so the check passed where float did not suffice.
  const double max_coord = grid.maxCoord();
  for (int a = 0; a < 3; ++a) {
    const float f = static_cast<float>(grid.origin[a] + (q[a] + 0.5) * grid.cell);
    const double t = std::floor((static_cast<double>(f) - grid.origin[a]) / grid.cell);
    if ((t < 0.0 ? 0.0 : (t > max_coord ? max_coord : t)) != q[a]) return false;
  }
  return true;
}

bool floatPositionsSuffice(const QuantizedMesh& mesh, const Grid& grid) {
  for (const auto& q : mesh.positions)
    if (!floatPositionSuffices(q, grid)) return false;
  return true;
}

bool insideBox(const Vec3d& p, const std::array<double, 6>& box) {
  return p[0] >= box[0] && p[1] >= box[1] && p[2] >= box[2] && p[0] <= box[3] && p[1] <= box[4] && p[2] <= box[5];
}

namespace {

// What a decode reads: the container, the chosen tiles (pointers into file.tiles()) and the level.
struct Selection {
  ContainerFile file;
  std::vector<const TileEntry*> chosen;
  std::optional<uint32_t> level;
  DecodeResult result;
};

Result<Selection> selectTiles(const DecodeSettings& settings) {
  if (settings.level && settings.bytes)  // one would silently win over the other
    return makeError(ErrorCode::kInvalidArgument, "--level and --bytes choose the level two ways: give one of them");
  SP_ASSIGN_OR_RETURN(ContainerFile file, ContainerFile::open(settings.input));
  if (settings.box && settings.tiles)
    return makeError(ErrorCode::kInvalidArgument, "--box and --tiles choose the tiles two ways: give one of them");
  if (settings.crop && !settings.box) return makeError(ErrorCode::kInvalidArgument, "--crop needs --box");
  std::vector<const TileEntry*> chosen;
  if (settings.box) {
    SP_ASSIGN_OR_RETURN(chosen, tilesInBox(file, settings.input, *settings.box));
  } else {
    SP_ASSIGN_OR_RETURN(chosen, chooseTiles(file, settings.input, settings.tiles));
  }
  const ContainerHeader& header = file.header();
  DecodeResult result;
  result.subset_index = header.subset_index;
  result.subset_count = header.subset_count;
  std::optional<uint32_t> level = settings.level;
  if (settings.level || settings.bytes) {
    SP_ASSIGN_OR_RETURN(auto bytes, levelBytes(file, chosen));
    if (level && *level >= bytes.size())
      return makeError(ErrorCode::kInvalidArgument, settings.input + ": level " + std::to_string(*level) +
                                                        " is past the last (" + std::to_string(bytes.size() - 1) + ")");
    if (settings.bytes) {
      if (bytes[0] > *settings.bytes)
        return makeError(ErrorCode::kInvalidArgument, settings.input + ": --bytes " + std::to_string(*settings.bytes) +
                                                          " is below the coarsest level, which needs " +
                                                          std::to_string(bytes[0]) + " bytes");
      uint32_t l = 0;
      while (l + 1 < bytes.size() && bytes[l + 1] <= *settings.bytes) ++l;
      if (!level || l < *level) level = l;
    }
    if (*level < bytes.size()) result.level_bytes = bytes[*level];
    result.level = level;
  }
  Selection sel{std::move(file), std::move(chosen), level, result};
  return sel;
}

}  // namespace

Result<DecodedMesh> decodeToMesh(const DecodeSettings& settings) {
  SP_ASSIGN_OR_RETURN(Selection sel, selectTiles(settings));
  SP_ASSIGN_OR_RETURN(QuantizedMesh q, decodeChosen(sel.file, sel.chosen, sel.level));
  const ContainerHeader& header = sel.file.header();
  if (settings.crop) q = cropToBox(q, header.grid, *settings.box);
  DecodedMesh out;
  out.result = sel.result;
  out.result.vertices = q.positions.size();
  out.result.faces = q.triangles.size();
  out.result.tiles = static_cast<uint32_t>(sel.chosen.size());
  out.header = header;
  out.mesh = dequantizeMesh(q, header.grid, header.layout);
  return out;
}

// The container's scalar channels that the output's format has no place for (all but PLY's; OBJ and glTF keep the
// texture coordinates and lossless normals: texcoords.h): listed (with the vertices written), never silent. A
// streamed decode writes what the in-memory one does.
void noteDroppedScalars(const ContainerHeader& header, const std::string& output, DecodeResult& result) {
  const std::vector<bool> written = channelsWritten(output, header.layout.scalars, result.faces > 0);
  for (size_t i = 0; i < header.layout.scalars.size(); ++i)
    if (!written[i]) result.dropped.push_back({"vertex." + header.layout.scalars[i].name, result.vertices});
  // Only OBJ has a place for the material lines, only PLY for the texture file comment.
  const auto format = MeshFileFormat::forPath(output);
  const auto kind = format.isOk() ? std::optional(format->kind()) : std::nullopt;
  for (const auto& [name, value, home] :
       {std::tuple{"obj mtllib", &header.materials.library, MeshFileFormat::Kind::kObj},
        {"obj usemtl", &header.materials.material, MeshFileFormat::Kind::kObj},
        {"ply comment TextureFile", &header.materials.texture, MeshFileFormat::Kind::kPly}})
    if (!value->empty() && kind != home) result.dropped.push_back({std::string(name) + " " + *value, 1});
}

Result<DecodeResult> decodeFile(const DecodeSettings& settings) {
  SP_RETURN_IF_ERROR(checkOutputPath(settings.output, {settings.input}));  // `decode X X` must not replace X
  SP_ASSIGN_OR_RETURN(Selection sel, selectTiles(settings));
  const ContainerFile& file = sel.file;
  const std::vector<const TileEntry*>& chosen = sel.chosen;
  const std::optional<uint32_t> level = sel.level;
  const ContainerHeader& header = file.header();
  DecodeResult result = sel.result;
  const std::string ext = lowerExtension(settings.output);
  const bool gltf = ext == ".glb" || ext == ".gltf";
  if (!gltf && (settings.gltf_tile_nodes || settings.gltf_compression != GltfCompression::kNone))
    return makeError(ErrorCode::kInvalidArgument, settings.output +
                                                      ": --gltf-compression and --gltf-nodes are for glTF output "
                                                      "(.glb, .gltf)");
  result.tiles = static_cast<uint32_t>(chosen.size());
  // Whether the output format writes any of the container's scalar channels (PLY all, OBJ and glTF texture
  // coordinates, lossless normals as normals): tiles weld by them then, and without them otherwise.
  const std::vector<bool> written = channelsWritten(settings.output, header.layout.scalars);
  const bool writes_scalars = std::find(written.begin(), written.end(), true) != written.end();
  const uint64_t in_memory = inMemoryDecodeBytes(chosen, size_t(header.layout.scalarStride()));
  if (settings.memory_budget > 0 && in_memory > settings.memory_budget) {
    uint64_t faces = 0;
    for (const TileEntry* e : chosen) faces += e->faces;
    const auto format = MeshFileFormat::forPath(settings.output);
    const bool obj = format.isOk() && format->kind() == MeshFileFormat::Kind::kObj;
    if (obj && faces > 0 && findTexcoords(header.layout.scalars))
      return makeError(ErrorCode::kUnsupported,
                       settings.output +
                           ": OBJ output with texture coordinates is built in memory (the wedges at texture seams "
                           "share their `v` lines), about " +
                           std::to_string(in_memory >> 20) + " MiB here, over the memory budget of " +
                           std::to_string(settings.memory_budget >> 20) +
                           " MiB: raise --memory-budget, or decode to .ply (it streams them)");
    if (gltf)
      return makeError(ErrorCode::kLimitExceeded,
                       settings.output + ": glTF output is built in memory, about " + std::to_string(in_memory >> 20) +
                           " MiB here, over the memory budget of " + std::to_string(settings.memory_budget >> 20) +
                           " MiB: raise --memory-budget, or decode to .ply, .obj, .stl or .off (those stream)");
    StreamDecodeSettings stream;
    stream.level = level;
    if (settings.crop) stream.crop = settings.box;
    stream.memory_budget = settings.memory_budget;
    stream.scratch_parent = settings.scratch_dir;
    stream.scalars = writes_scalars;
    stream.materials = header.materials;
    SP_ASSIGN_OR_RETURN(StreamDecodeResult streamed, streamDecode(file, chosen, settings.output, stream));
    result.vertices = streamed.vertices;
    result.faces = streamed.faces;
    result.double_positions = streamed.double_positions;
    result.streamed = true;
    noteDroppedScalars(header, settings.output, result);
    return result;
  }
  WriteOptions write;
  write.gltf_compression = settings.gltf_compression;
  write.grid = &header.grid;
  write.materials = header.materials;
  if (settings.gltf_tile_nodes) {  // one node per tile, each decoded on its own (border vertices in both)
    std::vector<Mesh> meshes;
    std::vector<std::string> names;
    for (const TileEntry* t : chosen) {
      SP_ASSIGN_OR_RETURN(QuantizedMesh q, decodeChosen(file, {t}, level));
      if (settings.crop) q = cropToBox(q, header.grid, *settings.box);
      result.vertices += q.positions.size();
      result.faces += q.triangles.size();
      meshes.push_back(dequantizeMesh(q, header.grid, header.layout));
      names.push_back("tile " + std::to_string(t->tile_id));
    }
    std::vector<GltfPart> parts;
    for (size_t i = 0; i < meshes.size(); ++i) parts.push_back({names[i], &meshes[i]});
    result.tiles = static_cast<uint32_t>(chosen.size());
    SP_RETURN_IF_ERROR(writeGltfParts(settings.output, parts, write));
    noteDroppedScalars(header, settings.output, result);
    return result;
  }
  // A format that writes none of the scalar channels gets the vertices the streamed decode writes: welded without
  // them (texture seams' wedges on tile borders weld into one vertex, as in the tiles' interiors they stay apart).
  const bool drop_scalars = header.layout.hasScalars() && !writes_scalars;
  AttributeLayout layout = header.layout;
  if (drop_scalars) layout.scalars.clear();
  SP_ASSIGN_OR_RETURN(QuantizedMesh q, decodeChosen(file, chosen, level, drop_scalars));
  if (settings.crop) q = cropToBox(q, header.grid, *settings.box);
  result.vertices = q.positions.size();
  result.faces = q.triangles.size();
  result.tiles = static_cast<uint32_t>(chosen.size());
  result.double_positions = !floatPositionsSuffice(q, header.grid);
  const Mesh mesh = dequantizeMesh(q, header.grid, layout);
  q = QuantizedMesh();  // the decoded mesh's memory is bounded by the container's size (FORMAT.md): held once
  write.double_positions = result.double_positions;
  SP_RETURN_IF_ERROR(writeMeshFile(settings.output, mesh, write));
  noteDroppedScalars(header, settings.output, result);
  return result;
}

}  // namespace scanpress
