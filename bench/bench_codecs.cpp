// Codec and I/O throughput on real scans: mesh reading (MB/s, Mtri/s), each codec's encode and decode (Mtri/s,
// bits per vertex), simplification and remeshing. Scans come from ../shared/data (the bundled bunny when it is missing).
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <filesystem>
#include <functional>
#include <map>
#include <stdexcept>

#include "engine/codecs/codec.h"
#include "engine/quantize.h"
#include "engine/remesh/remesh.h"
#include "engine/simplify/simplify.h"
#include "jobs/measure.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "spatial/surface_index.h"
#include "spatial/tiling.h"

#ifdef SCANPRESS_HAVE_MESHOPTIMIZER
#include <meshoptimizer.h>
#endif

namespace scanpress {
namespace {

std::string scanPath(const std::string& name) {
  const std::string shared = std::string(SCANPRESS_SHARED_DATA) + "/" + name;
  if (std::filesystem::exists(shared)) return shared;
  return std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
}

struct Prepared {
  QuantizedMesh mesh;
  TileContext ctx;
};

const Prepared& prepared(const std::string& name, int bits) {
  static std::map<std::pair<std::string, int>, Prepared> cache;
  auto key = std::make_pair(name, bits);
  auto it = cache.find(key);
  if (it != cache.end()) return it->second;
  auto mesh = readMeshFile(scanPath(name), nullptr, ReadOptions::asInFile());
  if (!mesh.isOk()) throw std::runtime_error(mesh.status().toString());
  Prepared p;
  auto grid = makeGrid(boundingBox(*mesh), bits);
  p.ctx.bits = bits;
  if (!mesh->normals.empty()) p.ctx.layout.normal_bits = kDefaultNormalBits;
  if (!mesh->colors.empty()) p.ctx.layout.color_channels = mesh->color_channels;
  p.mesh = *quantizeMesh(*mesh, *grid, p.ctx.layout, nullptr);
  return cache.emplace(key, std::move(p)).first->second;
}

void BM_Encode(benchmark::State& state, const CodecInfo* codec, std::string scan, int bits) {
  const Prepared& p = prepared(scan, bits);
  std::vector<uint8_t> out;
  for (auto _ : state) {
    auto encoded = encodeMesh(*codec, p.ctx, p.mesh);
    if (!encoded.isOk()) return state.SkipWithError("encode failed");
    out = std::move(encoded->payload);
    benchmark::DoNotOptimize(out.data());
  }
  const double tris = double(p.mesh.triangles.size());
  state.counters["Mtri/s"] = benchmark::Counter(tris * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["bpv"] = 8.0 * out.size() / p.mesh.positions.size();
  state.counters["bpt"] = 8.0 * out.size() / tris;
}

void BM_Decode(benchmark::State& state, const CodecInfo* codec, std::string scan, int bits) {
  const Prepared& p = prepared(scan, bits);
  auto encoded = encodeMesh(*codec, p.ctx, p.mesh);
  if (!encoded.isOk()) return state.SkipWithError("encode failed");
  const std::vector<uint8_t>& out = encoded->payload;
  for (auto _ : state) {
    auto m = codec->decode(p.ctx, payloadVersion(*codec, *encoded), out, limitsOf(encoded->decoded));
    if (!m.isOk()) state.SkipWithError("decode failed");
    benchmark::DoNotOptimize(m);
  }
  const double tris = double(encoded->decoded.faces);  // of the output (a lossy codec's differ from the input's)
  state.counters["Mtri/s"] = benchmark::Counter(tris * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["bpv"] = 8.0 * out.size() / p.mesh.positions.size();
}

// prm at lattice `grid` (a fraction of 2^bits), one tile: decode Mtri/s of output triangles (issue 21's target:
// 10 per core), bits per original vertex, and the share of regular faces in the output.
void BM_PrmDecode(benchmark::State& state, std::string scan, int bits, double grid) {
  const Prepared& p = prepared(scan, bits);
  const CodecInfo& codec = *findCodec(CodecId::kPrm);
  CodecOptions options;
  options.prm.grid = grid;
  auto encoded = encodeMesh(codec, p.ctx, p.mesh, options);
  if (!encoded.isOk()) return state.SkipWithError(encoded.status().toString().c_str());
  const std::vector<uint8_t>& out = encoded->payload;
  QuantizedMesh decoded;
  for (auto _ : state) {
    auto m = codec.decode(p.ctx, payloadVersion(codec, *encoded), out, limitsOf(encoded->decoded));
    if (!m.isOk()) return state.SkipWithError("decode failed");
    decoded = std::move(m).value();
    benchmark::DoNotOptimize(decoded);
  }
  const double tris = double(encoded->decoded.faces);
  const auto relief = latticeFaceReliefs(decoded, prmSpacing(options.prm, bits));
  state.counters["Mtri/s"] = benchmark::Counter(tris * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["bpov"] = 8.0 * out.size() / p.mesh.positions.size();
  state.counters["out_tris"] = tris;
  state.counters["regular"] = double(std::count_if(relief.begin(), relief.end(), [](int8_t r) { return r >= 0; })) /
                              std::max(tris, 1.0);
}

// pm lossless (ratio 1) and simplified to `ratio` of the faces: bits per original vertex, decode Mtri/s of output
// triangles (the whole payload, base mesh and every level of splits), and the base level's share of the payload.
void BM_PmDecode(benchmark::State& state, std::string scan, int bits, double ratio) {
  const Prepared& p = prepared(scan, bits);
  const CodecInfo& codec = *findCodec(CodecId::kPm);
  CodecOptions options;
  if (ratio < 1) options.pm.max_error = 1e30, options.pm.ratio = ratio;  // the face ratio decides
  auto encoded = encodeMesh(codec, p.ctx, p.mesh, options);
  if (!encoded.isOk()) return state.SkipWithError(encoded.status().toString().c_str());
  const std::vector<uint8_t>& out = encoded->payload;
  for (auto _ : state) {
    auto m = codec.decode(p.ctx, payloadVersion(codec, *encoded), out, limitsOf(encoded->decoded));
    if (!m.isOk()) state.SkipWithError("decode failed");
    benchmark::DoNotOptimize(m);
  }
  const double tris = double(encoded->decoded.faces);
  state.counters["Mtri/s"] = benchmark::Counter(tris * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["bpv"] = 8.0 * out.size() / p.mesh.positions.size();
  state.counters["out_faces"] = tris;
  state.counters["levels"] = double(encoded->levels.size());
  state.counters["base_share"] = double(encoded->levels.front().end_bytes) / double(out.size());
}

void BM_Read(benchmark::State& state, std::string scan) {
  const std::string path = scanPath(scan);
  ReadStats stats;
  for (auto _ : state) {
    auto m = readMeshFile(path, &stats, ReadOptions::asInFile());
    if (!m.isOk()) state.SkipWithError(m.status().message().c_str());
    benchmark::DoNotOptimize(m);
  }
  state.counters["Mtri/s"] =
      benchmark::Counter(double(stats.triangles) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["MB/s_file"] = benchmark::Counter(double(std::filesystem::file_size(path)) * state.iterations() / 1e6,
                                                   benchmark::Counter::kIsRate);
}

// Tiling building block: histogram of centroids, refinement, octree tiles, and one lookup per triangle.
void BM_Tiling(benchmark::State& state, std::string scan) {
  const Prepared& p = prepared(scan, 16);
  std::vector<Vec3u> centroids;
  for (const auto& t : p.mesh.triangles)
    centroids.push_back(triangleCentroid(p.mesh.positions[t[0]], p.mesh.positions[t[1]], p.mesh.positions[t[2]]));
  size_t tiles = 0;
  for (auto _ : state) {
    TileHistogram h(16, centroids.size(), static_cast<uint64_t>(state.range(0)));
    for (const auto& c : centroids) h.add(c);
    while (h.beginRefinement())
      for (const auto& c : centroids) h.addRefined(c);
    const TileIndex index = TileIndex::build(h);
    uint64_t sum = 0;
    for (const auto& c : centroids) sum += index.tileOf(c);
    benchmark::DoNotOptimize(sum);
    tiles = index.tiles().size();
  }
  state.counters["Mtri/s"] =
      benchmark::Counter(double(centroids.size()) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["tiles"] = double(tiles);
}

// Simplification to `percent` of the faces (issue 19: >= 2 Mtri/s of input per core on igea to 10%): Mtri/s of
// input, and the result's face count.
void BM_Simplify(benchmark::State& state, std::string scan, SimplifyWeights weights) {
  const Prepared& p = prepared(scan, 16);
  SimplifyOptions o;
  o.weights = weights;
  o.target_faces = p.mesh.triangles.size() * uint64_t(state.range(0)) / 100;
  size_t faces = 0, passes = 0;
  rusage before{};
  getrusage(RUSAGE_SELF, &before);
  for (auto _ : state) {
    auto s = simplify(p.mesh, {}, o);
    if (!s.isOk()) return state.SkipWithError(s.status().message().c_str());
    faces = s->mesh.triangles.size();
    passes = s->pass_ends.size();
    benchmark::DoNotOptimize(s);
  }
  state.counters["Mtri/s"] =
      benchmark::Counter(double(p.mesh.triangles.size()) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["faces_%"] = 100.0 * double(faces) / double(p.mesh.triangles.size());
  state.counters["passes"] = double(passes);
  // Growth of the peak RSS over what the process had reached (reading the scan), per input triangle: a lower
  // bound of the simplifier's peak (its result included), exact when it exceeds the reader's peak.
  rusage after{};
  getrusage(RUSAGE_SELF, &after);
  state.counters["peak_B/tri"] = 1024.0 * double(after.ru_maxrss - before.ru_maxrss) / double(p.mesh.triangles.size());
}

// Piecewise regular remeshing (engine/remesh/remesh.h) of a whole scan at 12 bits, spacing `range(0)` cells:
// input triangles per second (the target: 0.5 Mtri/s per core), the output's size and regular share, and
// the peak memory growth per input triangle (target: at most 300 bytes).
void BM_Remesh(benchmark::State& state, std::string scan) {
  const Prepared& p = prepared(scan, 12);
  const RemeshOptions o{.tau = 0.2, .spacing = uint32_t(state.range(0))};
  size_t faces = 0, regular = 0;
  rusage before{};
  getrusage(RUSAGE_SELF, &before);
  for (auto _ : state) {
    auto r = remeshPiecewiseRegular(p.mesh, {}, o);
    if (!r.isOk()) return state.SkipWithError(r.status().message().c_str());
    faces = r->triangles.size();
    regular = 0;
    for (uint8_t g : r->regular) regular += g;
    benchmark::DoNotOptimize(r);
  }
  state.counters["Mtri/s"] =
      benchmark::Counter(double(p.mesh.triangles.size()) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["out_faces_%"] = 100.0 * double(faces) / double(p.mesh.triangles.size());
  state.counters["regular_%"] = faces ? 100.0 * double(regular) / double(faces) : 0;
  rusage after{};
  getrusage(RUSAGE_SELF, &after);
  state.counters["peak_B/tri"] = 1024.0 * double(after.ru_maxrss - before.ru_maxrss) / double(p.mesh.triangles.size());
}

// The paper's Table 1 analogue: symmetric Hausdorff distance (relative to the diagonal) at `percent` of the faces,
// with the paper's weights and with plain QEM, on the same 16-bit grid.
void BM_SimplifyHausdorff(benchmark::State& state, std::string scan) {
  const Prepared& p = prepared(scan, 16);
  auto device = EmbreeDevice::create();
  if (!device.isOk()) return state.SkipWithError(device.status().message().c_str());
  auto source = readMeshFile(scanPath(scan), nullptr, ReadOptions::asInFile());
  if (!source.isOk()) return state.SkipWithError(source.status().message().c_str());
  auto grid = makeGrid(boundingBox(*source), 16);
  const Mesh original = dequantizeMesh(p.mesh, *grid, AttributeLayout{});
  MeasureSettings ms;
  ms.samples_per_triangle = 4;
  for (auto _ : state) {
    for (SimplifyWeights w : {SimplifyWeights::kShapePreserving, SimplifyWeights::kPlain}) {
      SimplifyOptions o;
      o.weights = w;
      o.target_faces = p.mesh.triangles.size() * uint64_t(state.range(0)) / 100;
      auto s = simplify(p.mesh, {}, o);
      if (!s.isOk()) return state.SkipWithError(s.status().message().c_str());
      auto r = measureMeshes(original, dequantizeMesh(s->mesh, *grid, AttributeLayout{}), ms, *device);
      if (!r.isOk()) return state.SkipWithError(r.status().message().c_str());
      const char* name = w == SimplifyWeights::kPlain ? "plain" : "paper";
      state.counters[std::string("H_") + name] = r->symmetric.max / r->diagonal;
      state.counters[std::string("rms_") + name] = r->symmetric.rms / r->diagonal;
    }
  }
}

#ifdef SCANPRESS_HAVE_MESHOPTIMIZER
// meshoptimizer's simplifier on the same quantized input (float positions of the grid coordinates).
void BM_MeshoptSimplify(benchmark::State& state, std::string scan) {
  const Prepared& p = prepared(scan, 16);
  std::vector<float> xyz;
  for (const auto& q : p.mesh.positions)
    for (uint32_t c : q) xyz.push_back(float(c));
  std::vector<uint32_t> indices;
  for (const auto& t : p.mesh.triangles) indices.insert(indices.end(), t.begin(), t.end());
  std::vector<uint32_t> out(indices.size());
  const size_t target = indices.size() * size_t(state.range(0)) / 100;
  size_t n = 0;
  for (auto _ : state) {
    float error = 0;
    n = meshopt_simplify(out.data(), indices.data(), indices.size(), xyz.data(), p.mesh.positions.size(),
                         3 * sizeof(float), target, 1.0f, 0, &error);
    benchmark::DoNotOptimize(out.data());
  }
  state.counters["Mtri/s"] =
      benchmark::Counter(double(p.mesh.triangles.size()) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["faces_%"] = 100.0 * double(n / 3) / double(p.mesh.triangles.size());
}
#endif

// Where a codec's bits go on every scan: connectivity and geometry per vertex (kdtree's paper, Table 2)
// and connectivity per triangle (EMC's paper, Table 1).
using StatsEncoder =
    std::function<Status(const TileContext&, const QuantizedMesh&, std::vector<uint8_t>&, CodecStats*)>;
void BM_Bits(benchmark::State& state, StatsEncoder encode, std::string scan, int bits) {
  const Prepared& p = prepared(scan, bits);
  std::vector<uint8_t> out;
  CodecStats stats;
  for (auto _ : state) {
    out.clear();
    if (!encode(p.ctx, p.mesh, out, &stats).isOk()) state.SkipWithError("encode failed");
  }
  const double n = double(stats.points);
  state.counters["Mtri/s"] =
      benchmark::Counter(double(p.mesh.triangles.size()) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["bpv"] = 8.0 * out.size() / n;
  state.counters["geo_bpv"] = stats.geometry_bits / n;
  state.counters["conn_bpv"] = stats.connectivity_bits / n;
  state.counters["conn_bpt"] = stats.connectivity_bits / std::max<double>(1, double(stats.triangles));
  state.counters["attr_bpv"] = stats.attribute_bits / n;
  if (stats.edge_expansions > 0)
    state.counters["expansion_%"] = 100.0 * double(stats.edge_expansions) / std::max<double>(1, double(stats.splits));
}

const char* kAllScans[] = {"aneurysm_data.stl.zst", "armadillo.obj.zst", "bun_zipper.ply.zst",
                           "bunny.stl.zst",         "decimated-max.obj", "fandisk.obj",
                           "gargo.ply.zst",         "horse.ply.zst",     "igea.ply.zst",
                           "lato000.ply.zst",       "lucy.ply.zst",      "parasaurolophus_low_normals2.ply.zst",
                           "rs1_normals.ply.zst",   "screwdriver.ply",   "turbineblade.ply.zst"};

const char* kScans[] = {"igea.ply.zst", "bun_zipper.ply.zst", "rs1_normals.ply.zst", "gargo.ply.zst"};

int registerAll() {
  benchmark::RegisterBenchmark("Tiling/igea.ply.zst", BM_Tiling, std::string("igea.ply.zst"))
      ->Arg(16384)
      ->Arg(131072)
      ->Unit(benchmark::kMillisecond);
  const StatsEncoder kdtree = [](const TileContext& c, const QuantizedMesh& m, std::vector<uint8_t>& o,
                                 CodecStats* s) { return kdtreeEncodeWithStats(c, m, o, s); };
  const StatsEncoder edgebreaker = &edgebreakerEncodeWithStats;
  const StatsEncoder octree = [](const TileContext& c, const QuantizedMesh& m, std::vector<uint8_t>& o,
                                 CodecStats* s) { return octreeEncodeWithStats(c, m, o, s, OctreeOptions{true}); };
  // Without contexts (one adaptive model per symbol kind): what the contexts gain. Not decodable.
  const StatsEncoder octree_flat =
      [](const TileContext& c, const QuantizedMesh& m, std::vector<uint8_t>& o, CodecStats* s) {
    return octreeEncodeWithStats(c, m, o, s, OctreeOptions{false});
  };
  for (const char* scan : kAllScans) {
    benchmark::RegisterBenchmark((std::string("KdtreeBits/") + scan + "/12").c_str(), BM_Bits, kdtree,
                                 std::string(scan), 12)
        ->Iterations(1)
        ->Unit(benchmark::kMillisecond);
    for (int bits : {12, 16}) {
      benchmark::RegisterBenchmark(("EdgebreakerBits/" + std::string(scan) + "/" + std::to_string(bits)).c_str(),
                                   BM_Bits, edgebreaker, std::string(scan), bits)
          ->Iterations(1)
          ->Unit(benchmark::kMillisecond);
    }
    for (int bits : {12, 24}) {
      const std::string suffix = std::string(scan) + "/" + std::to_string(bits);
      benchmark::RegisterBenchmark(("OctreeBits/" + suffix).c_str(), BM_Bits, octree, std::string(scan), bits)
          ->Iterations(1)
          ->Unit(benchmark::kMillisecond);
      benchmark::RegisterBenchmark(("OctreeBitsNoContexts/" + suffix).c_str(), BM_Bits, octree_flat, std::string(scan),
                                   bits)
          ->Iterations(1)
          ->Unit(benchmark::kMillisecond);
    }
  }
  for (const char* scan : {"igea.ply.zst", "bun_zipper.ply.zst"}) {
    benchmark::RegisterBenchmark((std::string("Simplify/") + scan).c_str(), BM_Simplify, std::string(scan),
                                 SimplifyWeights::kShapePreserving)
        ->Arg(10)
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark((std::string("SimplifyPlain/") + scan).c_str(), BM_Simplify, std::string(scan),
                                 SimplifyWeights::kPlain)
        ->Arg(10)
        ->Unit(benchmark::kMillisecond);
#ifdef SCANPRESS_HAVE_MESHOPTIMIZER
    benchmark::RegisterBenchmark((std::string("MeshoptSimplify/") + scan).c_str(), BM_MeshoptSimplify,
                                 std::string(scan))
        ->Arg(10)
        ->Unit(benchmark::kMillisecond);
#endif
  }
  for (const char* scan : {"rs1_normals.ply.zst", "lato000.ply.zst", "parasaurolophus_low_normals2.ply.zst",
                           "bun_zipper.ply.zst", "igea.ply.zst"})
    benchmark::RegisterBenchmark((std::string("SimplifyHausdorff/") + scan).c_str(), BM_SimplifyHausdorff,
                                 std::string(scan))
        ->Arg(10)
        ->Iterations(1)
        ->Unit(benchmark::kMillisecond);
  for (const char* scan : {"horse.ply.zst", "bun_zipper.ply.zst", "igea.ply.zst"})
    benchmark::RegisterBenchmark((std::string("Remesh/") + scan).c_str(), BM_Remesh, std::string(scan))
        ->Arg(24)
        ->Iterations(1)
        ->Unit(benchmark::kMillisecond);
  for (const char* scan : {"horse.ply.zst", "bun_zipper.ply.zst", "igea.ply.zst"})
    for (double grid : {0.005, 0.008})
      benchmark::RegisterBenchmark(("PrmDecode/" + std::string(scan) + "/12/grid" + std::to_string(grid)).c_str(),
                                   BM_PrmDecode, std::string(scan), 12, grid)
          ->Unit(benchmark::kMillisecond);
  for (const char* scan : {"igea.ply.zst", "bun_zipper.ply.zst"})
    for (double ratio : {1.0, 0.25, 0.1})
      benchmark::RegisterBenchmark(("PmDecode/" + std::string(scan) + "/16/ratio" + std::to_string(ratio)).c_str(),
                                   BM_PmDecode, std::string(scan), 16, ratio)
          ->Unit(benchmark::kMillisecond);
  for (const char* scan : kScans) {
    benchmark::RegisterBenchmark((std::string("Read/") + scan).c_str(), BM_Read, std::string(scan))
        ->Unit(benchmark::kMillisecond);
    for (const auto& codec : allCodecs())
      for (int bits : {12, 16}) {
        const std::string suffix = std::string(codec.name) + "/" + scan + "/" + std::to_string(bits);
        benchmark::RegisterBenchmark(("Encode/" + suffix).c_str(), BM_Encode, &codec, std::string(scan), bits)
            ->Unit(benchmark::kMillisecond);
        benchmark::RegisterBenchmark(("Decode/" + suffix).c_str(), BM_Decode, &codec, std::string(scan), bits)
            ->Unit(benchmark::kMillisecond);
      }
  }
  return 0;
}
const int kRegistered = registerAll();

}  // namespace
}  // namespace scanpress

BENCHMARK_MAIN();
