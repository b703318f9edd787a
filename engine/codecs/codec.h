// Tile codecs: pure functions from a quantized tile mesh to bytes and back.
//
// Codec ids are written to disk and are frozen: never renumber or reuse one. A codec's version is stored with
// every tile it writes; decoders accept every version they know and fail with kUnknownVersion otherwise.
// Decoders treat their input as hostile: they never read outside the payload, check counts against the bytes
// that remain before allocating, and validate what they return (indices < vertex count, coordinates on the grid).
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "engine/mesh.h"
#include "engine/simplify/simplify.h"
#include "engine/status.h"

namespace scanpress {

enum class CodecId : uint16_t {
  kStore = 1,
  kKdtree = 2,
  kOctree = 3,
  kPm = 4,           // engine/codecs/pm.cpp (issue 19)
  kEdgebreaker = 5,  // engine/codecs/edgebreaker.cpp (issue 20)
  kPrm = 6,          // engine/codecs/prm.cpp (issue 21)
};

// What every tile of a container shares: the grid's bits and the attribute layout (from the container header).
struct TileContext {
  int bits = 16;
  AttributeLayout layout;
};

// What a stage or codec receives: the tile's quantized mesh (local indices) and, per vertex, whether it is locked.
// A locked vertex is a border vertex under the contract in engine/tile.h: lossy stages must not move, remove or
// merge it, and must keep the chains of border edges between locked vertices. `locked` is empty (nothing locked)
// or has one entry per vertex. Lossless codecs keep everything and may ignore it.
struct TileView {
  const QuantizedMesh& mesh;
  std::span<const uint8_t> locked;
};

// The typed options of each codec, one struct per codec, filled by jobs/config.cpp and the CLI. The engine never
// sees options as strings.
struct OctreeOptions {
  // false codes every symbol kind with one adaptive model (measuring what the contexts gain): the payload is not
  // decodable. Not reachable from the CLI or job files.
  bool contexts = true;
};
// `pm` (engine/codecs/pm.cpp): the tile is simplified (engine/simplify/simplify.h) to its last level, and further to
// a base mesh; the payload is the base mesh and the vertex splits back to the last level, in batches (the levels).
// The defaults keep the tile as it is at the last level (lossless after quantization). The error targets of
// jobs/ (--max-error, --max-bytes) set max_error or ratio per tile.
struct PmOptions {
  SimplifyWeights weights = SimplifyWeights::kShapePreserving;
  // The last level: collapses of error estimate at most max_error grid cells (< 0: none, the tile as it is), down to
  // at least ratio of the tile's faces (1: no face target).
  double max_error = -1;
  double ratio = 1.0;
};
// `prm` (engine/codecs/prm.cpp): the tile is remeshed into a piecewise regular mesh (the `remesh` stage,
// engine/stages/stage.h) on hexagonal grids of spacing `grid` (a fraction of 2^bits cells), or `spacing` grid cells
// when that is >= 0 (the error targets of jobs/ set it per tile), and coded with the regular patches' lattice. The
// tile is coded as it is when that is smaller (a lattice finer than the tile's own triangles, most often), when its
// remeshing would break the border contract or exceed the remesher's size limit, or with spacing 0.
struct PrmOptions {
  double grid = 0.005;  // in (0, 1]
  double tau = 0.2;     // relief regularisation, in (0, 1/sqrt(3))
  double spacing = -1;  // grid cells; >= 0 overrides grid (rounded to an even number, at least 2; 0: no remeshing)
};
struct CodecOptions {
  OctreeOptions octree;
  PmOptions pm;
  PrmOptions prm;
};

// What a level means, as its codec states it (see CodecLevel).
enum class LevelKind : uint8_t {
  kCells = 1,       // vertices are cells of 2^cell_bits grid cells per axis, at the cells' centers (kdtree, octree)
  kSimplified = 2,  // a mesh of `vertices` vertices within `max_error` grid cells of the tile (simplification)
  kRemeshed = 3,    // a resampling on a regular grid of `spacing` grid cells (remeshing)
};

// One level of a progressive payload, coarse to fine: decoding it needs the first `end_bytes` bytes of the payload.
// Level numbers are the codec's own and increase towards the last level, which is the tile as encoded
// (`complete`). A level number coarser than a tile's first level decodes that first level; one past its last
// decodes the last.
struct CodecLevel {
  uint32_t level = 0;
  uint64_t end_bytes = 0;
  LevelKind kind = LevelKind::kCells;
  bool complete = false;   // the tile as encoded (lossless for the lossless codecs)
  uint32_t cell_bits = 0;  // kCells
  uint64_t vertices = 0;   // kSimplified
  double max_error = 0;    // kSimplified, in grid cells
  double spacing = 0;      // kRemeshed, in grid cells
};

// What the level means, in words ("cells of 2^4 grid cells", "complete (lossless)").
std::string describeLevel(const CodecLevel& level);

// Adds to total[L], for every level L < total.size(), the payload bytes a tile with these levels (as `levels`
// lists them, coarse to fine, non-empty) needs for L: a level coarser than the tile's first needs the first one's,
// a level past its last needs the last one's.
void addLevelBytes(std::span<const CodecLevel> levels, std::vector<uint64_t>& total);

// What a decoder of a payload yields: counts and quantized bounds of the decoded tile's vertices (inclusive; lo >
// hi when it has none). The encoder returns it with the payload; the container's index records it.
struct TileSummary {
  uint32_t vertices = 0;
  uint32_t faces = 0;
  Vec3u lo{UINT32_MAX, UINT32_MAX, UINT32_MAX};
  Vec3u hi{0, 0, 0};
};

struct EncodedTile {
  std::vector<uint8_t> payload;
  TileSummary decoded;
  std::vector<CodecLevel> levels;  // progressive codecs; empty for single-rate ones
  // The format version of the payload (0: the codec's, CodecInfo::version): kdtree writes a tile without creases
  // or seams as version 3, which older builds read too. The container records it (ContainerWriter::addTile).
  uint16_t version = 0;
  // Input points merged into another point at their grid position whose attributes (normal, color or scalar row)
  // differ: pm's weld keeps the wedges its triangles' corners use (a point no triangle uses is merged), and where its
  // last level is lossless (it simplifies nothing) the report lists how many it did not keep.
  uint64_t merged_points = 0;
};

// Hard limits on what a decoder may produce, from the container's index entry for the tile (DESIGN.md decision
// 10): a payload that claims more is rejected before anything is allocated. Coarse levels stay within them too.
struct DecodeLimits {
  uint32_t vertices = 0;
  uint32_t faces = 0;
};

// The least a payload of a codec can spend, documented per codec in engine/container/FORMAT.md: a tile of V
// vertices and F faces needs at least ceil((V * per_vertex + F * per_face) / 8) - slack_bytes payload bytes.
// Checked against the index's counts before any payload is read, so that an index cannot claim more than its
// file could hold; the writer checks it too, so that no file it writes is refused.
struct PayloadFloor {
  double bits_per_vertex = 0;
  double bits_per_face = 0;
  uint64_t slack_bytes = 0;
  // true: the codec spends a vertex's normal, color and scalar bits raw (2 x normal_bits + 8 x color_channels + each
  // scalar channel's type's bits), on top of
  // bits_per_vertex (store). false: it keeps none (pm) or predicts them at a cost near zero (kdtree, octree and
  // edgebreaker from version 2).
  bool raw_attributes = true;
  bool admits(const AttributeLayout& layout, uint64_t vertices, uint64_t faces, uint64_t payload_bytes) const;
  // The fewest payload bytes that admit these counts (0 when the slack covers them): what an encoder pads to.
  uint64_t minPayloadBytes(const AttributeLayout& layout, uint64_t vertices, uint64_t faces) const;
};

struct CodecInfo {
  CodecId id;
  std::string_view name;
  uint16_t version;  // the version this build writes
  PayloadFloor floor;
  // Encodes a tile; returns the payload and what the decoder will yield from it.
  Result<EncodedTile> (*encode)(const TileContext& ctx, const TileView& tile, const CodecOptions& options);
  // The whole tile, within `limits`.
  Result<QuantizedMesh> (*decode)(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                  const DecodeLimits& limits);
  // Progressive codecs only (nullptr otherwise): the levels a payload holds, and the mesh of one level from a
  // payload that may be cut after that level's end_bytes.
  Result<std::vector<CodecLevel>> (*levels)(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                            const DecodeLimits& limits) = nullptr;
  Result<QuantizedMesh> (*decode_level)(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                        uint32_t level, const DecodeLimits& limits) = nullptr;
  // False when the codec's payloads before `keeps_attributes_from` do not give back the tile's vertices with their
  // attributes (pm before v5 welded by position and kept the first point's): such tiles weld by position even when
  // complete, as coarse levels do, and get attributes derived from the welded mesh where they code none.
  bool keeps_attributes = true;
  // The first version whose levels show the tile's own normals and colors, coded through its levels (kdtree and
  // octree from 3, pm from 3; 0: coarse levels derive them from their triangles). A codec that welds by position
  // (keeps_attributes false) shows its own at its last level too from this version on.
  uint16_t coarse_attributes_from = 0;
  // Whether the first level shows them as well (pm: its base mesh codes them). kdtree's and octree's root level has
  // no segment: it derives them.
  bool root_level_attributes = false;
  // The first version whose whole payloads give back the tile's vertices with their attributes when
  // keeps_attributes is false (pm: 5, which keeps creases' and seams' wedges); 0: none.
  uint16_t keeps_attributes_from = 0;
  bool progressive() const { return levels != nullptr; }
  // Whether a whole payload of `version` gives back the tile's vertices and their attributes (else its tiles weld
  // by position).
  bool keepsAttributes(uint16_t version) const {
    return keeps_attributes || (keeps_attributes_from != 0 && version >= keeps_attributes_from);
  }
  // Whether a payload of `version` decodes with the tile's own attributes: whole (`level` = nullopt) or at a coarse
  // level (`root`: the first level).
  bool showsOwnAttributes(uint16_t version, bool coarse, bool root) const {
    const bool coded = coarse_attributes_from != 0 && version >= coarse_attributes_from;
    if (!coarse) return keepsAttributes(version) || coded;
    return coded && (!root || root_level_attributes);
  }
};

// The version a tile's payload decodes with: the one its encoder wrote (EncodedTile::version), or the codec's.
inline uint16_t payloadVersion(const CodecInfo& codec, const EncodedTile& tile) {
  return tile.version ? tile.version : codec.version;
}

std::span<const CodecInfo> allCodecs();
const CodecInfo* findCodec(CodecId id);
const CodecInfo* findCodec(std::string_view name);
// "store, kdtree, octree": for messages.
std::string codecNames();
// The codec's name, or "unknown(ID)".
std::string codecName(CodecId id);

// Encodes a whole tile with nothing locked (tests, benchmarks, whole-mesh tools).
Result<EncodedTile> encodeMesh(const CodecInfo& codec, const TileContext& ctx, const QuantizedMesh& mesh,
                               const CodecOptions& options = {});
// Limits that admit exactly the counts of `summary` (what the index will record for an encoded tile).
DecodeLimits limitsOf(const TileSummary& summary);

// Checks a decoded tile: attribute arrays sized to the vertex count, indices in range, coordinates on the grid.
Status validateTile(const TileContext& ctx, const QuantizedMesh& mesh);
// Checks counts a payload claims against the limits, naming `what` (the codec's payload) in the message.
Status checkLimits(std::string_view what, uint64_t vertices, uint64_t faces, const DecodeLimits& limits);
// The summary of a mesh: counts and bounds.
TileSummary summarize(const QuantizedMesh& mesh);
// Coarse-level attributes derived from geometry: area-weighted normals from the triangles, gray colors, scalars 0
// (as the layout asks); replaces whatever attributes the mesh had.
// `keep` (when not empty, one per vertex): the vertices that keep the attributes they have.
void deriveAttributes(QuantizedMesh& mesh, const AttributeLayout& layout, std::span<const uint8_t> keep = {});
// The lossless (float) normal deriveAttributes gives a vertex whose triangles' cross products sum to `sum`: the unit
// vector, or +z for a zero sum (as the octahedral code of a zero sum decodes to).
Vec3f derivedFloatNormal(const Vec3d& sum);
// A triangle's cross product on the grid (edges from its first corner, in double): the area-weighted normal that
// deriveAttributes sums at each corner, in triangle order.
Vec3d triangleCross(const std::vector<Vec3u>& positions, const Triangle& t);

// `store`: the reference codec (store.cpp).
Result<EncodedTile> storeEncode(const TileContext& ctx, const TileView& tile, const CodecOptions& options);
Result<QuantizedMesh> storeDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                  const DecodeLimits& limits);

