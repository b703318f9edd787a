// The encode pipeline for one scan, in named steps: see jobs/pipeline.h.
#include "jobs/pipeline.h"

#include <oneapi/tbb/flow_graph.h>
#include <oneapi/tbb/global_control.h>
#include <oneapi/tbb/info.h>
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <new>
#include <numeric>
#include <optional>

#include "engine/container/container.h"
#include "engine/geometry.h"
#include "engine/metro.h"
#include "engine/octahedral.h"
#include "engine/tile.h"
#include "jobs/errors.h"
#include "jobs/file_io.h"
#include "jobs/mesh_io/async_sink.h"
#include "jobs/process.h"
#include "jobs/scan_store.h"
#include "jobs/remote_tiles.h"
#include "jobs/targets.h"
#include "jobs/tile_work.h"
#include "spatial/surface_index.h"
#include "spatial/tile_builder.h"
#include "spatial/tiling.h"

namespace scanpress {

// Memory plan constants (measured; bench/RESULTS.md has the figures).
namespace {

// Per channel: whether it is one of a pair of texture coordinates (findTexcoords; every pair, not only the first).
std::vector<bool> texcoordChannels(std::span<const ScalarChannel> channels) {
  std::vector<bool> out(channels.size(), false);
  std::vector<ScalarChannel> rest(channels.begin(), channels.end());
  std::vector<size_t> index(channels.size());
  std::iota(index.begin(), index.end(), size_t{0});
  while (const auto tc = findTexcoords(rest)) {
    out[index[tc->u]] = out[index[tc->v]] = true;
    for (const size_t i : {std::max(tc->u, tc->v), std::min(tc->u, tc->v)}) {
      rest.erase(rest.begin() + ptrdiff_t(i));
      index.erase(index.begin() + ptrdiff_t(i));
    }
  }
  return out;
}

// The survey keeps the mesh for the ingest pass only while it is this small: a large mesh held in doubles costs
// more in memory traffic and page faults than parsing the file again. A binary PLY is never kept: reading it again
// costs less than keeping it at any size (bench/RESULTS.md, "Encode on two threads").
constexpr uint64_t kKeepLimit = 256ull << 20;
// Without a budget, tile data up to half of this stays in memory; beyond that, scratch files are faster as well as
// smaller. Only where the data lives changes: the tiles, hence the bytes, depend on an explicit budget only.
constexpr uint64_t kAutoStorageBudget = 2ull << 30;
// Smallest tile target a memory budget can lower the configured one to.
constexpr uint64_t kMinBudgetTileTarget = 4096;

}  // namespace

uint64_t effectiveTileTarget(const EncodeSettings& s) {
  uint64_t target = std::max<uint64_t>(1, s.tile_triangles);
  if (s.memory_budget > 0)
    target = std::min(target, std::max<uint64_t>(kMinBudgetTileTarget, s.memory_budget / 8 / kTileBytesPerTriangle));
  return target;
}

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

// Pass 1: bounds, counts, attributes; keeps the mesh while it fits in `keep_limit` bytes.
class SurveySink : public MeshSink {
 public:
  explicit SurveySink(uint64_t keep_limit) : keep_limit_(keep_limit) {}
  Status vertices(std::span<const Vec3d> p, std::span<const Vec3f> n, std::span<const Rgba8> c, uint8_t channels,
                  const ScalarChunk& s) override {
    for (const auto& v : p) box.extend(v);
    vertex_count += p.size();
    has_normals |= !n.empty();
    if (!c.empty()) channels_ = std::max(channels_, channels);
    if (scalar_channels.empty()) scalar_channels.assign(s.channels.begin(), s.channels.end());
    if (kept()) SP_RETURN_IF_ERROR(collector_.vertices(p, n, c, channels, s));
    checkLimit();
    return Status::ok();
  }
  Status triangles(std::span<const Triangle> t) override {
    triangle_count += t.size();
    // Readers deliver a triangle after its vertices: the bitmap covers every index seen so far.
    if (used_.size() * 64 < vertex_count) used_.resize((vertex_count + 63) / 64, 0);
    for (const Triangle& tri : t)
      for (uint32_t v : tri)
        if (v < vertex_count) used_[v >> 6] |= uint64_t(1) << (v & 63);
    if (kept()) SP_RETURN_IF_ERROR(collector_.triangles(t));
    checkLimit();
    return Status::ok();
  }
  Status vertexNormals(uint64_t first, std::span<const Vec3f> n) override {
    has_normals = true;
    return kept() ? collector_.vertexNormals(first, n) : Status::ok();
  }
  bool kept() const { return !dropped_; }
  uint8_t colorChannels() const { return channels_; }
  // Which vertices some triangle uses (bit i of word i / 64); one bit per vertex, so 125 MB for 10^9 vertices.
  const std::vector<uint64_t>& used() const { return used_; }
  uint64_t usedCount() const {
    uint64_t n = 0;
    for (uint64_t w : used_) n += static_cast<uint64_t>(std::popcount(w));
    return n;
  }
  // The kept mesh, with every attribute array covering every vertex (only when kept()).
  Mesh& keptMesh() {
    collector_.finish();
    return mesh_;
  }
  void releaseMesh() { mesh_ = Mesh(); }

  BoundingBox box;
  uint64_t vertex_count = 0, triangle_count = 0;
  bool has_normals = false;
  std::vector<ScalarChannel> scalar_channels;  // the file's

