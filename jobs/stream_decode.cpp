#include "jobs/stream_decode.h"

#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <cstring>
#include <memory>
#include <unordered_map>
#include <unordered_set>

#include "engine/codecs/codec.h"
#include "engine/octahedral.h"
#include "jobs/commands.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs/numbers.h"
#include "jobs/scan_store.h"
#include "spatial/weld.h"

namespace scanpress {
namespace {

// Decode memory per vertex and per face of a tile, over every codec's decoder at its peak (bench/RESULTS.md,
// "Streaming decode": measured peaks per codec, rounded up).
constexpr uint64_t kDecodeBytesPerVertex = 160;
constexpr uint64_t kDecodeBytesPerFace = 96;
// The in-memory decode: decoded tiles (20 B/vertex, 12 B/face), the welded copy (same), the weld table (about 64
// B/vertex), the float mesh (40 B/vertex with attributes, 12 B/face).
constexpr uint64_t kInMemoryBytesPerVertex = 20 + 20 + 64 + 40;
constexpr uint64_t kInMemoryBytesPerFace = 12 + 12 + 12;

constexpr uint32_t kUnassigned = UINT32_MAX;
constexpr size_t kBufferBytes = size_t(1) << 20;

// One scratch vertex: what the output writes for it, on the grid.
struct ScratchVertex {
  Vec3u p;
  OctNormal n;
  Rgba8 c;
};
static_assert(sizeof(ScratchVertex) == 20);

struct Bounds {
  Vec3u lo{1, 1, 1}, hi{0, 0, 0};  // empty
  bool empty() const { return lo[0] > hi[0]; }
  bool contains(const Vec3u& p) const {
    return p[0] >= lo[0] && p[1] >= lo[1] && p[2] >= lo[2] && p[0] <= hi[0] && p[1] <= hi[1] && p[2] <= hi[2];
  }
  bool meets(const Bounds& o) const {
    if (empty() || o.empty()) return false;
    for (int a = 0; a < 3; ++a)
      if (o.hi[a] < lo[a] || hi[a] < o.lo[a]) return false;
    return true;
  }
  void add(const Vec3u& p) {
    if (empty()) lo = hi = p;
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
  }
};

// A welded vertex while it can still be used: its output number (once it has one), what its record holds, its
// scalar values, and the sum of its triangles' normals when the attributes are derived.
struct Welded {
  uint32_t owner = 0;   // the tile (decode order) that created it
  bool derive = false;  // its attributes are derived (its owner tile has none of its own)
  uint32_t out = kUnassigned;
  ScratchVertex record{};
  Vec3d normal_sum{0, 0, 0};
  const uint32_t* scalars = nullptr;  // the layout's words: in its tile's mesh, or in `owned`
  std::unique_ptr<uint32_t[]> owned;  // a shared vertex's own copy: its key and record outlive its tile
};

// Scratch records of a fixed size (a ScratchVertex; a vertex's scalar words), appended through a buffer; a record
// already flushed is patched in place.
class RecordFile {
 public:
  explicit RecordFile(size_t record_bytes) : size_(record_bytes) {}
  Status open(const std::string& path) { return file_.open(path); }
  Status append(const void* record) {
    const auto* b = static_cast<const uint8_t*>(record);
    buffer_.insert(buffer_.end(), b, b + size_);
    return buffer_.size() >= kBufferBytes ? flush() : Status::ok();
  }
  // Bytes [offset, offset + len) of record i.
  Status patch(uint64_t i, size_t offset, const void* bytes, size_t len) {
    if (i >= flushed_) {
      std::memcpy(buffer_.data() + (i - flushed_) * size_ + offset, bytes, len);
      return Status::ok();
    }
    return file_.writeAt(i * size_ + offset, bytes, len);
  }
  Status flush() {
    SP_RETURN_IF_ERROR(file_.writeAt(flushed_ * size_, buffer_.data(), buffer_.size()));
    flushed_ += buffer_.size() / size_;
    buffer_.clear();
    return Status::ok();
  }
  // `count` records from `first`, their bytes in `out`.
  Status read(uint64_t first, size_t count, std::vector<uint8_t>& out) const {
    out.resize(count * size_);
    return file_.readAt(first * size_, out.data(), out.size());
  }