// `kdtree`: progressive lossless coding after Gandoin & Devillers (kdtree.cpp). The progressive hierarchy codecs
// (kdtree, octree) merge vertices that share position and attributes, so they may yield fewer vertices than given.
Result<EncodedTile> kdtreeEncode(const TileContext& ctx, const TileView& tile, const CodecOptions& options);
Result<QuantizedMesh> kdtreeDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                   const DecodeLimits& limits);
Result<std::vector<CodecLevel>> kdtreeLevels(const TileContext& ctx, uint16_t version,
                                             std::span<const uint8_t> payload, const DecodeLimits& limits);
Result<QuantizedMesh> kdtreeDecodeLevel(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                        uint32_t level, const DecodeLimits& limits);

// `octree`: embedded mesh coding after Magnor & Girod (octree.cpp).
Result<EncodedTile> octreeEncode(const TileContext& ctx, const TileView& tile, const CodecOptions& options);
Result<QuantizedMesh> octreeDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                   const DecodeLimits& limits);
Result<std::vector<CodecLevel>> octreeLevels(const TileContext& ctx, uint16_t version,
                                             std::span<const uint8_t> payload, const DecodeLimits& limits);
Result<QuantizedMesh> octreeDecodeLevel(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                        uint32_t level, const DecodeLimits& limits);