 private:
  void checkLimit() {
    if (dropped_) return;
    const uint64_t bytes = mesh_.positions.size() * sizeof(Vec3d) + mesh_.normals.size() * sizeof(Vec3f) +
                           mesh_.colors.size() * sizeof(Rgba8) + mesh_.triangles.size() * sizeof(Triangle) +
                           mesh_.scalars.size() * sizeof(uint32_t);
    if (bytes > keep_limit_) {
      dropped_ = true;
      mesh_ = Mesh();
    }
  }
  uint64_t keep_limit_;
  bool dropped_ = false;
  uint8_t channels_ = 0;
  std::vector<uint64_t> used_;
  Mesh mesh_;
  MeshCollector collector_{mesh_};
};

// The box of the vertices a triangle uses (`used`, from the survey), over a replay or a second read of the input.
// Once `vertex_count` vertices are seen, it stops the read (a reader delivers vertices before the triangles that
// use them, so only the vertex part of a PLY is parsed again): `complete` tells that stop from a failure.
class UsedBoxSink : public MeshSink {
 public:
  UsedBoxSink(const std::vector<uint64_t>& used, uint64_t vertex_count) : used_(used), vertex_count_(vertex_count) {}
  Status vertices(std::span<const Vec3d> p, std::span<const Vec3f>, std::span<const Rgba8>, uint8_t,
                  const ScalarChunk&) override {
    for (const Vec3d& v : p) {
      if (next_ >> 6 < used_.size() && (used_[next_ >> 6] >> (next_ & 63) & 1)) box.extend(v);
      ++next_;
    }
    if (next_ < vertex_count_) return Status::ok();
    complete = true;
    return makeError(ErrorCode::kInternal, "stop: every vertex seen");
  }
  Status triangles(std::span<const Triangle>) override { return Status::ok(); }
  Status vertexNormals(uint64_t, std::span<const Vec3f>) override { return Status::ok(); }

  BoundingBox box;
  bool complete = false;

 private:
  const std::vector<uint64_t>& used_;
  uint64_t vertex_count_;
  uint64_t next_ = 0;
};

// A triangle that quantization made degenerate (two corners in one cell): dropped.
bool collapses(const VertexRecord (&r)[3]) { return r[0].q == r[1].q || r[1].q == r[2].q || r[0].q == r[2].q; }

// Pass 2: quantize into the store, drop degenerate triangles, valences, histogram, spill.
class IngestSink : public MeshSink {
 public:
  // `points`: a point cloud, whose every vertex is tiled by its position, as a triangle (v, v, v) would be.
  // `spill`: nullptr out of core, where the tile pass reads the input again instead (KeptTriangles).
  // `input` names the scan in errors.
  IngestSink(const std::string& input, const Grid& grid, const AttributeLayout& layout, VertexStore& store,
             TileHistogram& hist, TriangleSpill* spill, bool points)
      : input_(input),
        grid_(grid),
        layout_(layout),
        store_(store),
        hist_(hist),
        spill_(spill),
        points_(points),
        normal_word_(layout.hasNormals() ? std::nullopt : losslessNormalsWord(layout.scalars)) {}
  static Vec3d originalOf(const VertexRecord& r) { return {r.original[0], r.original[1], r.original[2]}; }
  Status vertices(std::span<const Vec3d> p, std::span<const Vec3f> n, std::span<const Rgba8> c, uint8_t,
                  const ScalarChunk& s) override {
    const OctNormal no_normal = encodeOctahedral({0, 0, 0}, layout_.hasNormals() ? layout_.normal_bits : 8);
    if (layout_.hasScalars() && picks_.empty()) SP_RETURN_IF_ERROR(pickScalars(s.channels));
    const size_t in_stride = scalarWords(s.channels);
    if (layout_.hasScalars() && s.values.size() != p.size() * in_stride)
      return makeError(ErrorCode::kInternal, "scalar values do not match the vertices");
    for (size_t i = 0; i < p.size(); ++i) {
      if (layout_.hasScalars()) {
        row_.clear();
        for (const auto& [offset, words] : picks_)
          for (size_t w = 0; w < words; ++w) row_.push_back(s.values[i * in_stride + offset + w]);
        if (normal_word_) {  // lossless normals (OBJ's arrive later, through vertexNormals)
          const Vec3f normal = n.empty() ? Vec3f{0, 0, 0} : n[i];
          row_.insert(row_.begin() + ptrdiff_t(*normal_word_),
                      {std::bit_cast<uint32_t>(normal[0]), std::bit_cast<uint32_t>(normal[1]),
                       std::bit_cast<uint32_t>(normal[2])});
        }
        if (Status snap = snapScalarRow(layout_.scalars, row_.data(), store_.size()); !snap.isOk())
          return snap.withContext(input_);
        store_.appendScalars(row_);
      }
      VertexRecord r;
      r.q = grid_.quantize(p[i]);
      for (int a = 0; a < 3; ++a) r.original[a] = static_cast<float>(p[i][a] - grid_.origin[a]);
      if (layout_.hasNormals()) r.normal = n.empty() ? no_normal : encodeOctahedral(n[i], layout_.normal_bits);
      if (layout_.hasColors() && !c.empty()) r.color = quantizeColor(c[i], layout_);
      if (points_) {
        const uint32_t v = static_cast<uint32_t>(store_.size());
        hist_.add(r.q);
        if (spill_) SP_RETURN_IF_ERROR(spill_->append({{v, v, v}, r.q}));
        ++referenced;
      }
      SP_RETURN_IF_ERROR(store_.append(r));
    }
    return Status::ok();
  }
  Status triangles(std::span<const Triangle> tris) override {
    VertexRecord r[3];
    for (const Triangle& t : tris) {
      for (int k = 0; k < 3; ++k) SP_RETURN_IF_ERROR(store_.get(t[k], r[k]));
      if (collapses(r)) {
        ++stats.degenerate_triangles;
        input_degenerate += t[0] == t[1] || t[1] == t[2] || t[0] == t[2];
        continue;
      }
      for (uint32_t v : t) {
        bool first = false;
        SP_RETURN_IF_ERROR(store_.bumpValence(v, first));
        referenced += first;
      }
      area += triangleArea(originalOf(r[0]), originalOf(r[1]), originalOf(r[2]));
      const Vec3u c = triangleCentroid(r[0].q, r[1].q, r[2].q);
      hist_.add(c);
      ++kept;
      if (spill_) SP_RETURN_IF_ERROR(spill_->append({t, c}));
    }
    return Status::ok();
  }
  Status vertexNormals(uint64_t first, std::span<const Vec3f> n) override {
    if (normal_word_) {
      const size_t stride = size_t(layout_.scalarStride());
      for (size_t i = 0; i < n.size(); ++i)
        if (!std::isnan(n[i][0])) {
          const uint32_t words[3] = {std::bit_cast<uint32_t>(n[i][0]), std::bit_cast<uint32_t>(n[i][1]),
                                     std::bit_cast<uint32_t>(n[i][2])};
          SP_RETURN_IF_ERROR(store_.setScalars(first + i, stride, *normal_word_, words));
        }
      return Status::ok();
    }
    if (!layout_.hasNormals()) return Status::ok();
    for (size_t i = 0; i < n.size(); ++i)
      if (!std::isnan(n[i][0]))
        SP_RETURN_IF_ERROR(store_.setNormal(first + i, encodeOctahedral(n[i], layout_.normal_bits)));
    return Status::ok();
  }