 private:
  size_t size_;
  ScratchFile file_;
  std::vector<uint8_t> buffer_;
  uint64_t flushed_ = 0;
};

// Welds decoded tiles one after the other, as weldTiles then cropToBox and deriveAttributes (for the vertices of
// tiles without attributes of their own, `own` by tile in decode order) would on the whole mesh, writing vertex
// records and face bytes as it goes. With `scalars` (a record file of the layout's scalar words per vertex), the
// tiles' scalar values are welded by and written as well; without, the tiles come without them.
class Welder {
 public:
  Welder(const ContainerHeader& header, const std::vector<Bounds>& bounds, bool all_complete, std::vector<uint8_t> own,
         bool point_cloud, const std::optional<std::array<double, 6>>& crop, MeshFileFormat format,
         RecordFile& records, RecordFile* scalars, ScratchFile& faces)
      : grid_(header.grid),
        layout_(header.layout),
        stride_(scalars ? size_t(header.layout.scalarStride()) : 0),
        float_normals_(stride_ && !header.layout.hasNormals() ? losslessNormalsWord(header.layout.scalars)
                                                              : std::nullopt),
        zeros_(stride_, 0),
        scalars_(scalars),
        bounds_(bounds),
        by_(all_complete ? WeldBy::kPositionAndAttributes : WeldBy::kPosition),
        own_(std::move(own)),
        derive_(std::find(own_.begin(), own_.end(), 0) != own_.end()),
        point_cloud_(point_cloud),
        crop_(crop),
        format_(format),
        records_(records),
        faces_(faces),
        near_(bounds.size()),
        evict_(bounds.size()) {
    file_layout_.normals = layout_.hasNormals() || float_normals_.has_value();  // lossless ones are the normals
    file_layout_.color_channels = layout_.color_channels;
    findNeighbours();
  }

  Status add(uint32_t t, const QuantizedMesh& m) {
    const size_t n = m.positions.size();
    local_.clear();
    local_.resize(n);
    ref_.assign(n, nullptr);
    for (size_t v = 0; v < n; ++v) {
      const Vec3u& p = m.positions[v];
      bool before = false;
      uint32_t last = t;
      for (uint32_t j : near_[t])
        if (bounds_[j].contains(p)) {
          if (j < t) before = true;
          else last = std::max(last, j);
        }
      Welded* w = &local_[v];
      if (before || last > t) {
        WeldKey key = weldKey(m, v, by_);
        auto it = shared_.find(key);
        if (it != shared_.end() && it->second.owner != t) {
          ref_[v] = &it->second;
          continue;  // welded to an earlier tile's vertex
        }
        // Found with this tile as owner: a second vertex of one tile at one key stays apart, as in weldTiles.
        if (it == shared_.end() && last > t) {
          std::unique_ptr<uint32_t[]> owned;
          if (stride_) {  // the key and the record outlive the tile: they use the vertex's own copy
            owned = std::make_unique<uint32_t[]>(stride_);
            std::copy_n(m.scalars.data() + v * stride_, stride_, owned.get());
            if (key.s) key.s = owned.get();
          }
          w = &shared_.emplace(key, Welded{}).first->second;
          w->owned = std::move(owned);
          evict_[last].push_back(key);
        }
      }
      w->owner = t;
      if (stride_) w->scalars = w->owned ? w->owned.get() : m.scalars.data() + v * stride_;
      w->derive = !own_[t];
      w->record = ScratchVertex{p, w->derive || m.normals.empty() ? OctNormal{0, 0} : m.normals[v],
                                m.colors.empty() ? Rgba8{0, 0, 0, 0} : m.colors[v]};
      if (w->derive && layout_.hasColors()) w->record.c = Rgba8{128, 128, 128, 255};
      ref_[v] = w;
      if (!crop_ || (point_cloud_ && inside(p))) SP_RETURN_IF_ERROR(emit(*w));
    }
    if (derive_ && (layout_.hasNormals() || float_normals_)) sumNormals(m);
    for (const Triangle& tri : m.triangles) {
      Welded* c[3] = {ref_[tri[0]], ref_[tri[1]], ref_[tri[2]]};
      if (crop_ && !(inside(c[0]->record.p) && inside(c[1]->record.p) && inside(c[2]->record.p))) continue;
      for (Welded* w : c)
        if (w->out == kUnassigned) SP_RETURN_IF_ERROR(emit(*w));
      format_.face(file_layout_, {c[0]->out, c[1]->out, c[2]->out},
                   {grid_.dequantize(c[0]->record.p), grid_.dequantize(c[1]->record.p),
                    grid_.dequantize(c[2]->record.p)},
                   face_bytes_);
      ++file_layout_.faces;
      if (face_bytes_.size() >= kBufferBytes) SP_RETURN_IF_ERROR(flushFaces());
    }
    for (Welded& w : local_)
      if (w.owner == t) SP_RETURN_IF_ERROR(finish(w));  // a local vertex is done with its tile
    for (const WeldKey& key : evict_[t]) {
      auto it = shared_.find(key);
      SP_RETURN_IF_ERROR(finish(it->second));
      shared_.erase(it);
    }
    std::vector<WeldKey>().swap(evict_[t]);  // frees it (`= {}` keeps the capacity: 700 MB at 10^9)
    return Status::ok();
  }

