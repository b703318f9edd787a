// The encode pipeline for one scan: bounded-memory passes over the input, tiling, and a oneTBB flow graph that
// runs the per-tile pipeline in parallel and writes tiles in order.
//
//   pass 1  stream the input: bounding box, counts, which attributes exist (and the mesh itself, if it fits)
//   grid    the scan's one global quantization grid
//   pass 2  stream again (or replay the buffered mesh): quantize vertices into the vertex store, drop triangles
//           that quantization makes degenerate, count each vertex's valence, histogram triangle centroids
//   tiling  octree tiles from the histogram (spatial/tiling), then a counting sort of triangles into tile bins
//   graph   source -> limiter -> tile task (parallel) -> sequencer (tile order) -> serial container writer
//
// Memory: the store, the spill and the bins go to scratch files when they would not fit in half of the budget
// (2 GiB when none is set: beyond that, scratch files are faster too), their buffers take about a quarter each,
// and with a budget the limiter keeps the tiles in flight (and the tile size) within the rest. The output is byte-identical at any thread count:
// each tile's bytes depend only on its content, and the sequencer restores tile order.
#include <sys/resource.h>

#include <oneapi/tbb/flow_graph.h>
#include <oneapi/tbb/global_control.h>
#include <oneapi/tbb/info.h>
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <bit>
#include <cinttypes>
#include <cstdio>
#include <atomic>
#include <chrono>
#include <cmath>
#include <exception>
#include <new>
#include <optional>

#include "engine/codecs/codec.h"
#include "engine/container/container.h"
#include "engine/geometry.h"
#include "engine/metro.h"
#include "engine/octahedral.h"
#include "engine/tile.h"
#include "jobs/commands.h"
#include "jobs/config.h"
#include "jobs/file_io.h"
#include "jobs/process.h"
#include "jobs/scan_store.h"
#include "spatial/surface_index.h"
#include "spatial/tiling.h"

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