  // Where each of the layout's scalar channels sits in the reader's rows (by name and type): the survey found
  // them all, so a miss means the file changed between the reads.
  Status pickScalars(std::span<const ScalarChannel> channels) {
    // (The lossless normals' channels are the reader's normals, not its channels.)
    const std::span<const ScalarChannel> wanted(layout_.scalars.data(),
                                                layout_.scalars.size() - (normal_word_ ? 3 : 0));
    auto picks = pickScalarChannels(channels, wanted);
    if (!picks.isOk())
      return makeError(ErrorCode::kIo, "the file changed between the reads: " + picks.status().message());
    picks_ = std::move(picks).value();
    return Status::ok();
  }

  QuantizeStats stats;
  uint64_t input_degenerate = 0;  // of the degenerate triangles, those with a repeated index (no grid keeps them)
  uint64_t referenced = 0;        // vertices encoded: used by a kept triangle, or points
  uint64_t kept = 0;              // triangles kept
  double area = 0;                // of the kept triangles, original positions

 private:
  const std::string& input_;
  const Grid& grid_;
  const AttributeLayout& layout_;
  VertexStore& store_;
  TileHistogram& hist_;
  TriangleSpill* spill_;
  bool points_;
  std::vector<std::pair<size_t, size_t>> picks_;  // (word offset in the reader's row, words) per layout channel
  std::optional<size_t> normal_word_;             // lossless normals: their first word in a row
  std::vector<uint32_t> row_;
};

// Out of core, the tile pass's source of the kept triangles (or a point cloud's points, as (v, v, v)), in input
// order with their centroids, from another read of the input and the vertex store: what the ingest pass kept,
// exactly. Instead of a spill file of 24 bytes per triangle (the largest part of the scratch disk; bench/RESULTS.md,
// "Scale"), the input is read once per round, which costs less than writing and reading the spill.
class KeptTriangles : public MeshSink {
 public:
  KeptTriangles(VertexStore& store, bool points, std::function<Status(const SpilledTriangle&)> fn)
      : store_(store), points_(points), fn_(std::move(fn)) {}
  Status vertices(std::span<const Vec3d> p, std::span<const Vec3f>, std::span<const Rgba8>, uint8_t,
                  const ScalarChunk&) override {
    if (!points_) return Status::ok();
    VertexRecord r;
    for (size_t i = 0; i < p.size(); ++i, ++next_vertex_) {
      const uint32_t v = static_cast<uint32_t>(next_vertex_);
      SP_RETURN_IF_ERROR(store_.get(v, r));
      SP_RETURN_IF_ERROR(fn_({{v, v, v}, r.q}));
      ++delivered;
    }
    return Status::ok();
  }
  Status triangles(std::span<const Triangle> tris) override {
    VertexRecord r[3];
    for (const Triangle& t : tris) {
      for (int k = 0; k < 3; ++k) SP_RETURN_IF_ERROR(store_.get(t[k], r[k]));
      if (collapses(r)) continue;
      SP_RETURN_IF_ERROR(fn_({t, triangleCentroid(r[0].q, r[1].q, r[2].q)}));
      ++delivered;
    }
    return Status::ok();
  }
  Status vertexNormals(uint64_t, std::span<const Vec3f>) override { return Status::ok(); }

  uint64_t delivered = 0;

 private:
  VertexStore& store_;
  bool points_;
  std::function<Status(const SpilledTriangle&)> fn_;
  uint64_t next_vertex_ = 0;
};

// Feeds a buffered mesh to a sink in chunks, as a reader would.
Status replay(const Mesh& m, MeshSink& sink, size_t chunk) {
  for (size_t i = 0; i < m.positions.size(); i += chunk) {
    const size_t n = std::min(chunk, m.positions.size() - i);
    const size_t stride = scalarWords(m.scalar_channels);
    const ScalarChunk scalars{m.scalar_channels, stride ? std::span(m.scalars).subspan(i * stride, n * stride)
                                                        : std::span<const uint32_t>()};
    SP_RETURN_IF_ERROR(sink.vertices(std::span(m.positions).subspan(i, n),
                                     m.normals.empty() ? std::span<const Vec3f>() : std::span(m.normals).subspan(i, n),
                                     m.colors.empty() ? std::span<const Rgba8>() : std::span(m.colors).subspan(i, n),
                                     m.color_channels, scalars));
  }
  for (size_t i = 0; i < m.triangles.size(); i += chunk)
    SP_RETURN_IF_ERROR(sink.triangles(std::span(m.triangles).subspan(i, std::min(chunk, m.triangles.size() - i))));
  return Status::ok();
}

struct TileJob {
  uint32_t tile = 0;
};

// One scan's encode: the steps of jobs/pipeline.h as methods, sharing the scan's state.
class ScanEncoder {
 public:
  ScanEncoder(const EncodeSettings& s, const CodecInfo& codec, ProgressListener* progress,
              std::shared_ptr<EmbreeDevice> device, const PipelineHooks* hooks)
      : s_(s),
        codec_(codec),
        progress_(progress),
        device_(std::move(device)),
        hooks_(hooks),
        survey_(cheapToReadAgain(s.input)
                    ? 0
                    : std::min(kKeepLimit, s.memory_budget == 0 ? UINT64_MAX : s.memory_budget / 3)) {
    result_.codec = codec.name;
    for (const StageSpec& st : s.stages) result_.stages.emplace_back(findStage(st.kind)->name);
    result_.threads = s.threads > 0 ? s.threads : tbb::info::default_concurrency();
  }

