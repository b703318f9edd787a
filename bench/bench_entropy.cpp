// Entropy coder throughput: MB/s of coded output and of equivalent input symbols, for the adaptive binary
// coder (context-modelled bits), the adaptive multi-symbol coder, and raw bit packing.
#include <benchmark/benchmark.h>

#include <random>

#include "engine/entropy/bit_io.h"
#include "engine/entropy/range_coder.h"
#include "engine/io/crc32c.h"

namespace scanpress {
namespace {

constexpr size_t kCount = 1 << 20;

std::vector<int> skewedBits(double p1) {
  std::mt19937 rng(1);
  std::vector<int> bits(kCount);
  for (auto& b : bits) b = std::bernoulli_distribution(p1)(rng);
  return bits;
}

std::vector<uint32_t> geometricSymbols(uint32_t alphabet) {
  std::mt19937 rng(2);
  std::geometric_distribution<int> geo(0.2);
  std::vector<uint32_t> s(kCount);
  for (auto& x : s) x = static_cast<uint32_t>(std::min<int>(static_cast<int>(alphabet) - 1, geo(rng)));
  return s;
}

// Binary: 8 contexts (as a codec would use), p(1) = 0.1.
void BM_BinaryEncode(benchmark::State& state) {
  const auto bits = skewedBits(0.1);
  std::vector<uint8_t> out;
  for (auto _ : state) {
    out.clear();
    RangeEncoder enc(out);
    BitModel m[8];
    for (size_t i = 0; i < bits.size(); ++i) enc.encodeBit(m[i & 7], bits[i]);
    enc.finish();
    benchmark::DoNotOptimize(out.data());
  }
  state.counters["Mbit/s"] = benchmark::Counter(double(kCount) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["MB/s_out"] =
      benchmark::Counter(double(out.size()) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["bits_per_bit"] = 8.0 * out.size() / kCount;
}
BENCHMARK(BM_BinaryEncode)->Unit(benchmark::kMillisecond);

void BM_BinaryDecode(benchmark::State& state) {
  const auto bits = skewedBits(0.1);
  std::vector<uint8_t> out;
  RangeEncoder enc(out);
  BitModel m[8];
  for (size_t i = 0; i < bits.size(); ++i) enc.encodeBit(m[i & 7], bits[i]);
  enc.finish();
  for (auto _ : state) {
    RangeDecoder dec(out);
    BitModel d[8];
    int sum = 0;
    for (size_t i = 0; i < bits.size(); ++i) sum += dec.decodeBit(d[i & 7]);
    benchmark::DoNotOptimize(sum);
  }
  state.counters["Mbit/s"] = benchmark::Counter(double(kCount) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["MB/s_in"] =
      benchmark::Counter(double(out.size()) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_BinaryDecode)->Unit(benchmark::kMillisecond);

void BM_SymbolEncode(benchmark::State& state) {
  const uint32_t alphabet = static_cast<uint32_t>(state.range(0));
  const auto syms = geometricSymbols(alphabet);
  std::vector<uint8_t> out;
  for (auto _ : state) {
    out.clear();
    RangeEncoder enc(out);
    SymbolModel m(alphabet);
    for (uint32_t s : syms) enc.encodeSymbol(m, s);
    enc.finish();
    benchmark::DoNotOptimize(out.data());
  }
  state.counters["Msym/s"] = benchmark::Counter(double(kCount) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["MB/s_out"] =
      benchmark::Counter(double(out.size()) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["bits_per_sym"] = 8.0 * out.size() / kCount;
}
BENCHMARK(BM_SymbolEncode)->Arg(16)->Arg(256)->Unit(benchmark::kMillisecond);

void BM_SymbolDecode(benchmark::State& state) {
  const uint32_t alphabet = static_cast<uint32_t>(state.range(0));
  const auto syms = geometricSymbols(alphabet);
  std::vector<uint8_t> out;
  RangeEncoder enc(out);
  SymbolModel m(alphabet);
  for (uint32_t s : syms) enc.encodeSymbol(m, s);
  enc.finish();
  for (auto _ : state) {
    RangeDecoder dec(out);
    SymbolModel d(alphabet);
    uint32_t sum = 0;
    for (size_t i = 0; i < syms.size(); ++i) sum += dec.decodeSymbol(d);
    benchmark::DoNotOptimize(sum);
  }
  state.counters["Msym/s"] = benchmark::Counter(double(kCount) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
  state.counters["MB/s_in"] =
      benchmark::Counter(double(out.size()) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_SymbolDecode)->Arg(16)->Arg(256)->Unit(benchmark::kMillisecond);

void BM_BitPack(benchmark::State& state) {
  std::vector<uint8_t> out;
  for (auto _ : state) {
    out.clear();
    BitWriter w(out);
    for (size_t i = 0; i < kCount; ++i) w.put(static_cast<uint32_t>(i), 17);
    w.flush();
    BitReader r(out);
    uint32_t sum = 0;
    for (size_t i = 0; i < kCount; ++i) sum += r.get(17);
    benchmark::DoNotOptimize(sum);
  }
  state.counters["MB/s"] =
      benchmark::Counter(double(out.size()) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_BitPack)->Unit(benchmark::kMillisecond);

void BM_Crc32c(benchmark::State& state) {
  std::vector<uint8_t> data(16 << 20, 0x5A);
  for (auto _ : state) benchmark::DoNotOptimize(crc32c(data));
  state.counters["MB/s"] =
      benchmark::Counter(double(data.size()) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_Crc32c)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace scanpress

BENCHMARK_MAIN();
