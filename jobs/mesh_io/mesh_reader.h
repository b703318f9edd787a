// Streaming mesh readers: PLY (ascii, binary little and big endian, tristrips), OBJ, STL (binary and ascii,
// welded), OFF; any of them zstd-compressed.
//
// A reader hands vertices and triangles to a MeshSink in chunks of at most `ReadOptions::chunk` elements, so its
// own memory stays bounded whatever the file size (STL keeps one hash entry per distinct position, to weld).
// Guarantees to the sink: every triangle's indices refer to vertices already delivered; normals and colors, when
// present, come with their vertices (OBJ only: normals that faces assign to vertices arrive at the end through
// vertexNormals). Polygons are fan-triangulated.
//
// Nothing is dropped silently: every property, element or record a reader skips is listed in ReadStats::dropped
// by name and count (per-face properties, extra PLY elements, OBJ mtllib/usemtl, ...).
//
// Errors name the file and the line (text formats) or byte offset (binary formats; for compressed files, the
// offset in the decompressed data). Malformed input fails with kMalformed or kTruncated, never a crash; declared
// counts are never trusted for allocation.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "engine/mesh.h"
#include "engine/status.h"

namespace scanpress {

enum class MeshFormat { kUnknown, kPly, kObj, kStl, kOff };

struct ReadOptions {
  size_t chunk = 1u << 16;  // vertices or triangles per sink call
  // OBJ `vt` named by faces: kept as scalar channels u and v, vertices split into wedges at texture seams
  // (texcoords.h; the file is read twice). Off (a codec that does not carry scalars, whose simplification would open
  // the seams): listed dropped as "obj vt", vertices as in the file.
  bool texture_coordinates = true;
};

// Something the file holds that scanpress does not keep (yet): a PLY property or element, OBJ texture coordinates
// or materials. `name` says what ("vertex.confidence", "face.quality", "element camera", "obj vt", "obj usemtl"),
// `count` how many values or records were dropped.
struct DroppedProperty {
  std::string name;
  uint64_t count = 0;
};

// "vertex.confidence x 35947, element camera x 1": for warnings and errors.
std::string describeDropped(std::span<const DroppedProperty> dropped);

struct ReadStats {
  MeshFormat format = MeshFormat::kUnknown;
  std::string format_detail;             // e.g. "PLY binary_big_endian", "STL ascii"
  uint64_t vertices = 0;                 // vertices delivered (after STL welding)
  uint64_t triangles = 0;                // triangles delivered (after triangulation)
  uint64_t polygons = 0;                 // faces with more than 3 corners that were triangulated
  uint64_t source_vertices = 0;          // vertex records in the file (STL: 3 per facet)
  std::vector<DroppedProperty> dropped;  // what the reader read past, in file order (empty: nothing)
};

// A chunk's scalar channels (PLY vertex properties kept at their type, such as confidence or intensity): the
// channels, the same on every call of one read, and their values, ScalarValues' words (stride per vertex: the
// channels' scalarTypeWords) for the chunk's vertices; both empty when the file has none.
struct ScalarChunk {
  std::span<const ScalarChannel> channels;
  std::span<const uint32_t> values;
};

class MeshSink {
 public:
  virtual ~MeshSink() = default;
  // `normals` and `colors` are empty or as long as `positions`; `color_channels` is 3 or 4 when colors are given.
  virtual Status vertices(std::span<const Vec3d> positions, std::span<const Vec3f> normals,
                          std::span<const Rgba8> colors, uint8_t color_channels, const ScalarChunk& scalars) = 0;
  virtual Status triangles(std::span<const Triangle> triangles) = 0;
  // OBJ: normals referenced by face corners, for vertices [first, first + normals.size()); NaN where none.
  virtual Status vertexNormals(uint64_t first, std::span<const Vec3f> normals) = 0;
};

// Collects everything a reader delivers into a Mesh. Attributes that start late (a first chunk without colors,
// OBJ normals from faces) are padded: missing normals are (0,0,0), missing colors white; call finish() after the
// read so every attribute array covers every vertex.
class MeshCollector : public MeshSink {
 public:
  explicit MeshCollector(Mesh& mesh) : mesh_(mesh) {}
  Status vertices(std::span<const Vec3d> positions, std::span<const Vec3f> normals, std::span<const Rgba8> colors,
                  uint8_t color_channels, const ScalarChunk& scalars) override;
  Status triangles(std::span<const Triangle> triangles) override;
  Status vertexNormals(uint64_t first, std::span<const Vec3f> normals) override;
  void finish();