  // Pass 1 over the input: bounds, counts, attributes; the grid.
  Status survey() {
    stage("reading");
    SP_ASSIGN_OR_RETURN(result_.read, readInput(survey_));
    const bool lossless_normals = s_.keep_normals && survey_.has_normals && s_.lossless_normals;
    if (lossless_normals && !keepsScanVertices())
      return makeError(ErrorCode::kInvalidArgument,
                       s_.input +
                           ": --lossless-normals needs a codec that keeps the scan's vertices (store, kdtree, "
                           "octree, edgebreaker, pm) and no remesh stage: " +
                           droppedBy() + " makes new ones, whose normals would be resampled");
    if (lossless_normals && result_.read.double_normals)
      return makeError(ErrorCode::kInvalidArgument,
                       s_.input + ": --lossless-normals keeps float normals bit for bit; this PLY's are double");
    if (s_.keep_normals && survey_.has_normals && !lossless_normals)
      result_.layout.normal_bits = static_cast<uint8_t>(s_.normal_bits);
    if (s_.keep_colors && survey_.colorChannels()) {
      result_.layout.color_channels = survey_.colorChannels();
      result_.layout.color_bits = static_cast<uint8_t>(s_.color_bits);
    }
    if (s_.keep_scalars) {
      result_.layout.scalars = survey_.scalar_channels;
      // prm and the remesh stage resample: they keep no texture seam, so texture coordinates are dropped (checkDrops
      // lists them), the other channels kept.
      if (!codecKeepsWedges()) {
        const std::vector<bool> texcoords = texcoordChannels(result_.layout.scalars);
        for (size_t i = texcoords.size(); i-- > 0;)
          if (texcoords[i]) result_.layout.scalars.erase(result_.layout.scalars.begin() + ptrdiff_t(i));
      }
      if (const auto tc = findTexcoords(result_.layout.scalars); tc && s_.uv_bits > 0)
        for (size_t ch : {tc->u, tc->v}) result_.layout.scalars[ch].bits = static_cast<uint8_t>(s_.uv_bits);
    }
    // A PLY's texture image is kept with the texture coordinates it belongs to.
    if (!result_.read.materials.texture.empty() && !findTexcoords(result_.layout.scalars)) {
      result_.read.dropped.push_back({"ply comment TextureFile (its texture coordinates are not kept)", 1});
      result_.read.materials.texture.clear();
    }
    if (lossless_normals) {
      for (const ScalarChannel& c : result_.layout.scalars)
        for (const ScalarChannel& n : kLosslessNormalChannels)
          if (c.name == n.name)
            return makeError(ErrorCode::kInvalidArgument,
                             s_.input + ": --lossless-normals: the scan has a channel named " + c.name + " already");
      if (result_.layout.scalars.size() + 3 > 255)
        return makeError(ErrorCode::kLimitExceeded, s_.input + ": --lossless-normals: the scan's " +
                                                        std::to_string(result_.layout.scalars.size()) +
                                                        " scalar channels and the normals' three exceed 255");
      result_.layout.scalars.insert(result_.layout.scalars.end(), kLosslessNormalChannels.begin(),
                                    kLosslessNormalChannels.end());
    }
    result_.point_cloud = survey_.triangle_count == 0 && survey_.vertex_count > 0;
    SP_ASSIGN_OR_RETURN(const BoundingBox box, gridBox());
    auto grid = makeGrid(box, s_.bits);
    if (!grid.isOk()) return grid.status().withContext(s_.input);
    result_.grid = *grid;
    result_.diagonal = box.diagonal();
    result_.seconds.read = clock_.lap();
    return Status::ok();
  }

  // The box the grid spans: of the vertices that triangles use, so that vertices no triangle uses (dropped anyway)
  // cannot stretch the grid (one stray vertex far away made nearly every triangle degenerate); a point cloud's box
  // is of all its points. Only when some vertex is unused: the kept mesh is replayed, or a streamed scan's vertex
  // part is read once more. Measured (bench/RESULTS.md, "Unused vertices"): a 3M-triangle binary PLY streamed
  // under a 64 MiB budget, read pass 0.98 s -> 1.34 s with one stray vertex (encode 7.4 s either way), peak RSS
  // +0.3 MiB; the survey's bitmap costs one bit per vertex. Keeping float positions in the scratch store would
  // cost 12 bytes per vertex instead.
  Result<BoundingBox> gridBox() {
    if (survey_.triangle_count == 0 || survey_.usedCount() == survey_.vertex_count) return survey_.box;
    UsedBoxSink used(survey_.used(), survey_.vertex_count);
    Status read = survey_.kept() ? replay(survey_.keptMesh(), used, ReadOptions().chunk)
                                 : readMesh(s_.input, used, readOptions()).status();
    if (!used.complete) {
      if (!read.isOk()) return read;
      return makeError(ErrorCode::kIo, s_.input + ": file changed between the two passes");
    }
    return used.box;
  }