// `pm`: a simplified base mesh and the vertex splits back to the tile, after Ahn, Chang and Ho (pm.cpp). Welds
// vertices by position; keeps no normals or colors (derived from the triangles at every level).
Result<EncodedTile> pmEncode(const TileContext& ctx, const TileView& tile, const CodecOptions& options);
Result<QuantizedMesh> pmDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                               const DecodeLimits& limits);
Result<std::vector<CodecLevel>> pmLevels(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                         const DecodeLimits& limits);
Result<QuantizedMesh> pmDecodeLevel(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                    uint32_t level, const DecodeLimits& limits);

// `edgebreaker`: single-rate lossless coding, Edgebreaker connectivity and parallelogram prediction
// (edgebreaker.cpp). Like kdtree it merges vertices that share position and attributes.
Result<EncodedTile> edgebreakerEncode(const TileContext& ctx, const TileView& tile, const CodecOptions& options);
Result<QuantizedMesh> edgebreakerDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                        const DecodeLimits& limits);

// What an encoding (kdtree, octree, edgebreaker) spent, in bits (ideal arithmetic-coding costs; the bytes add flushes and headers).
struct CodecStats {
  uint64_t points = 0;           // distinct coded vertices
  uint64_t triangles = 0;        // triangles coded (with multiplicity)
  uint64_t splits = 0;           // cell splits with both halves non-empty (vertex splits)
  uint64_t edge_expansions = 0;  // of those, coded as edge expansions
  double geometry_bits = 0;
  double connectivity_bits = 0;  // vertex splits, triangle orientation and multiplicity
  double attribute_bits = 0;
  double regularity_bits = 0;  // prm: which faces are regular, and their reliefs (the paper's "irregular" part)
  uint64_t payload_bytes = 0;
  uint64_t regular_faces = 0, patches = 0, lattice_points = 0;  // prm
};
// `version` (when given) gets the payload's format version (EncodedTile::version).
Status kdtreeEncodeWithStats(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out,
                             CodecStats* stats, uint16_t* version = nullptr);