  Status flushFaces() {
    SP_RETURN_IF_ERROR(faces_.writeAt(face_file_bytes_, face_bytes_.data(), face_bytes_.size()));
    face_file_bytes_ += face_bytes_.size();
    face_bytes_.clear();
    return Status::ok();
  }
  MeshFileLayout layout() const { return file_layout_; }
  uint64_t faceFileBytes() const { return face_file_bytes_; }

 private:
  // Tiles whose bounds meet each tile's (sweep along x).
  void findNeighbours() {
    std::vector<uint32_t> order;
    for (uint32_t i = 0; i < bounds_.size(); ++i)
      if (!bounds_[i].empty()) order.push_back(i);
    std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return bounds_[a].lo[0] < bounds_[b].lo[0]; });
    for (size_t i = 0; i < order.size(); ++i)
      for (size_t j = i + 1; j < order.size() && bounds_[order[j]].lo[0] <= bounds_[order[i]].hi[0]; ++j)
        if (bounds_[order[i]].meets(bounds_[order[j]])) {
          near_[order[i]].push_back(order[j]);
          near_[order[j]].push_back(order[i]);
        }
  }
  bool inside(const Vec3u& p) const { return insideBox(grid_.dequantize(p), *crop_); }

  Status emit(Welded& w) {
    if (file_layout_.vertices >= 0x7FFFFFFF)
      return makeError(ErrorCode::kLimitExceeded, "more than 2^31-1 vertices: too many for PLY, OBJ or OFF");
    w.out = static_cast<uint32_t>(file_layout_.vertices++);
    file_layout_.double_positions |= !floatPositionSuffices(w.record.p, grid_);
    SP_RETURN_IF_ERROR(records_.append(&w.record));
    // Derived attributes: scalars 0 (lossless normals are patched in when final), as deriveAttributes.
    return stride_ ? scalars_->append(w.derive ? zeros_.data() : w.scalars) : Status::ok();
  }
  // The vertex's last triangle is in: its derived normal is final.
  Status finish(const Welded& w) {
    if (!w.derive || w.out == kUnassigned) return Status::ok();
    const Vec3d& a = w.normal_sum;
    if (layout_.hasNormals()) {
      const OctNormal n = encodeOctahedral(Vec3f{float(a[0]), float(a[1]), float(a[2])}, layout_.normal_bits);
      SP_RETURN_IF_ERROR(records_.patch(w.out, offsetof(ScratchVertex, n), &n, sizeof n));
    }
    if (float_normals_) {
      const Vec3f n = derivedFloatNormal(a);
      SP_RETURN_IF_ERROR(scalars_->patch(w.out, *float_normals_ * sizeof(uint32_t), n.data(), sizeof n));
    }
    return Status::ok();
  }
  // As deriveAttributes: each triangle's cross product added to its corners, in triangle order.
  void sumNormals(const QuantizedMesh& m) {
    for (const Triangle& t : m.triangles) {
      const Vec3d nrm = triangleCross(m.positions, t);
      for (uint32_t v : t)
        for (int a = 0; a < 3; ++a) ref_[v]->normal_sum[a] += nrm[a];
    }
  }