  // Where tile data lives (memory or scratch files), then pass 2: quantization into the store.
  Status ingest() {
    const uint64_t n_vertices = survey_.vertex_count, n_triangles = survey_.triangle_count;
    // A point cloud's points go through the spill and the bins as triangles (v, v, v) at their own positions.
    const uint64_t n_items = result_.point_cloud ? n_vertices : n_triangles;
    // Scalar channels stay in memory (4 bytes per value), whatever the budget: counted here so that the rest goes
    // out of core sooner.
    const uint64_t in_memory_bytes = n_vertices * sizeof(VertexRecord) +
                                     n_items * (sizeof(SpilledTriangle) + sizeof(Triangle)) +
                                     n_vertices * uint64_t(result_.layout.scalarStride()) * sizeof(uint32_t);
    storage_budget_ = s_.memory_budget > 0 ? s_.memory_budget : kAutoStorageBudget;
    in_memory_ = in_memory_bytes <= storage_budget_ / 2;
    result_.out_of_core = !in_memory_;
    target_ = effectiveTileTarget(s_);  // independent of the thread count: so are the bytes
    if (!in_memory_) {
      SP_ASSIGN_OR_RETURN(ScratchDir dir, ScratchDir::create(s_.scratch_dir));
      scratch_.emplace(std::move(dir));
    }
    stage("quantizing");
    store_.emplace(scratchFile("vertices.bin"), in_memory_ ? UINT64_MAX / 2 : storage_budget_ / 4);
    histogram_.emplace(result_.grid.bits, n_items, target_);
    if (in_memory_) spill_.emplace(std::string(), true, n_items);
    IngestSink ingest(s_.input, result_.grid, result_.layout, *store_, *histogram_, spill_ ? &*spill_ : nullptr,
                      result_.point_cloud);
    if (survey_.kept()) {
      SP_RETURN_IF_ERROR(replay(survey_.keptMesh(), ingest, ReadOptions().chunk));
      survey_.releaseMesh();
    } else {
      auto again = readInput(ingest);
      if (!again.isOk()) return again.status();
      if (again->vertices != n_vertices || again->triangles != n_triangles)
        return makeError(ErrorCode::kIo, s_.input + ": file changed between the two passes");
    }
    if (spill_) SP_RETURN_IF_ERROR(spill_->finish());
    result_.quantize = ingest.stats;
    result_.quantize.unreferenced_vertices = n_vertices - ingest.referenced;
    result_.vertices = ingest.referenced;
    result_.faces = result_.point_cloud ? 0 : ingest.kept;
    kept_items_ = result_.point_cloud ? n_vertices : ingest.kept;
    SP_RETURN_IF_ERROR(checkDegenerate(n_triangles, ingest.stats.degenerate_triangles - ingest.input_degenerate));
    area_ = ingest.area;
    result_.seconds.quantize = clock_.lap();
    return Status::ok();
  }

  // Octree tiles from the histogram, then the triangles binned by tile.
  Status tile() {
    stage("tiling");
    std::vector<SpilledTriangle> chunk(1u << 16);
    // The kept triangles in input order: from the spill in memory, or out of core from the input read again.
    auto forEachSpilled = [&](auto&& fn) -> Status {
      if (!spill_) {
        KeptTriangles again(*store_, result_.point_cloud, fn);
        auto read = readInput(again);
        if (!read.isOk()) return read.status();
        if (read->vertices != survey_.vertex_count || read->triangles != survey_.triangle_count ||
            again.delivered != kept_items_)
          return makeError(ErrorCode::kIo, s_.input + ": file changed between the passes");
        return Status::ok();
      }
      for (uint64_t first = 0; first < spill_->size(); first += chunk.size()) {
        const size_t n = static_cast<size_t>(std::min<uint64_t>(chunk.size(), spill_->size() - first));
        SP_RETURN_IF_ERROR(spill_->read(first, std::span(chunk).first(n)));
        for (size_t i = 0; i < n; ++i) SP_RETURN_IF_ERROR(fn(chunk[i]));
      }
      return Status::ok();
    };
    // Cells denser than the target are counted again at finer levels (a few rounds at most).
    while (histogram_->beginRefinement())
      SP_RETURN_IF_ERROR(forEachSpilled([&](const SpilledTriangle& t) {
        histogram_->addRefined(t.centroid);
        return Status::ok();
      }));
    const TileIndex index = TileIndex::build(*histogram_);
    histogram_.reset();
    const auto tiles = index.tiles();
    std::vector<uint64_t> counts(tiles.size());
    for (size_t t = 0; t < tiles.size(); ++t) counts[t] = tiles[t].triangles;
    bins_.emplace(scratchFile("bins.bin"), in_memory_, counts, storage_budget_ / 4);
    SP_RETURN_IF_ERROR(forEachSpilled([&](const SpilledTriangle& t) -> Status {
      SP_ASSIGN_OR_RETURN(uint32_t tile, tileOfTriangle(index, t));
      return bins_->add(tile, t.t);
    }));
    SP_RETURN_IF_ERROR(bins_->finish());
    if (spill_) spill_->release();
    SP_RETURN_IF_ERROR(store_->finalize());
    tile_count_ = static_cast<uint32_t>(tiles.size());
    result_.seconds.tile = clock_.lap();
    return Status::ok();
  }

