// Whole-pipeline throughput (read, quantize, tile, encode with `store`, write) at 1 and 2 threads, on the largest
// scan of ../shared/data and on a synth scan of 20M triangles (generated once into $SCANPRESS_BENCH_DIR or the
// temp directory): Mtri/s, peak RSS, and the 2-thread speedup measured as a ratio in the same iteration; and
// the scale series (synth 1M, 10M, 50M triangles, in memory and with a 512 MiB budget). The synth files take
// about 20 + 190 + 380 + 950 MB of disk.
//
// Each measurement runs in a forked child, so that its peak RSS (wait4's ru_maxrss) is its own.
#include <benchmark/benchmark.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <stdexcept>

#include "jobs/commands.h"
#include "jobs/synth.h"

namespace scanpress {
namespace {

namespace fs = std::filesystem;

std::string benchDir() {
  const char* env = std::getenv("SCANPRESS_BENCH_DIR");
  const fs::path dir = env ? fs::path(env) : fs::temp_directory_path() / "scanpress-bench";
  fs::create_directories(dir);
  return dir.string();
}

std::string largestScan() {
  const std::string p = std::string(SCANPRESS_SHARED_DATA) + "/igea.ply.zst";
  return fs::exists(p) ? p : std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
}

std::string synthScan(uint64_t triangles) {
  const std::string path = benchDir() + "/synth-" + std::to_string(triangles) + ".ply";
  if (!fs::exists(path)) {
    SynthSettings s;
    s.output = path;
    s.triangles = triangles;
    auto r = synthesize(s);
    if (!r.isOk()) throw std::runtime_error(r.status().toString());
  }
  return path;
}

struct Measured {
  double seconds = 0;
  uint64_t peak_rss = 0;
  bool ok = false;
};

// Encodes in a child process; returns wall time and the child's peak RSS.
Measured encodeInChild(const std::string& input, int threads, uint64_t budget) {
  const std::string out = benchDir() + "/out-" + std::to_string(::getpid()) + ".spz";
  const auto start = std::chrono::steady_clock::now();
  const pid_t pid = ::fork();
  if (pid == 0) {
    EncodeSettings s;
    s.input = input;
    s.output = out;
    s.threads = threads;
    s.memory_budget = budget;
    _exit(encodeFile(s).isOk() ? 0 : 1);
  }
  int status = 0;
  struct rusage ru {};
  ::wait4(pid, &status, 0, &ru);
  Measured m;
  m.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  m.peak_rss = static_cast<uint64_t>(ru.ru_maxrss) * 1024;
  m.ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  std::error_code ec;
  fs::remove(out, ec);
  return m;
}

uint64_t triangleCount(const std::string& path) {
  struct Count : MeshSink {
    Status vertices(std::span<const Vec3d>, std::span<const Vec3f>, std::span<const Rgba8>, uint8_t,
                    const ScalarChunk&) override {
      return Status::ok();
    }
    Status triangles(std::span<const Triangle>) override { return Status::ok(); }
    Status vertexNormals(uint64_t, std::span<const Vec3f>) override { return Status::ok(); }
  } sink;
  auto r = readMesh(path, sink, ReadOptions::asInFile());
  return r.isOk() ? r->triangles : 0;
}

void BM_Pipeline(benchmark::State& state, std::string (*scan)(), int threads, uint64_t budget) {
  const std::string input = scan();
  const double tris = double(triangleCount(input));
  uint64_t rss = 0;
  for (auto _ : state) {
    const Measured m = encodeInChild(input, threads, budget);
    if (!m.ok) state.SkipWithError("encode failed");
    state.SetIterationTime(m.seconds);
    rss = std::max(rss, m.peak_rss);
  }
  state.counters["Mtri/s"] = benchmark::Counter(tris * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["peak_rss_MB"] = rss / 1e6;
  state.counters["Mtri"] = tris / 1e6;
}

void BM_Speedup(benchmark::State& state, std::string (*scan)()) {
  const std::string input = scan();
  double t1 = 0, t2 = 0;
  for (auto _ : state) {
    const Measured a = encodeInChild(input, 1, 0), b = encodeInChild(input, 2, 0);
    if (!a.ok || !b.ok) state.SkipWithError("encode failed");
    t1 += a.seconds;
    t2 += b.seconds;
    state.SetIterationTime(a.seconds + b.seconds);
  }
  state.counters["speedup_2_threads"] = t2 > 0 ? t1 / t2 : 0;
}

std::string igea() { return largestScan(); }
std::string synth1m() { return synthScan(1000000); }
std::string synth10m() { return synthScan(10000000); }
std::string synth20m() { return synthScan(20000000); }
std::string synth50m() { return synthScan(50000000); }

int registerAll() {
  for (int threads : {1, 2}) {
    benchmark::RegisterBenchmark(("Pipeline/igea/threads:" + std::to_string(threads)).c_str(), BM_Pipeline, &igea,
                                 threads, uint64_t(0))
        ->UseManualTime()
        ->Unit(benchmark::kMillisecond)
        ->Iterations(5);
    benchmark::RegisterBenchmark(("Pipeline/synth20M/threads:" + std::to_string(threads)).c_str(), BM_Pipeline,
                                 &synth20m, threads, uint64_t(0))
        ->UseManualTime()
        ->Unit(benchmark::kMillisecond)
        ->Iterations(2);
  }
  benchmark::RegisterBenchmark("Pipeline/synth20M/threads:2/budget:256M", BM_Pipeline, &synth20m, 2,
                               uint64_t(256) << 20)
      ->UseManualTime()
      ->Unit(benchmark::kMillisecond)
      ->Iterations(2);
  // Scale: cost per triangle should stay flat with size; with a budget, so should memory.
  for (auto [name, fn] :
       {std::pair<const char*, std::string (*)()>{"1M", &synth1m}, {"10M", &synth10m}, {"50M", &synth50m}}) {
    benchmark::RegisterBenchmark((std::string("Scale/synth") + name + "/threads:2").c_str(), BM_Pipeline, fn, 2,
                                 uint64_t(0))
        ->UseManualTime()
        ->Unit(benchmark::kMillisecond)
        ->Iterations(1);
    benchmark::RegisterBenchmark((std::string("Scale/synth") + name + "/threads:2/budget:512M").c_str(), BM_Pipeline,
                                 fn, 2, uint64_t(512) << 20)
        ->UseManualTime()
        ->Unit(benchmark::kMillisecond)
        ->Iterations(1);
  }
  benchmark::RegisterBenchmark("Speedup/igea", BM_Speedup, &igea)
      ->UseManualTime()
      ->Unit(benchmark::kMillisecond)
      ->Iterations(5);
  benchmark::RegisterBenchmark("Speedup/synth20M", BM_Speedup, &synth20m)
      ->UseManualTime()
      ->Unit(benchmark::kMillisecond)
      ->Iterations(2);
  return 0;
}
const int kRegistered = registerAll();

}  // namespace
}  // namespace scanpress

BENCHMARK_MAIN();
