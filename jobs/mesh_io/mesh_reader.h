// Streaming mesh readers: PLY (ascii, binary little and big endian, tristrips), OBJ, STL (binary and ascii,
// welded), OFF; any of them zstd-compressed.
//
// A reader hands vertices and triangles to a MeshSink in chunks of at most `ReadOptions::chunk` elements, so its
// own memory stays bounded whatever the file size (STL keeps one hash entry per distinct position, to weld; OBJ
// and PLY files whose faces give corners texture coordinates or normals keep a few bytes per vertex and per
// distinct value: WedgePlan).
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
#include <unordered_map>
#include <string>
#include <vector>

#include "engine/mesh.h"
#include "engine/status.h"

namespace scanpress {

enum class MeshFormat { kUnknown, kPly, kObj, kStl, kOff };

struct ReadOptions {
  size_t chunk = 1u << 16;  // vertices or triangles per sink call
  // OBJ `vt` and PLY `texcoord` lists named by faces: kept as scalar channels u and v, vertices split into wedges
  // at texture seams (texcoords.h; the file is read twice). Off (a codec that does not carry scalars, whose
  // simplification would open the seams): listed dropped as "obj vt" or "face.texcoord", not split by them.
  bool texture_coordinates = true;
  // OBJ `vn` per corner: a vertex whose corners name different normals (a crease) is split into wedges, one per
  // normal (compared by bit pattern; a flat-shaded file's vertex splits once per face normal). Off (a simplifying
  // codec): a vertex's normal is its first corner's, the others listed "obj vn per corner". The wedges stay apart
  // in decoded output, except that OBJ output with texture coordinates shares their `v` lines.
  bool corner_normals = true;

  // Vertices as the file has them (no wedges: OBJ `vt` and PLY `texcoord` lists listed dropped, a vertex's normal its
  // first corner's), the file read once: what surface measurement, rendering, synthesis and the benchmarks read.
  static ReadOptions asInFile() {
    ReadOptions o;
    o.texture_coordinates = o.corner_normals = false;
    return o;
  }
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
  // OBJ: the `mtllib` libraries, and the `usemtl` name when every face has that one (a file naming several
  // materials keeps none, listed dropped: a material per face is not kept yet; its libraries are kept). PLY: the
  // `comment TextureFile` name, when the header names one.
  MaterialNames materials;
  // PLY: normals stored as double (delivered as float: --lossless-normals refuses them).
  bool double_normals = false;
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
Result<Mesh> readMeshFile(const std::string& path, ReadStats* stats = nullptr, const ReadOptions& options = {});

// What a file's faces make of their corners' texture coordinates and normals (OBJ `vt`/`vn`, PLY per-face
// `texcoord` lists), learnt by a first read: a vertex whose corners name different values is split into wedges,
// one per distinct value, delivered right after it by the second read (texcoords.h).
//
// A corner's key is its (texture coordinate, normal) pair of value indices, kNone for a kind it does not name (a
// corner `v/t` beside `v/t/n` corners is a wedge of its own, without a normal: as the file has it); a corner naming
// neither takes the vertex's first wedge, whose key is its first corner naming either.
struct WedgePlan {
  static constexpr uint32_t kNone = UINT32_MAX;
  bool textures = false;  // split on texture coordinates (delivered as channels u and v): some face names one
  bool normals = false;   // split on normals (OBJ `vn`)
  std::vector<std::array<float, 2>> uvs;              // the distinct (u, v) values, in order of first appearance
  std::unordered_map<uint64_t, uint32_t> uv_ids;      // a (u, v)'s bits -> its index in uvs
  std::vector<uint32_t> uv_of;                        // OBJ: per `vt` record, its value's index
  std::vector<bool> vt_used;                          // OBJ: per `vt` record, named by a face corner
  std::vector<uint32_t> normal_of;                    // OBJ: per `vn` record, its distinct value's index
  std::vector<std::pair<uint32_t, uint32_t>> keys;    // distinct (uv, normal) pairs of corners (kNone: none)
  std::unordered_map<uint64_t, uint32_t> key_ids;     // a pair -> its index in keys
  std::vector<uint32_t> first;                        // per vertex: the key of wedge 0, or kNone
  std::vector<std::pair<uint32_t, uint32_t>> wedges;  // (vertex, key) of its further keys, sorted, distinct

  bool splits() const { return !keys.empty(); }
  // The vertex count: the first read grows it as it goes (OBJ) or sets it once the vertices are read (PLY).
  void resizeVertices(size_t n) { first.resize(n, kNone); }
  // The index of a (u, v) value, added when new (the first read).
  uint32_t addUv(const std::array<float, 2>& uv);
  // The index of a (u, v) value the first read saw, else kNone - 1.
  uint32_t uvId(const std::array<float, 2>& uv) const;
  // The first read: a corner of vertex v (< the vertex count) naming values t and n (kNone: none).
  void addCorner(uint32_t v, uint32_t t, uint32_t n);
  // The end of the first read.
  void finish();
  // The second read: which of vertex v's delivered vertices (0: the first, k: its k-th wedge) a corner naming t and
  // n takes; nullopt when the first read saw no such corner (the file changed between the reads).
  std::optional<uint32_t> wedgeOf(uint32_t v, uint32_t t, uint32_t n) const;
  // The u and v words of a vertex with key `key` ((0, 0) when it names no texture coordinate).
  std::array<uint32_t, 2> words(uint32_t key) const {
    const uint32_t t = key == kNone ? kNone : keys[key].first;
    if (t == kNone) return {0, 0};
    return {std::bit_cast<uint32_t>(uvs[t][0]), std::bit_cast<uint32_t>(uvs[t][1])};
  }

 private:
  static uint64_t uvBits(const std::array<float, 2>& uv) {
    return uint64_t(std::bit_cast<uint32_t>(uv[0])) << 32 | std::bit_cast<uint32_t>(uv[1]);
  }
  uint32_t keyOf(uint64_t pair);
  size_t deduplicated_ = 0;  // wedges' size at their last deduplication
};

// The scalar channels a plan's vertices carry: u and v (float32) when it splits on texture coordinates, else none.
std::vector<ScalarChannel> texcoordChannels(const WedgePlan* plan);

// Format-specific entry points (used by readMesh; exposed for tests).
class Scanner;
Result<ReadStats> readPly(Scanner& in, MeshSink& sink, const ReadOptions& options, const WedgePlan* plan = nullptr);
// `plan`: from planObjWedges (planPlyWedges) over the same bytes (nullptr: `vt` records and `texcoord` lists are
// listed dropped, a vertex's normal is its first corner's).
Result<WedgePlan> planObjWedges(Scanner& in, const ReadOptions& options);
Result<WedgePlan> planPlyWedges(Scanner& in, const ReadOptions& options);
Result<ReadStats> readObj(Scanner& in, MeshSink& sink, const ReadOptions& options, const WedgePlan* plan = nullptr);
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