  // The flow graph: tiles built, staged, coded (and measured) in parallel, written in order.
  Status encodeTiles() {
    stage("encoding");
    SP_ASSIGN_OR_RETURN(file_, AtomicFile::create(s_.output));
    writer_.emplace(*file_, result_.grid, result_.layout);
    if (s_.subset_count) writer_->setSubset(s_.subset_index, s_.subset_count);
    SP_RETURN_IF_ERROR(writer_->setMaterial(result_.read.materials));
    SP_RETURN_IF_ERROR(writer_->begin());
    // A point cloud has no surface to sample (jobs/measure.h): it is not measured.
    result_.measured = s_.measure.enabled && !result_.point_cloud;
    density_ = samplingDensity(s_.measure, result_.faces, area_);
    const TileScanFacts facts{result_.grid, result_.layout, result_.measured, result_.diagonal, density_};
    if (result_.measured && !device_ && !remote_) {
      SP_ASSIGN_OR_RETURN(device_, EmbreeDevice::create());
    }
    tile_encoder_.emplace(s_, codec_, facts, device_, hooks_);
    size_t in_flight = 2 * static_cast<size_t>(result_.threads);
    if (s_.memory_budget > 0)
      in_flight = std::clamp<size_t>(s_.memory_budget / 4 / (target_ * kTileBytesPerTriangle), 1, in_flight);
    result_.tiles.resize(tile_count_);
    for (uint32_t t = 0; t < tile_count_; ++t) result_.tiles[t].id = t;
    step_ = s_.subset_count ? s_.subset_count : 1;
    share_count_ = s_.subset_count ? (tile_count_ + step_ - 1 - s_.subset_index) / step_ : tile_count_;
    if (remote_) {  // the tiles go to other processes (jobs/remote_tiles.h)
      SP_RETURN_IF_ERROR(runRemoteTiles(
          *remote_, s_, facts, s_.subset_count ? s_.subset_index : 0, step_, tile_count_,
          [&](uint32_t tile, std::vector<uint8_t>& message) {
        TileMesh tm;
        std::vector<Vec3d> originals;
        TileResult built = tileAsBuilt(tm, buildTile(tile, tm, originals));
        if (built.status.isOk()) message = tileMessage(tm, originals);
        return built;
          },
          [&](const TileResult& r) { writeTile(r); }));
      return finishTiles();
    }

    // More threads than cores: oneTBB's worker limit defaults to the cores, and an arena asking for more
    // printed "TBB Warning: The number of workers is currently limited to ..." on stderr (through --quiet
    // too). The user asked for this many threads: allow them while the encode runs (at least the cores, so
    // this never lowers the limit).
    tbb::global_control allow_threads(tbb::global_control::max_allowed_parallelism,
                                      std::max<size_t>(result_.threads, tbb::info::default_concurrency()));
    tbb::task_arena arena(result_.threads);
    arena.execute([&] {
      namespace flow = tbb::flow;
      flow::graph g;
      // A subset encodes every N-th tile from its index (round robin: neighbouring tiles, of similar sizes, go to
      // different parts); the sequencer numbers them 0, 1, 2, ... in that order.
      const uint32_t step = step_;
      uint32_t next = s_.subset_count ? s_.subset_index : 0;
      flow::input_node<TileJob> source(g, [&](tbb::flow_control& fc) -> TileJob {
        if (next >= tile_count_) {
          fc.stop();
          return TileJob{};
        }
        const uint32_t t = next;
        next += step;
        return TileJob{t};
      });
      flow::limiter_node<TileJob> limiter(g, in_flight);
      flow::function_node<TileJob, TileResult> work(g, flow::unlimited,
                                                    [&](const TileJob& job) { return runTile(job.tile); });
      flow::sequencer_node<TileResult> order(g, [&](const TileResult& r) {
        return static_cast<size_t>((r.tile - (s_.subset_count ? s_.subset_index : 0)) / step);
      });
      flow::function_node<TileResult, flow::continue_msg> sink(g, flow::serial, [&](const TileResult& r) {
        writeTile(r);
        return flow::continue_msg();
      });
      flow::make_edge(source, limiter);
      flow::make_edge(limiter, work);
      flow::make_edge(work, order);
      flow::make_edge(order, sink);
      flow::make_edge(sink, limiter.decrementer());
      source.activate();
      g.wait_for_all();
    });
    return finishTiles();
  }

  Status finishTiles() {
    SP_RETURN_IF_ERROR(write_status_);
    if (s_.subset_count)  // the report lists the tiles this part holds
      std::erase_if(result_.tiles, [&](const TileReport& t) { return t.id % step_ != s_.subset_index; });
    result_.seconds.encode = clock_.lap();
    return Status::ok();
  }

  // After the tiles: the points pm's weld merged into another point at their position with other attributes (v5:
  // points no triangle uses at a position whose other points they do not match; v3 and v4 merged every crease and
  // seam) are listed dropped, and under `strict` fail the file before it is committed.
  Status checkMerged() {
    if (merged_points_ == 0) return Status::ok();
    const DroppedProperty d{"attributes of points sharing a grid position (codec " + std::string(codec_.name) +
                                " keeps those its triangles use)",
                            merged_points_};
    result_.read.dropped.push_back(d);
    if (s_.strict)
      return strictRefusal(std::span(&d, 1),
                           "encode without --strict or /strict to drop them, or with a codec that keeps every point");
    return Status::ok();
  }

  // Under `strict`: the file refused for what the container would not keep, with how to go on.
  Status strictRefusal(std::span<const DroppedProperty> dropped, const std::string& remedy) const {
    return makeError(ErrorCode::kUnsupported, s_.input + ": strict: the container would not keep " +
                                                  describeDropped(dropped) + " (" + remedy + ")");
  }

  // Index, footer, sync, rename.
  Status finish() {
    SP_RETURN_IF_ERROR(writer_->finish());
    SP_RETURN_IF_ERROR(file_->commit());
    result_.bytes = writer_->bytesWritten();
    result_.seconds.write = clock_.lap();
    result_.peak_rss = peakRss();
    return Status::ok();
  }

  // After the survey: what the container will not keep. Normals and colors the settings drop are listed (not
  // silent); what the reader skipped is silent unless reported, and under `strict` it fails the file before
  // anything is written.
  Status checkDrops() {
    if (!s_.keep_normals && survey_.has_normals)
      result_.dropped_on_request.push_back({"vertex normals", survey_.vertex_count});
    if (!s_.keep_colors && survey_.colorChannels())
      result_.dropped_on_request.push_back({"vertex colors", survey_.vertex_count});
    // Texture coordinates that --no-scalars kept the reader from splitting wedges for: dropped on request.
    if (!s_.keep_scalars) {
      std::erase_if(result_.read.dropped, [&](const DroppedProperty& d) {
        const bool texcoords = d.name == "obj vt" || d.name == "face.texcoord";
        if (texcoords) result_.dropped_on_request.push_back(d);
        return texcoords;
      });
    }
    // What a codec that does not keep every vertex made the reader drop, with the reason.
    if (!codecKeepsWedges()) {
      for (DroppedProperty& d : result_.read.dropped) {
        if (d.name == "obj vt" || d.name == "face.texcoord") d.name += " (" + droppedBy() + " keeps no texture seams)";
        else if (d.name == "obj vn per corner") d.name += " (" + droppedBy() + " keeps a normal per vertex)";
      }
    }
    const std::vector<bool> texcoords = texcoordChannels(survey_.scalar_channels);
    for (size_t i = 0; i < survey_.scalar_channels.size(); ++i) {
      const ScalarChannel& c = survey_.scalar_channels[i];
      if (!s_.keep_scalars) result_.dropped_on_request.push_back({"vertex." + c.name, survey_.vertex_count});
      else if (!codecKeepsWedges() && texcoords[i])
        result_.read.dropped.push_back({"vertex." + c.name + " (" + droppedBy() + " keeps no texture seams)",
                                        survey_.vertex_count});
    }
    if (s_.strict && !result_.read.dropped.empty())
      return strictRefusal(result_.read.dropped,
                           "scanpress keeps positions, triangles, normals, colors and per-vertex scalars; texture "
                           "coordinates and normals per corner with store, kdtree, octree, edgebreaker and pm; "
                           "encode without --strict or /strict to drop them");
    return Status::ok();
  }