// Pass 1: bounds, counts, attributes; keeps the mesh while it fits in `keep_limit` bytes.
class SurveySink : public MeshSink {
 public:
  explicit SurveySink(uint64_t keep_limit) : keep_limit_(keep_limit) {}
  Status vertices(std::span<const Vec3d> p, std::span<const Vec3f> n, std::span<const Rgba8> c,
                  uint8_t channels) override {
    for (const auto& v : p) box.extend(v);
    vertex_count += p.size();
    has_normals |= !n.empty();
    if (!c.empty()) channels_ = std::max(channels_, channels);
    if (kept()) SP_RETURN_IF_ERROR(collector_.vertices(p, n, c, channels));
    checkLimit();
    return Status::ok();
  }
  Status triangles(std::span<const Triangle> t) override {
    triangle_count += t.size();
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
  // The kept mesh, with every attribute array covering every vertex (only when kept()).
  Mesh& keptMesh() {
    collector_.finish();
    return mesh_;
  }
  void releaseMesh() { mesh_ = Mesh(); }

  BoundingBox box;
  uint64_t vertex_count = 0, triangle_count = 0;
  bool has_normals = false;

 private:
  void checkLimit() {
    if (dropped_) return;
    const uint64_t bytes = mesh_.positions.size() * sizeof(Vec3d) + mesh_.normals.size() * sizeof(Vec3f) +
                           mesh_.colors.size() * sizeof(Rgba8) + mesh_.triangles.size() * sizeof(Triangle);
    if (bytes > keep_limit_) {
      dropped_ = true;
      mesh_ = Mesh();
    }
  }
  uint64_t keep_limit_;
  bool dropped_ = false;
  uint8_t channels_ = 0;
  Mesh mesh_;
  MeshCollector collector_{mesh_};
};

// Pass 2: quantize into the store, drop degenerate triangles, valences, histogram, spill.
class IngestSink : public MeshSink {
 public:
  IngestSink(const Grid& grid, const AttributeLayout& layout, VertexStore& store, TileHistogram& hist,
             TriangleSpill& spill)
      : grid_(grid), layout_(layout), store_(store), hist_(hist), spill_(spill) {}
  static Vec3d originalOf(const VertexRecord& r) { return {r.original[0], r.original[1], r.original[2]}; }
  Status vertices(std::span<const Vec3d> p, std::span<const Vec3f> n, std::span<const Rgba8> c,
                  uint8_t) override {
    const OctNormal no_normal = encodeOctahedral({0, 0, 0}, layout_.hasNormals() ? layout_.normal_bits : 8);
    for (size_t i = 0; i < p.size(); ++i) {
      VertexRecord r;
      r.q = grid_.quantize(p[i]);
      for (int a = 0; a < 3; ++a) r.original[a] = static_cast<float>(p[i][a] - grid_.origin[a]);
      if (layout_.hasNormals()) r.normal = n.empty() ? no_normal : encodeOctahedral(n[i], layout_.normal_bits);
      if (layout_.hasColors() && !c.empty()) r.color = c[i];
      SP_RETURN_IF_ERROR(store_.append(r));
    }
    return Status::ok();
  }
  Status triangles(std::span<const Triangle> tris) override {
    VertexRecord r[3];
    for (const Triangle& t : tris) {
      for (int k = 0; k < 3; ++k) SP_RETURN_IF_ERROR(store_.get(t[k], r[k]));
      if (r[0].q == r[1].q || r[1].q == r[2].q || r[0].q == r[2].q) {
        ++stats.degenerate_triangles;
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
      SP_RETURN_IF_ERROR(spill_.append({t, c}));
    }
    return Status::ok();
  }
  Status vertexNormals(uint64_t first, std::span<const Vec3f> n) override {
    if (!layout_.hasNormals()) return Status::ok();
    for (size_t i = 0; i < n.size(); ++i)
      if (!std::isnan(n[i][0])) SP_RETURN_IF_ERROR(store_.setNormal(first + i, encodeOctahedral(n[i], layout_.normal_bits)));
    return Status::ok();
  }

  QuantizeStats stats;
  uint64_t referenced = 0;
  double area = 0;  // of the kept triangles, original positions

 private:
  const Grid& grid_;
  const AttributeLayout& layout_;
  VertexStore& store_;
  TileHistogram& hist_;
  TriangleSpill& spill_;
};

// Feeds a buffered mesh to a sink in chunks, as a reader would.
Status replay(const Mesh& m, MeshSink& sink, size_t chunk) {
  for (size_t i = 0; i < m.positions.size(); i += chunk) {
    const size_t n = std::min(chunk, m.positions.size() - i);
    SP_RETURN_IF_ERROR(sink.vertices(std::span(m.positions).subspan(i, n),
                                     m.normals.empty() ? std::span<const Vec3f>() : std::span(m.normals).subspan(i, n),
                                     m.colors.empty() ? std::span<const Rgba8>() : std::span(m.colors).subspan(i, n),
                                     m.color_channels));
  }
  for (size_t i = 0; i < m.triangles.size(); i += chunk)
    SP_RETURN_IF_ERROR(sink.triangles(std::span(m.triangles).subspan(i, std::min(chunk, m.triangles.size() - i))));
  return Status::ok();
}

struct TileJob {
  uint32_t tile = 0;
};

struct TileResult {
  uint32_t tile = 0;
  Status status;
  EncodedTile encoded;
  uint32_t border = 0;
  uint32_t input_vertices = 0, input_faces = 0;  // of the tile as built (a failed tile reports what it lost)
  ErrorAccumulator forward, backward;
};

// Builds the tile's local mesh from the bins and the store: local vertex ids in order of first use (an
// open-addressing hash from global to local id), records read in global-id order (runs of nearby ids become one
// read when the store is on disk), border flags from the valence inside the tile against the global valence.
Status buildTileMesh(uint32_t tile, const TileBins& bins, const VertexStore& store, const AttributeLayout& layout,
                     TileMesh& out, std::vector<Vec3d>* originals) {
  std::vector<Triangle> tris;
  SP_RETURN_IF_ERROR(bins.read(tile, tris));
  size_t cap = 16;
  while (cap < 3 * tris.size()) cap <<= 1;  // load factor <= 1/2 even if every corner is a distinct vertex
  const int shift = 64 - std::countr_zero(cap);
  std::vector<uint32_t> keys(cap, UINT32_MAX), vals(cap);
  std::vector<uint32_t>& ids = out.local_to_global;
  ids.clear();
  QuantizedMesh& m = out.mesh;
  m.triangles.resize(tris.size());
  std::vector<uint32_t> local_valence;
  for (size_t t = 0; t < tris.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      const uint32_t g = tris[t][k];
      size_t h = static_cast<size_t>((uint64_t(g) * 0x9E3779B97F4A7C15ull) >> shift);
      while (keys[h] != UINT32_MAX && keys[h] != g) h = (h + 1) & (cap - 1);
      if (keys[h] == UINT32_MAX) {
        keys[h] = g;
        vals[h] = static_cast<uint32_t>(ids.size());
        ids.push_back(g);
        local_valence.push_back(0);
      }
      m.triangles[t][k] = vals[h];
      ++local_valence[vals[h]];
    }
  // Read the records in global order, then scatter them to their local slots.
  std::vector<std::pair<uint32_t, uint32_t>> order(ids.size());
  for (uint32_t i = 0; i < ids.size(); ++i) order[i] = {ids[i], i};
  std::sort(order.begin(), order.end());
  std::vector<uint32_t> sorted(ids.size());
  for (size_t i = 0; i < order.size(); ++i) sorted[i] = order[i].first;
  std::vector<VertexRecord> records;
  SP_RETURN_IF_ERROR(store.read(sorted, records));
  out.tile_id = tile;
  m.positions.resize(ids.size());
  if (layout.hasNormals()) m.normals.resize(ids.size());
  if (layout.hasColors()) m.colors.resize(ids.size());
  out.border.resize(ids.size());
  if (originals) originals->resize(ids.size());
  for (size_t i = 0; i < order.size(); ++i) {
    const uint32_t local = order[i].second;
    const VertexRecord& r = records[i];
    if (originals) (*originals)[local] = {r.original[0], r.original[1], r.original[2]};
    m.positions[local] = r.q;
    if (layout.hasNormals()) m.normals[local] = r.normal;
    if (layout.hasColors()) m.colors[local] = r.color;
    out.border[local] = local_valence[local] < r.valence ? 1 : 0;
  }
  return Status::ok();
}

Status statusFromException() {
  try {
    throw;
  } catch (const std::bad_alloc&) {
    return makeError(ErrorCode::kIo, "out of memory");
  } catch (const std::exception& e) {
    return makeError(ErrorCode::kInternal, e.what());
  } catch (...) {
    return makeError(ErrorCode::kInternal, "unknown exception");
  }
}

// Measures one tile: its original triangles against the decoded tile, both ways. Near tile borders the other
// tile's surface is not considered, which can only make a distance larger (never hide an error).
Status measureTile(const EncodeSettings& s, const CodecInfo& codec, const TileContext& ctx, const Grid& grid,
                   double density, std::shared_ptr<EmbreeDevice> device, const TileMesh& tm,
                   const std::vector<Vec3d>& originals, TileResult& r) {
  SP_ASSIGN_OR_RETURN(QuantizedMesh decoded_q,
                      codec.decode(ctx, codec.version, r.encoded.payload, limitsOf(r.encoded.decoded)));
  std::vector<Vec3d> decoded(decoded_q.positions.size());
  for (size_t i = 0; i < decoded.size(); ++i) {
    decoded[i] = grid.dequantize(decoded_q.positions[i]);
    for (int a = 0; a < 3; ++a) decoded[i][a] -= grid.origin[a];  // same frame as the originals
  }
  return measureSurfaces(originals, tm.mesh.triangles, decoded, decoded_q.triangles, s.measure, density,
                         2 * uint64_t(tm.tile_id), device, r.forward, r.backward);
}

}  // namespace

Result<EncodeResult> encodeFile(const EncodeSettings& s, ProgressListener* progress,
                                std::shared_ptr<EmbreeDevice> device) {
  const CodecInfo* codec = findCodec(s.codec);
  if (!codec) return makeError(ErrorCode::kInvalidArgument, "unknown codec '" + s.codec + "'");
  if (s.normal_bits < 4 || s.normal_bits > 16)
    return makeError(ErrorCode::kInvalidArgument, "normal bits must be in [4, 16]");
  EncodeResult result;
  result.codec = codec->name;
  result.threads = s.threads > 0 ? s.threads : tbb::info::default_concurrency();
  const uint64_t budget = s.memory_budget;
  Stopwatch clock;

  // ---- pass 1
  if (progress) progress->stage("reading");
  // Pass 1 keeps the mesh for pass 2 only while it is small: a large mesh held in doubles costs more in memory
  // traffic and page faults than parsing the file again (20M triangles: 5.7 s re-reading vs 8.1 s kept).
  constexpr uint64_t kKeepLimit = 256ull << 20;
  SurveySink survey(std::min(kKeepLimit, budget == 0 ? UINT64_MAX : budget / 3));
  SP_ASSIGN_OR_RETURN(result.read, readMesh(s.input, survey));
  if (s.keep_normals && survey.has_normals) result.layout.normal_bits = static_cast<uint8_t>(s.normal_bits);
  if (s.keep_colors && survey.colorChannels()) result.layout.color_channels = survey.colorChannels();
  auto grid = makeGrid(survey.box, s.bits);
  if (!grid.isOk()) return grid.status().withContext(s.input);
  result.grid = *grid;
  result.seconds.read = clock.lap();

  // ---- memory plan
  const uint64_t n_vertices = survey.vertex_count, n_triangles = survey.triangle_count;
  const uint64_t in_memory_bytes = n_vertices * sizeof(VertexRecord) + n_triangles * (sizeof(SpilledTriangle) + sizeof(Triangle));
  // Without a budget, tile data up to kAutoStorageBudget / 2 stays in memory; beyond that, scratch files are
  // faster as well as smaller (50M-triangle synth: 2.83 vs 2.28 Mtri/s, 262 MB vs 2.74 GB). Only where the data
  // lives changes: the tiles, hence the bytes, depend on an explicit budget only.
  constexpr uint64_t kAutoStorageBudget = 2ull << 30;
  const uint64_t storage_budget = budget > 0 ? budget : kAutoStorageBudget;
  const bool in_memory = in_memory_bytes <= storage_budget / 2;
  result.out_of_core = !in_memory;
  const uint64_t target = effectiveTileTarget(s);  // independent of the thread count: so are the bytes
  std::optional<ScratchDir> scratch;
  if (!in_memory) {
    SP_ASSIGN_OR_RETURN(ScratchDir dir, ScratchDir::create(s.scratch_dir));
    scratch.emplace(std::move(dir));
  }
  auto scratchFile = [&](const char* name) { return scratch ? scratch->file(name) : std::string(); };

  // ---- pass 2
  if (progress) progress->stage("quantizing");
  VertexStore store(scratchFile("vertices.bin"), in_memory ? UINT64_MAX / 2 : storage_budget / 4);
  std::optional<TileHistogram> histogram(std::in_place, result.grid.bits, n_triangles, target);
  TriangleSpill spill(scratchFile("triangles.bin"), in_memory, n_triangles);
  IngestSink ingest(result.grid, result.layout, store, *histogram, spill);
  if (survey.kept()) {
    SP_RETURN_IF_ERROR(replay(survey.keptMesh(), ingest, ReadOptions().chunk));
    survey.releaseMesh();
  } else {
    auto again = readMesh(s.input, ingest);
    if (!again.isOk()) return again.status();
    if (again->vertices != n_vertices || again->triangles != n_triangles)
      return makeError(ErrorCode::kIo, s.input + ": file changed between the two passes");
  }
  SP_RETURN_IF_ERROR(spill.finish());
  result.quantize = ingest.stats;
  result.quantize.unreferenced_vertices = n_vertices - ingest.referenced;
  result.vertices = ingest.referenced;
  result.faces = spill.size();
  result.seconds.quantize = clock.lap();

  // ---- tiling and binning
  if (progress) progress->stage("tiling");
  std::vector<SpilledTriangle> chunk(1u << 16);
  auto forEachSpilled = [&](auto&& fn) -> Status {
    for (uint64_t first = 0; first < spill.size(); first += chunk.size()) {
      const size_t n = static_cast<size_t>(std::min<uint64_t>(chunk.size(), spill.size() - first));
      SP_RETURN_IF_ERROR(spill.read(first, std::span(chunk).first(n)));
      for (size_t i = 0; i < n; ++i) SP_RETURN_IF_ERROR(fn(chunk[i]));
    }
    return Status::ok();
  };
  // Cells denser than the target are counted again at finer levels (a few rounds at most).
  while (histogram->beginRefinement())
    SP_RETURN_IF_ERROR(forEachSpilled([&](const SpilledTriangle& t) {
      histogram->addRefined(t.centroid);
      return Status::ok();
    }));
  const TileIndex index = TileIndex::build(*histogram);
  histogram.reset();
  const auto tiles = index.tiles();
  std::vector<uint64_t> counts(tiles.size());
  for (size_t t = 0; t < tiles.size(); ++t) counts[t] = tiles[t].triangles;
  TileBins bins(scratchFile("bins.bin"), in_memory, counts, storage_budget / 4);
  SP_RETURN_IF_ERROR(forEachSpilled([&](const SpilledTriangle& t) {
    const uint32_t tile = index.tileOf(t.centroid);
    if (tile == UINT32_MAX) return makeError(ErrorCode::kInternal, "triangle centroid outside every tile");
    return bins.add(tile, t.t);
  }));
  chunk = {};
  SP_RETURN_IF_ERROR(bins.finish());
  spill.release();
  SP_RETURN_IF_ERROR(store.finalize());
  result.seconds.tile = clock.lap();

  // ---- the flow graph
  if (progress) progress->stage("encoding");
  SP_ASSIGN_OR_RETURN(auto file, AtomicFile::create(s.output));
  ContainerWriter writer(*file, result.grid, result.layout);
  SP_RETURN_IF_ERROR(writer.begin());
  const TileContext ctx{result.grid.bits, result.layout};
  result.measured = s.measure.enabled;
  result.diagonal = survey.box.diagonal();
  const double density = samplingDensity(s.measure, result.faces, ingest.area);
  if (result.measured && !device) {
    SP_ASSIGN_OR_RETURN(device, EmbreeDevice::create());
  }
  const uint32_t tile_count = static_cast<uint32_t>(tiles.size());
  size_t in_flight = 2 * static_cast<size_t>(result.threads);
  if (budget > 0)
    in_flight = std::clamp<size_t>(budget / 4 / (target * kTileBytesPerTriangle), 1, in_flight);
  Status write_status;
  uint32_t written = 0;
  uint64_t triangles_done = 0;
  result.tiles.resize(tile_count);

  auto runTile = [&](const TileJob& job) -> TileResult {
    TileResult r;
    r.tile = job.tile;
    try {
      TileMesh tm;
      std::vector<Vec3d> originals;
      r.status = buildTileMesh(job.tile, bins, store, result.layout, tm, result.measured ? &originals : nullptr);
      // Per-tile stages run here in order (simplify, remesh: border vertices stay fixed, see engine/tile.h);
      // the codec is the last stage.
      if (r.status.isOk() && std::find(s.fail_tiles.begin(), s.fail_tiles.end(), job.tile) != s.fail_tiles.end())
        r.status = makeError(ErrorCode::kInternal, "injected failure (test)");
      if (r.status.isOk()) {
        auto encoded = codec->encode(ctx, TileView{tm.mesh, tm.border}, CodecOptions{});
        if (encoded.isOk()) r.encoded = std::move(encoded).value();
        else r.status = encoded.status();
      }
      if (r.status.isOk() && result.measured)  // decode in memory, measure, discard
        r.status = measureTile(s, *codec, ctx, result.grid, density, device, tm, originals, r);
      r.border = static_cast<uint32_t>(std::count(tm.border.begin(), tm.border.end(), 1));
      r.input_vertices = static_cast<uint32_t>(tm.mesh.positions.size());
      r.input_faces = static_cast<uint32_t>(tm.mesh.triangles.size());
    } catch (...) {
      r.status = statusFromException();
      r.encoded = EncodedTile{};
    }
    return r;
  };
  auto writeTile = [&](const TileResult& r) {
    TileReport& rep = result.tiles[r.tile];
    rep.id = r.tile;
    rep.vertices = r.status.isOk() ? r.encoded.decoded.vertices : r.input_vertices;
    rep.faces = r.status.isOk() ? r.encoded.decoded.faces : r.input_faces;
    rep.border_vertices = r.border;
    rep.status = r.status;
    rep.forward = statsOf(r.forward);
    rep.backward = statsOf(r.backward);
    result.forward.merge(r.forward);
    result.backward.merge(r.backward);
    if (!r.status.isOk()) {
      ++result.failed_tiles;
    } else if (write_status.isOk()) {
      write_status = writer.addTile(r.tile, *codec, r.encoded.decoded, r.encoded.payload);
      rep.bytes = kChunkHeaderSize + r.encoded.payload.size();
      result.tile_vertices += r.encoded.decoded.vertices;
    }
    ++written;
    triangles_done += r.input_faces;
    if (progress) progress->tiles(written, tile_count, triangles_done);
  };

  tbb::task_arena arena(result.threads);
  arena.execute([&] {
    namespace flow = tbb::flow;
    flow::graph g;
    uint32_t next = 0;
    flow::input_node<TileJob> source(g, [&](tbb::flow_control& fc) -> TileJob {
      if (next >= tile_count) {
        fc.stop();
        return TileJob{};
      }
      return TileJob{next++};
    });
    flow::limiter_node<TileJob> limiter(g, in_flight);
    flow::function_node<TileJob, TileResult> work(g, flow::unlimited, runTile);
    flow::sequencer_node<TileResult> order(g, [](const TileResult& r) { return static_cast<size_t>(r.tile); });
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
  SP_RETURN_IF_ERROR(write_status);
  result.seconds.encode = clock.lap();

  SP_RETURN_IF_ERROR(writer.finish());
  SP_RETURN_IF_ERROR(file->commit());
  result.bytes = writer.bytesWritten();
  result.seconds.write = clock.lap();
  result.peak_rss = peakRss();
  return result;
}

}  // namespace scanpress