// edgebreaker: `splits` and `edge_expansions` stay zero.
Status edgebreakerEncodeWithStats(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out,
                                  CodecStats* stats);
// prm's coder: edgebreaker with the regular patches of a lattice of `spacing` grid cells (even, 2..
// kMaxLatticeSpacing): which faces are regular and their reliefs, then heights only for points of anchored patches.
constexpr uint32_t kMaxLatticeSpacing = uint32_t(1) << 24;
Status edgebreakerEncodeOnLattice(const TileContext& ctx, const QuantizedMesh& mesh, uint32_t spacing,
                                  std::vector<uint8_t>& out, CodecStats* stats, TileSummary* summary);
Result<QuantizedMesh> edgebreakerDecodeOnLattice(const TileContext& ctx, std::span<const uint8_t> payload,
                                                 const DecodeLimits& limits, uint32_t spacing);
// Per face, the relief (0..5: +x, -x, +y, -y, +z, -z) in whose lattice of `spacing` grid cells it is a unit triangle
// (either orientation; of several, the one whose axis the face's normal is nearest), or -1: the faces prm's coder
// codes as regular (FORMAT.md, "prm").
std::vector<int8_t> latticeFaceReliefs(const QuantizedMesh& mesh, uint32_t spacing);
// `prm`: remeshing and the coder in one (prm.cpp); `stats` as edgebreaker's, with the regularity part.
Result<EncodedTile> prmEncode(const TileContext& ctx, const TileView& tile, const CodecOptions& options);
Result<QuantizedMesh> prmDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                const DecodeLimits& limits);
Status prmEncodeWithStats(const TileContext& ctx, const TileView& tile, const CodecOptions& options,
                          std::vector<uint8_t>& out, CodecStats* stats, TileSummary* summary);
// The lattice spacing a prm v1 payload was coded on (its first field), checked as the decoder checks it.
Result<uint32_t> prmPayloadSpacing(std::span<const uint8_t> payload);
// The lattice spacing prm's options give at `bits`: an even number of grid cells, at least 2.
uint32_t prmSpacing(const PrmOptions& options, int bits);

Status octreeEncodeWithStats(const TileContext& ctx, const QuantizedMesh& mesh, std::vector<uint8_t>& out,
                             CodecStats* stats, const OctreeOptions& options = {}, uint16_t* version = nullptr);

}  // namespace scanpress