  EncodeResult& result() { return result_; }

 private:
  // Whether the codec keeps the scan's own vertices: not prm, nor any codec after a remesh stage (they make new
  // vertices and resample their attributes).
  bool keepsScanVertices() const {
    for (const StageSpec& st : s_.stages)
      if (st.kind == StageKind::kRemesh) return false;
    return codec_.id != CodecId::kPrm;
  }
  // ... and the wedges of texture seams and creases: every codec that keeps the scan's vertices does (pm since its
  // version 5: its simplifier moves a corner only to a wedge on its own side).
  bool codecKeepsWedges() const { return keepsScanVertices(); }
  // What drops wedges (or lossless normals), as the report names it.
  std::string droppedBy() const {
    for (const StageSpec& st : s_.stages)
      if (st.kind == StageKind::kRemesh) return "the remesh stage";
    return "codec " + std::string(codec_.name);
  }

  // Fails (exit 2) when quantization made more than kMaxDegenerateShare of the triangles degenerate: the grid is
  // too coarse for the scan (or an outlying vertex that a triangle uses stretched it), and the archive would
  // silently lose its surface.
  Status checkDegenerate(uint64_t triangles, uint64_t dropped) const {
    if (s_.allow_degenerate || double(dropped) <= kMaxDegenerateShare * double(triangles)) return Status::ok();
    char share[32];
    std::snprintf(share, sizeof share, "%.2f%%", 100.0 * double(dropped) / double(triangles));
    return makeError(ErrorCode::kLimitExceeded,
                     s_.input + ": quantization at " + std::to_string(s_.bits) + " bits makes " +
                         std::to_string(dropped) + " of " + std::to_string(triangles) + " triangles degenerate (" +
                         share + ", more than the 0.1% allowed): raise --bits (job key /codec/bits), or drop them " +
                         "with --allow-degenerate (/codec/allow_degenerate)");
  }

  // Reads the input into `sink`; with more than one thread, the sink runs on a thread of its own while the reader
  // parses the next chunk (the sink sees the same calls in the same order).
  Result<ReadStats> readInput(MeshSink& sink) const {
    if (result_.threads < 2) return readMesh(s_.input, sink, readOptions());
    AsyncSink async(sink);
    auto read = readMesh(s_.input, async, readOptions());
    const Status delivered = async.finish();
    if (!read.isOk()) return read;
    if (!delivered.isOk()) return delivered;
    return read;
  }

  // Texture coordinates and normals per corner (OBJ `vt`, `vn`) split vertices into wedges at seams and creases:
  // only for codecs that keep every vertex (pm, prm and the remesh stage would open the seams: they read the
  // vertices as they are, `vt` listed dropped, a vertex's normal its first corner's), and what is kept.
  ReadOptions readOptions() const {
    ReadOptions o;
    o.texture_coordinates = s_.keep_scalars && codecKeepsWedges();
    o.corner_normals = s_.keep_normals && codecKeepsWedges();
    return o;
  }

  void stage(const char* name) {
    if (progress_) progress_->stage(name);
  }
  std::string scratchFile(const char* name) const { return scratch_ ? scratch_->file(name) : std::string(); }

  // Builds tile `tile` (its triangles from the bins, its vertices from the store, its border flags) with the
  // original positions when measuring. A failed build is a failed tile, not a failed encode.
  Status buildTile(uint32_t tile, TileMesh& tm, std::vector<Vec3d>& originals) const {
    tm.tile_id = tile;
    try {
      std::vector<Triangle> triangles;
      SP_RETURN_IF_ERROR(bins_->read(tile, triangles));
      SP_RETURN_IF_ERROR(buildTileMesh(tile, triangles, *store_, result_.layout, tm,
                                       result_.measured ? &originals : nullptr));
      // A point cloud's bins hold (v, v, v) per point: its vertices, in input order, without triangles.
      if (result_.point_cloud) tm.mesh.triangles.clear();
      return Status::ok();
    } catch (...) {
      return statusFromException();
    }
  }

  TileResult runTile(uint32_t tile) const {
    TileMesh tm;
    std::vector<Vec3d> originals;
    if (Status built = buildTile(tile, tm, originals); !built.isOk()) return tileAsBuilt(tm, std::move(built));
    return tile_encoder_->run(tm, originals);
  }

  void writeTile(const TileResult& r) {
    TileReport& rep = result_.tiles[r.tile];
    rep.id = r.tile;
    rep.vertices = r.status.isOk() ? r.encoded.decoded.vertices : r.input_vertices;
    rep.faces = r.status.isOk() ? r.encoded.decoded.faces : r.input_faces;
    rep.border_vertices = r.border;
    rep.status = r.status;
    rep.forward = statsOf(r.forward);
    rep.backward = statsOf(r.backward);
    rep.knob_cells = r.knob_cells;
    rep.target_met = r.target_met;
    rep.knob_trials = r.knob_trials;
    result_.forward.merge(r.forward);
    result_.backward.merge(r.backward);
    if (!r.status.isOk()) {
      ++result_.failed_tiles;
    } else if (write_status_.isOk()) {
      write_status_ = writer_->addTile(r.tile, codec_, r.encoded);
      merged_points_ += r.encoded.merged_points;
      rep.bytes = kChunkHeaderSize + r.encoded.payload.size();
      result_.tile_vertices += r.encoded.decoded.vertices;
    }
    ++written_;
    triangles_done_ += r.input_faces;
    if (progress_) progress_->tiles(written_, share_count_, triangles_done_);
  }