 private:
  Mesh& mesh_;
};

// Format from the name (a trailing .zst is ignored), else from the content.
MeshFormat formatFromName(const std::string& path);

Result<ReadStats> readMesh(const std::string& path, MeshSink& sink, const ReadOptions& options = {});

// Whether reading `path` again costs less than keeping what a first read delivered: an uncompressed binary PLY,
// whose records parse at memory speed (bench/RESULTS.md, "Encode on two threads"). False when unsure (a file that
// cannot be opened, stdin, text, compressed).
bool cheapToReadAgain(const std::string& path);

// Convenience: the whole mesh in memory.
Result<Mesh> readMeshFile(const std::string& path, ReadStats* stats = nullptr);

// What an OBJ's faces make of its texture coordinates (the first of two reads: obj_reader.cpp).
struct ObjTexturePlan {
  std::vector<std::array<float, 2>> values;  // the distinct (u, v) values, in order of first `vt`
  std::vector<uint32_t> canonical;           // per `vt` record: its value's index
  std::vector<bool> used_records;            // per `vt` record: named by a face corner
  std::vector<uint32_t> first;               // per `v`: the value of its first corner naming one, or UINT32_MAX
  std::vector<std::pair<uint32_t, uint32_t>> wedges;  // (v, value) of further values, sorted, distinct

  uint32_t firstOf(uint64_t v) const { return v < first.size() ? first[v] : UINT32_MAX; }
  // A vertex's scalar words for value `c` ((0, 0) for UINT32_MAX).
  std::array<uint32_t, 2> words(uint32_t c) const {
    if (c == UINT32_MAX) return {0, 0};
    return {std::bit_cast<uint32_t>(values[c][0]), std::bit_cast<uint32_t>(values[c][1])};
  }
  // Which of vertex v's delivered vertices (0: the first, k: its k-th wedge) carries `vt` record `record`;
  // nullopt when the plan has none (the file changed between the reads).
  std::optional<uint32_t> wedgeOf(uint32_t v, uint32_t record) const {
    if (record >= canonical.size()) return std::nullopt;
    const uint32_t c = canonical[record];
    if (c == firstOf(v)) return 0;
    const auto begin = std::lower_bound(wedges.begin(), wedges.end(), std::pair<uint32_t, uint32_t>{v, 0});
    const auto it = std::lower_bound(begin, wedges.end(), std::pair<uint32_t, uint32_t>{v, c});
    if (it == wedges.end() || *it != std::pair<uint32_t, uint32_t>{v, c}) return std::nullopt;
    return uint32_t(1 + (it - begin));
  }
};

// The scalar channels a plan's vertices carry: u and v (float32), or none without a plan or values.
std::vector<ScalarChannel> texcoordChannels(const ObjTexturePlan* plan);

// Format-specific entry points (used by readMesh; exposed for tests).
class Scanner;
Result<ReadStats> readPly(Scanner& in, MeshSink& sink, const ReadOptions& options);
// `plan`: from planObjTextures over the same bytes (nullptr: `vt` records are listed dropped).
Result<ObjTexturePlan> planObjTextures(Scanner& in);
Result<ReadStats> readObj(Scanner& in, MeshSink& sink, const ReadOptions& options,
                          const ObjTexturePlan* plan = nullptr);
Result<ReadStats> readStl(Scanner& in, MeshSink& sink, const ReadOptions& options);
Result<ReadStats> readOff(Scanner& in, MeshSink& sink, const ReadOptions& options);

// Buffers vertices and triangles and hands them to a sink in chunks (shared by the readers).
class ChunkBuffer {
 public:
  ChunkBuffer(MeshSink& sink, size_t chunk, uint8_t color_channels, bool normals,
              std::vector<ScalarChannel> scalar_channels = {})
      : sink_(sink),
        chunk_(chunk),
        channels_(color_channels),
        normals_(normals),
        scalar_channels_(std::move(scalar_channels)),
        stride_(scalarWords(scalar_channels_)) {}
  // `scalars`: the vertex's scalar values (stride words), when the buffer has scalar channels.
  Status addVertex(const Vec3d& p, const Vec3f& n, const Rgba8& c, const uint32_t* scalars = nullptr) {
    pos_.push_back(p);
    if (normals_) nrm_.push_back(n);
    if (channels_) col_.push_back(c);
    if (stride_ && scalars) sca_.insert(sca_.end(), scalars, scalars + stride_);
    ++vertices_;
    return pos_.size() >= chunk_ ? flushVertices() : Status::ok();
  }
  Status addTriangle(const Triangle& t) {
    tri_.push_back(t);
    ++triangles_;
    return tri_.size() >= chunk_ ? flushTriangles() : Status::ok();
  }
  Status flushVertices();
  Status flushTriangles();  // flushes pending vertices first
  Status flush() { return flushTriangles(); }
  uint64_t vertices() const { return vertices_; }
  uint64_t triangles() const { return triangles_; }

 private:
  MeshSink& sink_;
  size_t chunk_;
  uint8_t channels_;
  bool normals_;
  std::vector<ScalarChannel> scalar_channels_;
  size_t stride_;
  ScalarValues sca_;
  std::vector<Vec3d> pos_;
  std::vector<Vec3f> nrm_;
  std::vector<Rgba8> col_;
  std::vector<Triangle> tri_;
  uint64_t vertices_ = 0, triangles_ = 0;
};

// Limits that make hostile files fail early instead of exhausting memory.
constexpr uint64_t kMaxVertices = 0xFFFFFFFEull;  // indices are 32-bit
constexpr uint32_t kMaxPolygonCorners = 1u << 16;

}  // namespace scanpress