  const Grid& grid_;
  const AttributeLayout& layout_;
  const size_t stride_;                        // scalar words per vertex welded and written (0: none)
  const std::optional<size_t> float_normals_;  // the lossless normals' first word among them
  const std::vector<uint32_t> zeros_;          // a derived vertex's scalar words
  RecordFile* scalars_;
  const std::vector<Bounds>& bounds_;
  const WeldBy by_;
  const std::vector<uint8_t> own_;
  const bool derive_, point_cloud_;  // derive_: some tile has no attributes of its own
  const std::optional<std::array<double, 6>>& crop_;
  const MeshFileFormat format_;
  RecordFile& records_;
  ScratchFile& faces_;
  std::vector<std::vector<uint32_t>> near_;
  std::vector<std::vector<WeldKey>> evict_;  // keys whose last tile is this one
  std::unordered_map<WeldKey, Welded, WeldKeyHash> shared_;
  std::vector<Welded> local_;
  std::vector<Welded*> ref_;
  MeshFileLayout file_layout_;
  std::string face_bytes_;
  uint64_t face_file_bytes_ = 0;
};

// Consecutive runs of `chosen` to decode together: within half the budget, the rest for welding, buffers and the
// writer; a tile larger than that goes alone, up to three quarters of the budget (the estimate is conservative:
// measured peaks are 0.4-0.8 of it).
// `scalar_stride`: the scalar words per vertex the tiles are decoded with.
Result<std::vector<std::pair<size_t, size_t>>> decodeBatches(const ContainerFile& file,
                                                             const std::vector<const TileEntry*>& chosen,
                                                             uint64_t memory_budget, size_t scalar_stride = 0) {
  const size_t n = chosen.size();
  const uint64_t batch_budget = memory_budget / 2, tile_limit = memory_budget / 4 * 3;
  std::vector<std::pair<size_t, size_t>> batches;
  for (size_t i = 0; i < n;) {
    const uint64_t need = tileDecodeBytes(*chosen[i], scalar_stride);
    if (need > tile_limit)
      return makeError(ErrorCode::kLimitExceeded,
                       file.path() + ": tile " + std::to_string(chosen[i]->tile_id) + " (" +
                           std::to_string(chosen[i]->vertices) + " vertices, " + std::to_string(chosen[i]->faces) +
                           " faces) needs about " + humanBytes(need) +
                           " to decode, more than three quarters of the memory budget of " + humanBytes(memory_budget) +
                           ": give --memory-budget " + std::to_string((need / 3 * 4 >> 20) + 1) + "M or more");
    size_t j = i + 1;
    uint64_t sum = need;
    while (j < n && sum + tileDecodeBytes(*chosen[j], scalar_stride) <= batch_budget)
      sum += tileDecodeBytes(*chosen[j++], scalar_stride);
    batches.push_back({i, j});
    i = j;
  }
  return batches;
}

// Every decoded vertex inside the tile's bounds in the index: what welding and clustering rely on.
Status checkWithinIndexBounds(const ContainerFile& file, const TileEntry& e, const QuantizedMesh& m) {
  const Bounds b{e.lo, e.hi};
  for (const Vec3u& p : m.positions)
    if (!b.contains(p))
      return makeError(ErrorCode::kMalformed, file.path() + ": tile " + std::to_string(e.tile_id) +
                                                  ": a decoded vertex lies outside the index's bounds");
  return Status::ok();
}

}  // namespace

