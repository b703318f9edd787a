// Closest-point queries per second per core: scanpress (Embree scene, exact double-precision distances) side by
// side with CGAL's AABB tree (bench-only dependency), on the same query points, in one run. Queries: Metro
// samples of igea against its 10% simplification (meshoptimizer, bench-only) and back.
#include <benchmark/benchmark.h>

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>
#include <meshoptimizer.h>

#include <filesystem>
#include <stdexcept>
#include <vector>

#include "engine/metro.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "spatial/surface_index.h"

namespace scanpress {
namespace {

using K = CGAL::Simple_cartesian<double>;
using CgalTriangle = K::Triangle_3;
using Primitive = CGAL::AABB_triangle_primitive<K, std::vector<CgalTriangle>::const_iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;

struct Fixture {
  std::string scan;  // the file's name: igea from ../shared/data, or the bundled bunny when that is missing
  Mesh full, reduced;
  std::vector<Vec3d> on_full, on_reduced;  // query points
};

const Fixture& fixture() {
  static Fixture f = [] {
    Fixture x;
    std::string path = std::string(SCANPRESS_SHARED_DATA) + "/igea.ply.zst";
    if (!std::filesystem::exists(path)) path = std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
    x.scan = std::filesystem::path(path).filename().string();
    auto m = readMeshFile(path, nullptr, ReadOptions::asInFile());
    if (!m.isOk()) throw std::runtime_error(m.status().toString());
    x.full = std::move(m).value();
    std::vector<float> pos;
    for (const auto& p : x.full.positions)
      for (double c : p) pos.push_back(static_cast<float>(c));
    std::vector<unsigned> idx;
    for (const auto& t : x.full.triangles) idx.insert(idx.end(), t.begin(), t.end());
    std::vector<unsigned> out(idx.size());
    const size_t n = meshopt_simplify(out.data(), idx.data(), idx.size(), pos.data(), x.full.positions.size(), 12,
                                      idx.size() / 10, 1e-2f, 0, nullptr);
    x.reduced.positions = x.full.positions;
    for (size_t i = 0; i + 2 < n; i += 3) x.reduced.triangles.push_back({out[i], out[i + 1], out[i + 2]});
    SampleOptions opt;
    opt.density = 200000 / surfaceArea(x.full.positions, x.full.triangles);  // ~200k queries each way
    opt.vertices = false;
    sampleSurface(x.full.positions, x.full.triangles, opt, x.on_full);
    opt.stream = 1;
    sampleSurface(x.reduced.positions, x.reduced.triangles, opt, x.on_reduced);
    return x;
  }();
  return f;
}

// The counters both kinds of benchmark report: queries per second and the mean distance of the last pass.
void report(benchmark::State& state, const Fixture& f, size_t queries, double sum) {
  state.counters["Mqueries/s"] =
      benchmark::Counter(double(queries) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["mean_distance"] = sum / double(queries);
  state.SetLabel(f.scan);
}

// batch: closestMany over blocks of 1024 samples, as `scanpress measure` queries; otherwise one closest() per
// sample, each starting from the previous answer.
void BM_ScanpressClosest(benchmark::State& state, bool to_reduced, bool batch) {
  const Fixture& f = fixture();
  auto device = *EmbreeDevice::create();
  const Mesh& target = to_reduced ? f.reduced : f.full;
  const auto& queries = to_reduced ? f.on_full : f.on_reduced;
  auto index = SurfaceIndex::build(device, target.positions, target.triangles);
  if (!index.isOk()) return state.SkipWithError("build failed");
  double sum = 0;
  std::vector<SurfaceIndex::Closest> out(1024);
  // closestMany builds its records on its first call, outside the timing like Embree's scene (and CGAL's tree).
  if (batch) index->closestMany(std::span(queries).first(std::min<size_t>(2, queries.size())), out);
  for (auto _ : state) {  // one thread: per-core rate
    double s = 0;
    if (batch) {
      for (size_t b = 0; b < queries.size(); b += out.size()) {
        const size_t n = std::min(out.size(), queries.size() - b);
        index->closestMany(std::span(queries).subspan(b, n), std::span(out).first(n));
        for (size_t k = 0; k < n; ++k) s += out[k].distance;
      }
    } else {
      uint32_t hint = UINT32_MAX;
      for (const auto& q : queries) {
        const auto c = index->closest(q, hint);
        s += c.distance;
        hint = c.triangle;
      }
    }
    benchmark::DoNotOptimize(s);
    sum = s;
  }
  report(state, f, queries.size(), sum);
}

void BM_CgalClosest(benchmark::State& state, bool to_reduced) {
  const Fixture& f = fixture();
  const Mesh& target = to_reduced ? f.reduced : f.full;
  const auto& queries = to_reduced ? f.on_full : f.on_reduced;
  std::vector<CgalTriangle> tris;
  auto pt = [&](uint32_t v) {
    return K::Point_3(target.positions[v][0], target.positions[v][1], target.positions[v][2]);
  };
  for (const auto& t : target.triangles) tris.emplace_back(pt(t[0]), pt(t[1]), pt(t[2]));
  Tree tree(tris.begin(), tris.end());
  tree.accelerate_distance_queries();
  double sum = 0;
  for (auto _ : state) {
    double s = 0;
    for (const auto& q : queries) s += std::sqrt(tree.squared_distance(K::Point_3(q[0], q[1], q[2])));
    benchmark::DoNotOptimize(s);
    sum = s;
  }
  report(state, f, queries.size(), sum);
}

// Five repetitions each, reported as mean, median, stddev and cv, the repetitions of all six run in random order
// (main below): single runs vary on a shared machine, and the ratio to CGAL is read from two medians taken over
// the same stretch of time.
#define SCANPRESS_DISTANCE_BENCH(...) \
  BENCHMARK_CAPTURE(__VA_ARGS__)->Unit(benchmark::kMillisecond)->Repetitions(5)->ReportAggregatesOnly(true)
SCANPRESS_DISTANCE_BENCH(BM_ScanpressClosest, igea_to_10pct, true, true);
SCANPRESS_DISTANCE_BENCH(BM_ScanpressClosest, igea_to_10pct_one_by_one, true, false);
SCANPRESS_DISTANCE_BENCH(BM_CgalClosest, igea_to_10pct, true);
SCANPRESS_DISTANCE_BENCH(BM_ScanpressClosest, 10pct_to_igea, false, true);
SCANPRESS_DISTANCE_BENCH(BM_ScanpressClosest, 10pct_to_igea_one_by_one, false, false);
SCANPRESS_DISTANCE_BENCH(BM_CgalClosest, 10pct_to_igea, false);

}  // namespace
}  // namespace scanpress

// BENCHMARK_MAIN with random interleaving on by default (a flag given on the command line comes after, and wins).
int main(int argc, char** argv) {
  static char interleave[] = "--benchmark_enable_random_interleaving=true";
  std::vector<char*> args(argv, argv + argc);
  args.insert(args.begin() + 1, interleave);
  int count = static_cast<int>(args.size());
  benchmark::Initialize(&count, args.data());
  if (benchmark::ReportUnrecognizedArguments(count, args.data())) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