  const EncodeSettings& s_;
  const CodecInfo& codec_;
  ProgressListener* progress_;
  std::shared_ptr<EmbreeDevice> device_;
  const PipelineHooks* hooks_;
  EncodeResult result_;
  Stopwatch clock_;
  SurveySink survey_;
  // Tile data: in memory or in scratch files.
  uint64_t storage_budget_ = 0;
  uint64_t merged_points_ = 0;  // summed over the tiles written (EncodedTile::merged_points)
  bool in_memory_ = true;
  uint64_t target_ = 0;
  std::optional<ScratchDir> scratch_;
  std::optional<VertexStore> store_;
  std::optional<TileHistogram> histogram_;
  std::optional<TriangleSpill> spill_;  // in memory only; out of core the tile pass reads the input again
  uint64_t kept_items_ = 0;             // triangles kept (a point cloud: points)
  std::optional<TileBins> bins_;
  double area_ = 0;  // of the kept triangles, original positions
  uint32_t tile_count_ = 0;
  uint32_t share_count_ = 0;  // the tiles this encode codes: all, or a subset's share
  uint32_t step_ = 1;         // a subset's count N, else 1
  // Encoding and writing.
  double density_ = 0;
  TileTransport* remote_ = tileTransport();  // tiles go to other processes; nullptr: encoded here
  std::optional<TileEncoder> tile_encoder_;
  std::unique_ptr<AtomicFile> file_;
  std::optional<ContainerWriter> writer_;
  Status write_status_;
  uint32_t written_ = 0;
  uint64_t triangles_done_ = 0;
};

}  // namespace

const char* targetKindName(TargetKind kind) {
  switch (kind) {
    case TargetKind::kNone: return "none";
    case TargetKind::kMaxError: return "max_error";
    case TargetKind::kMaxBytes: return "max_bytes";
    case TargetKind::kBitsPerVertex: return "bpv";
  }
  return "unknown";
}

const char* errorMetricName(ErrorMetric m) { return m == ErrorMetric::kMax ? "max" : "rms"; }

ErrorKnob errorKnobOf(CodecId id) {
  // pm's last level keeps collapses whose error estimate is at most max_error grid cells (engine/codecs/codec.h).
  if (id == CodecId::kPm) return [](CodecOptions& o, double cells) { o.pm.max_error = cells; };
  // prm's lattice spacing: a coarser lattice departs further from the tile. Remeshed scans measure an RMS of about
  // a fortieth of the spacing and a max of about a tenth (bench/RESULTS.md), so the spacing is 16 times the
  // knob's cells; 0 keeps the tile as it is.
  if (id == CodecId::kPrm) return [](CodecOptions& o, double cells) { o.prm.spacing = kPrmSpacingPerCell * cells; };
  return nullptr;
}

Result<EncodeResult> encodeFile(const EncodeSettings& s, ProgressListener* progress,
                                std::shared_ptr<EmbreeDevice> device, const PipelineHooks* hooks) {
  if (s.subset_count == 1 || (s.subset_count && s.subset_index >= s.subset_count))
    return makeError(ErrorCode::kInvalidArgument, "--subset i/N needs N >= 2 and i < N");
  if (s.subset_count && s.target.active())
    return makeError(ErrorCode::kInvalidArgument,
                     "--subset and a target (--max-error, --max-bytes, --bpv) do not go together: a target is met by "
                     "the whole scan, which no part holds");
  if (s.target.active()) return encodeToTarget(s, progress, std::move(device), hooks);
  if (s.codec == kAutoCodec) {
    EncodeSettings lossless = s;
    lossless.codec = "edgebreaker";
    return encodeFileOnce(lossless, progress, std::move(device), hooks);
  }
  return encodeFileOnce(s, progress, std::move(device), hooks);
}

Result<EncodeResult> encodeFileOnce(const EncodeSettings& s, ProgressListener* progress,
                                    std::shared_ptr<EmbreeDevice> device, const PipelineHooks* hooks) {
  const CodecInfo* codec = findCodec(s.codec);
  if (!codec)
    return makeError(ErrorCode::kInvalidArgument, "unknown codec '" + s.codec + "' (available: " + codecNames() + ")");
  if (s.normal_bits < 4 || s.normal_bits > 16)
    return makeError(ErrorCode::kInvalidArgument, "normal bits must be in [4, 16]");
  if (s.color_bits < 1 || s.color_bits > 8)
    return makeError(ErrorCode::kInvalidArgument, "color bits must be in [1, 8]");
  if (s.uv_bits < 0 || s.uv_bits > kMaxScalarBits)
    return makeError(ErrorCode::kInvalidArgument,
                     "texture coordinate bits must be in [1, " + std::to_string(kMaxScalarBits) + "] (0: lossless)");
  for (const StageSpec& st : s.stages)
    if (!findStage(st.kind)) return makeError(ErrorCode::kInvalidArgument, "unknown stage");
  SP_RETURN_IF_ERROR(checkOutputPath(s.output, {s.input}));  // before reading: `encode X X` must not replace X
  if (hooks && hooks->before_survey) hooks->before_survey(s.input);
  ScanEncoder encoder(s, *codec, progress, std::move(device), hooks);
  SP_RETURN_IF_ERROR(encoder.survey());
  SP_RETURN_IF_ERROR(encoder.checkDrops());
  SP_RETURN_IF_ERROR(encoder.ingest());
  SP_RETURN_IF_ERROR(encoder.tile());
  SP_RETURN_IF_ERROR(encoder.encodeTiles());
  SP_RETURN_IF_ERROR(encoder.checkMerged());
  SP_RETURN_IF_ERROR(encoder.finish());
  return std::move(encoder.result());
}

}  // namespace scanpress