uint64_t tileDecodeBytes(const TileEntry& e, size_t scalar_stride) {
  // Scalar words: held by the decoder (coded and decoded) and by the decoded tile.
  return e.vertices * (kDecodeBytesPerVertex + 3 * 4 * uint64_t(scalar_stride)) + e.faces * kDecodeBytesPerFace;
}

uint64_t inMemoryDecodeBytes(const std::vector<const TileEntry*>& chosen, size_t scalar_stride) {
  uint64_t total = 0, largest = 0;
  for (const TileEntry* e : chosen) {
    total += e->vertices * (kInMemoryBytesPerVertex + 3 * 4 * uint64_t(scalar_stride)) +
             e->faces * kInMemoryBytesPerFace;
    largest = std::max(largest, tileDecodeBytes(*e, scalar_stride));
  }
  return total + largest;
}

Result<std::vector<DecodedTile>> decodeTiles(const ContainerFile& file, std::span<const TileEntry* const> tiles,
                                             std::optional<uint32_t> level) {
  std::vector<DecodedTile> decoded(tiles.size());
  std::vector<Status> errors(tiles.size());
  tbb::parallel_for(size_t(0), tiles.size(), [&](size_t i) {
    try {
      bool done = true, own = true;
      auto m = file.decodeTile(*tiles[i], level, &done, &own);
      decoded[i].complete = done;
      decoded[i].own_attributes = own;
      if (m.isOk()) decoded[i].mesh = std::move(m).value();
      else errors[i] = m.status();
    } catch (const std::exception& e) {
      errors[i] = makeError(ErrorCode::kInternal,
                            file.path() + ": tile " + std::to_string(tiles[i]->tile_id) + ": " + e.what());
    }
  });
  for (const Status& e : errors) SP_RETURN_IF_ERROR(e);
  return decoded;
}

Result<Mesh> decodeClustered(const ContainerFile& file, uint32_t cells, uint64_t memory_budget) {
  std::vector<const TileEntry*> chosen;
  Bounds all;
  for (const TileEntry& e : file.tiles())
    if (e.vertices > 0) {
      chosen.push_back(&e);
      all.add(e.lo);
      all.add(e.hi);
    }
  SP_ASSIGN_OR_RETURN(auto batches,
                      decodeBatches(file, chosen, memory_budget, size_t(file.header().layout.scalarStride())));
  const ContainerHeader& header = file.header();
  Mesh out;
  if (chosen.empty()) return out;
  uint32_t extent = 1;
  for (int a = 0; a < 3; ++a) extent = std::max(extent, all.hi[a] - all.lo[a] + 1);
  cells = std::clamp(cells, 1u, 127u);  // cluster ids stay under 2^21: three make one triangle key
  const double size = std::max(1.0, double(extent) / cells);  // grid cells per cluster cell
  std::unordered_map<uint64_t, uint32_t> cluster;
  std::unordered_set<uint64_t> seen;  // triangles by their sorted cluster ids (< 2^21 each)
  std::vector<uint32_t> of;
  std::vector<Vec3d> sum;  // per cluster: the sum of its vertices (each tile's copy of a border vertex too)
  std::vector<uint32_t> count;
  for (auto [a, b] : batches) {
    SP_ASSIGN_OR_RETURN(auto tiles, decodeTiles(file, std::span(chosen).subspan(a, b - a), std::nullopt));
    for (size_t i = 0; i < tiles.size(); ++i) {
      const QuantizedMesh& m = tiles[i].mesh;
      SP_RETURN_IF_ERROR(checkWithinIndexBounds(file, *chosen[a + i], m));
      of.resize(m.positions.size());
      for (size_t v = 0; v < m.positions.size(); ++v) {
        uint64_t key = 0;
        for (int k = 0; k < 3; ++k) key = key << 21 | uint64_t((m.positions[v][k] - all.lo[k]) / size);
        auto [it, inserted] = cluster.try_emplace(key, uint32_t(sum.size()));
        if (inserted) sum.push_back({0, 0, 0}), count.push_back(0);
        const Vec3d p = header.grid.dequantize(m.positions[v]);
        for (int k = 0; k < 3; ++k) sum[it->second][k] += p[k];
        ++count[it->second];
        of[v] = it->second;
      }
      for (const Triangle& tri : m.triangles) {
        Triangle c{of[tri[0]], of[tri[1]], of[tri[2]]};
        if (c[0] == c[1] || c[1] == c[2] || c[0] == c[2]) continue;
        std::array<uint32_t, 3> s = c;
        std::sort(s.begin(), s.end());
        if (seen.insert(uint64_t(s[0]) << 42 | uint64_t(s[1]) << 21 | s[2]).second) out.triangles.push_back(c);
      }
    }
  }
  out.positions.resize(sum.size());
  for (size_t c = 0; c < sum.size(); ++c)
    for (int k = 0; k < 3; ++k) out.positions[c][k] = sum[c][k] / count[c];
  return out;
}

Result<StreamDecodeResult> streamDecode(const ContainerFile& file, const std::vector<const TileEntry*>& chosen,
                                        const std::string& output, const StreamDecodeSettings& settings) {
  SP_ASSIGN_OR_RETURN(MeshFileFormat format, MeshFileFormat::forPath(output));
  const ContainerHeader& header = file.header();
  const size_t n = chosen.size();
  const size_t stride = settings.scalars ? size_t(header.layout.scalarStride()) : 0;
  // The tiles decode with every channel, whether or not the output writes them.
  SP_ASSIGN_OR_RETURN(auto batches,
                      decodeBatches(file, chosen, settings.memory_budget, size_t(header.layout.scalarStride())));

  // Where each tile's vertices lie, whether every tile is complete, whether the decode is a point cloud. From the
  // index for a complete decode; a coarse level is decoded once to measure them.
  std::vector<Bounds> bounds(n);
  bool all_complete = true;
  std::vector<uint8_t> own(n, 1);
  uint64_t total_faces = 0;
  if (settings.level) {
    for (auto [a, b] : batches) {
      SP_ASSIGN_OR_RETURN(auto tiles, decodeTiles(file, std::span(chosen).subspan(a, b - a), settings.level));
      for (size_t i = a; i < b; ++i) {
        for (const Vec3u& p : tiles[i - a].mesh.positions) bounds[i].add(p);
        all_complete &= tiles[i - a].complete;
        own[i] = tiles[i - a].own_attributes;
        total_faces += tiles[i - a].mesh.triangles.size();
      }
    }
  } else {
    for (size_t i = 0; i < n; ++i) {
      const TileEntry& e = *chosen[i];
      if (e.vertices > 0) bounds[i] = Bounds{e.lo, e.hi};
      const CodecInfo* codec = findCodec(e.codec);
      all_complete &= !codec || codec->keepsAttributes(e.codec_version);
      own[i] = !codec || codec->showsOwnAttributes(e.codec_version, false, false);
      total_faces += e.faces;
    }
  }

  SP_ASSIGN_OR_RETURN(ScratchDir scratch, ScratchDir::create(settings.scratch_parent));
  RecordFile records(sizeof(ScratchVertex)), scalar_records(stride * sizeof(uint32_t));
  ScratchFile faces;
  SP_RETURN_IF_ERROR(records.open(scratch.file("vertices")));
  if (stride) SP_RETURN_IF_ERROR(scalar_records.open(scratch.file("scalars")));
  SP_RETURN_IF_ERROR(faces.open(scratch.file("faces")));
  Welder welder(header, bounds, all_complete, std::move(own), total_faces == 0, settings.crop, format, records,
                stride ? &scalar_records : nullptr, faces);
  for (auto [a, b] : batches) {
    SP_ASSIGN_OR_RETURN(auto tiles, decodeTiles(file, std::span(chosen).subspan(a, b - a), settings.level));
    for (size_t i = a; i < b; ++i) {
      QuantizedMesh& m = tiles[i - a].mesh;
      // An output that writes no scalar channel: the weld ignores them, as the in-memory decode's does then.
      if (!stride) m.scalars.clear();
      if (!settings.level) SP_RETURN_IF_ERROR(checkWithinIndexBounds(file, *chosen[i], m));
      SP_RETURN_IF_ERROR(welder.add(static_cast<uint32_t>(i), m));
      tiles[i - a].mesh = QuantizedMesh();
    }
  }
  SP_RETURN_IF_ERROR(records.flush());
  if (stride) SP_RETURN_IF_ERROR(scalar_records.flush());
  SP_RETURN_IF_ERROR(welder.flushFaces());

  MeshFileLayout layout = welder.layout();
  // As dequantizeMesh and the writers: lossless normals (float channels nx, ny, nz) are the normals; PLY writes the
  // other channels.
  size_t float_word = SIZE_MAX;  // the first word of the lossless normals (SIZE_MAX: none)
  if (stride && !header.layout.hasNormals())
    if (const auto word = losslessNormalsWord(header.layout.scalars)) float_word = *word;
  const bool float_normals = float_word != SIZE_MAX;
  if (stride && format.kind() == MeshFileFormat::Kind::kPly)
    layout.scalars = float_normals ? channelsBesideLosslessNormals(header.layout.scalars, float_word)
                                   : header.layout.scalars;
  if (layout.vertices == 0) layout.normals = false, layout.color_channels = 0;  // as the in-memory writers do
  layout.materials = settings.materials;
  SP_ASSIGN_OR_RETURN(auto writer, MeshFileWriter::create(output, layout, format));
  if (format.indexed()) {
    std::vector<uint8_t> chunk, scalar_chunk;
    std::vector<uint32_t> words(stride), out_words;
    const size_t per_chunk = kBufferBytes / (sizeof(ScratchVertex) + stride * sizeof(uint32_t));
    for (uint64_t first = 0; first < layout.vertices; first += per_chunk) {
      const size_t count = size_t(std::min<uint64_t>(per_chunk, layout.vertices - first));
      SP_RETURN_IF_ERROR(records.read(first, count, chunk));
      if (stride) SP_RETURN_IF_ERROR(scalar_records.read(first, count, scalar_chunk));
      for (size_t i = 0; i < count; ++i) {
        ScratchVertex r;
        std::memcpy(&r, chunk.data() + i * sizeof r, sizeof r);
        if (stride) std::memcpy(words.data(), scalar_chunk.data() + i * stride * sizeof(uint32_t), stride * 4);
        Vec3f normal{};
        if (float_normals)
          for (size_t k = 0; k < 3; ++k) normal[k] = std::bit_cast<float>(words[float_word + k]);
        else if (layout.normals) normal = decodeOctahedral(r.n, header.layout.normal_bits);
        const uint32_t* written = words.data();  // the words of layout.scalars
        if (float_normals && !layout.scalars.empty()) {
          out_words.clear();
          appendWordsBesideLosslessNormals(words.data(), stride, float_word, out_words);
          written = out_words.data();
        }
        SP_RETURN_IF_ERROR(writer->vertex(header.grid.dequantize(r.p), layout.normals ? &normal : nullptr,
                                          layout.color_channels ? &r.c : nullptr,
                                          layout.scalars.empty() ? nullptr : written));
      }
    }
  }
  std::vector<uint8_t> bytes;
  for (uint64_t at = 0; at < welder.faceFileBytes(); at += kBufferBytes) {
    const size_t len = size_t(std::min<uint64_t>(kBufferBytes, welder.faceFileBytes() - at));
    bytes.resize(len);
    SP_RETURN_IF_ERROR(faces.readAt(at, bytes.data(), len));
    SP_RETURN_IF_ERROR(writer->faceBytes(bytes, at + len == welder.faceFileBytes() ? layout.faces : 0));
  }
  SP_RETURN_IF_ERROR(writer->commit());
  StreamDecodeResult result;
  result.vertices = layout.vertices;
  result.faces = layout.faces;
  result.double_positions = layout.double_positions;
  result.batches = static_cast<uint32_t>(batches.size());
  return result;
}

}  // namespace scanpress
