#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "engine/entropy/bit_io.h"
#include "engine/entropy/range_coder.h"
#include "engine/io/crc32c.h"

namespace scanpress {
namespace {

TEST(Crc32c, KnownVectors) {
  const std::string s = "123456789";
  EXPECT_EQ(crc32c(std::span(reinterpret_cast<const uint8_t*>(s.data()), s.size())), 0xE3069283u);
  std::vector<uint8_t> zeros(32, 0);
  EXPECT_EQ(crc32c(zeros), 0x8A9136AAu);
  // Piecewise equals whole.
  std::vector<uint8_t> data(1000);
  for (size_t i = 0; i < data.size(); ++i) data[i] = static_cast<uint8_t>(i * 7 + 3);
  const uint32_t whole = crc32c(data);
  EXPECT_EQ(crc32c(std::span(data).subspan(357), crc32c(std::span(data).first(357))), whole);
}

// A mixed stream: context bits, two symbol alphabets, explicit frequencies, raw and uniform values.
struct Op {
  int kind;
  uint32_t value;
  uint32_t aux;
};

std::vector<Op> randomOps(uint32_t seed, size_t n) {
  std::mt19937 rng0(seed);
  auto rng = [&rng0]() { return static_cast<uint32_t>(rng0()); };
  std::vector<Op> ops;
  for (size_t i = 0; i < n; ++i) {
    const int kind = static_cast<int>(rng() % 6);
    switch (kind) {
      case 0: ops.push_back({0, (rng() % 10) < 2 ? 1u : 0u, rng() % 4}); break;  // skewed bit, context
      case 1:
        ops.push_back({1, static_cast<uint32_t>(std::min<double>(7, std::abs(std::normal_distribution<>(0, 2)(rng0)))),
                       0});
        break;
      case 2: ops.push_back({2, rng() % 300, 0}); break;  // 300-symbol alphabet
      case 3: {                                           // explicit distribution
        const uint32_t total = 1 + rng() % 65536;
        ops.push_back({3, rng() % total, total});
        break;
      }
      case 4: {
        const int bits = static_cast<int>(rng() % 33);
        ops.push_back({4,
                       bits == 32 ? static_cast<uint32_t>(rng()) : static_cast<uint32_t>(rng() & ((1ull << bits) - 1)),
                       static_cast<uint32_t>(bits)});
        break;
      }
      default: {
        const uint32_t count = 1 + static_cast<uint32_t>(rng() % 5000000);
        ops.push_back({5, static_cast<uint32_t>(rng() % count), count});
      }
    }
  }
  return ops;
}

std::vector<uint8_t> encodeOps(const std::vector<Op>& ops) {
  std::vector<uint8_t> out;
  RangeEncoder enc(out);
  BitModel bits[4];
  SymbolModel small(8), large(300);
  for (const Op& op : ops) {
    switch (op.kind) {
      case 0: enc.encodeBit(bits[op.aux], static_cast<int>(op.value)); break;
      case 1: enc.encodeSymbol(small, op.value); break;
      case 2: enc.encodeSymbol(large, op.value); break;
      case 3: enc.encodeFrequency(op.value, 1, op.aux); break;
      case 4: enc.encodeBits(op.value, static_cast<int>(op.aux)); break;
      default: enc.encodeUniform(op.value, op.aux);
    }
  }
  enc.finish();
  return out;
}

TEST(RangeCoder, MixedStreamRoundTrips) {
  for (uint32_t seed = 1; seed <= 20; ++seed) {
    const auto ops = randomOps(seed, 20000);
    const auto bytes = encodeOps(ops);
    RangeDecoder dec(bytes);
    BitModel bits[4];
    SymbolModel small(8), large(300);
    for (size_t i = 0; i < ops.size(); ++i) {
      const Op& op = ops[i];
      uint32_t got = 0;
      switch (op.kind) {
        case 0: got = static_cast<uint32_t>(dec.decodeBit(bits[op.aux])); break;
        case 1: got = dec.decodeSymbol(small); break;
        case 2: got = dec.decodeSymbol(large); break;
        case 3: got = dec.peekFrequency(op.aux), dec.consumeFrequency(got, 1); break;
        case 4: got = dec.decodeBits(static_cast<int>(op.aux)); break;
        default: got = dec.decodeUniform(op.aux);
      }
      ASSERT_EQ(got, op.value) << "seed " << seed << " op " << i << " kind " << op.kind;
    }
    EXPECT_FALSE(dec.overrun()) << "a valid stream must decode without reading past its end";
    EXPECT_LE(dec.consumed(), bytes.size());
  }
}

TEST(RangeCoder, EmptyStreamIsFourBytes) {
  std::vector<uint8_t> out;
  RangeEncoder enc(out);
  enc.finish();
  EXPECT_EQ(out.size(), 4u);
  RangeDecoder dec(out);
  EXPECT_FALSE(dec.overrun());
}

TEST(RangeCoder, SkewedBitsCompressNearEntropy) {
  std::mt19937 rng(7);
  const double p1 = 0.05;
  const size_t n = 200000;
  std::vector<int> bits(n);
  for (auto& b : bits) b = std::bernoulli_distribution(p1)(rng);
  std::vector<uint8_t> out;
  RangeEncoder enc(out);
  BitModel m;
  for (int b : bits) enc.encodeBit(m, b);
  enc.finish();
  const double entropy = n * (-(p1 * std::log2(p1) + (1 - p1) * std::log2(1 - p1))) / 8.0;
  EXPECT_LT(out.size(), entropy * 1.03) << "adaptive binary model should be within 3% of the entropy";
  RangeDecoder dec(out);
  BitModel d;
  for (int b : bits) ASSERT_EQ(dec.decodeBit(d), b);
}

TEST(RangeCoder, SymbolModelLearnsDistribution) {
  std::mt19937 rng(11);
  std::geometric_distribution<int> geo(0.3);
  const size_t n = 200000;
  std::vector<uint32_t> sym(n);
  double entropy_bits = 0;
  std::vector<double> counts(64, 0);
  for (auto& s : sym) s = static_cast<uint32_t>(std::min(63, geo(rng))), counts[s]++;
  for (double c : counts)
    if (c > 0) entropy_bits -= c * std::log2(c / n);
  std::vector<uint8_t> out;
  RangeEncoder enc(out);
  SymbolModel m(64);
  for (auto s : sym) enc.encodeSymbol(m, s);
  enc.finish();
  EXPECT_LT(out.size(), entropy_bits / 8 * 1.03);
  RangeDecoder dec(out);
  SymbolModel d(64);
  for (auto s : sym) ASSERT_EQ(dec.decodeSymbol(d), s);
}

TEST(RangeCoder, TruncatedAndCorruptInputNeverReadsOutOfBounds) {
  const auto ops = randomOps(99, 3000);
  const auto bytes = encodeOps(ops);
  std::mt19937 rng(5);
  for (size_t cut = 0; cut < bytes.size(); cut += 1 + cut / 16) {
    // An exact-size heap copy so ASan flags any read past the end.
    std::vector<uint8_t> part(bytes.begin(), bytes.begin() + static_cast<ptrdiff_t>(cut));
    const bool flipped = rng() % 2 && !part.empty();
    if (flipped) part[rng() % part.size()] ^= static_cast<uint8_t>(1 + rng() % 255);
    RangeDecoder dec(part);
    BitModel bits[4];
    SymbolModel small(8), large(300);
    for (const Op& op : ops) {
      uint32_t v = 0;
      switch (op.kind) {
        case 0:
          v = static_cast<uint32_t>(dec.decodeBit(bits[op.aux]));
          ASSERT_LE(v, 1u);
          break;
        case 1:
          v = dec.decodeSymbol(small);
          ASSERT_LT(v, 8u);
          break;
        case 2:
          v = dec.decodeSymbol(large);
          ASSERT_LT(v, 300u);
          break;
        case 3:
          v = dec.peekFrequency(op.aux);
          ASSERT_LT(v, op.aux);
          dec.consumeFrequency(v, 1);
          break;
        case 4: dec.decodeBits(static_cast<int>(op.aux)); break;
        default: v = dec.decodeUniform(op.aux); ASSERT_LT(v, op.aux);
      }
    }
    if (!flipped) {
      EXPECT_TRUE(dec.overrun()) << "cut at " << cut << " of " << bytes.size();
    }
  }
}

TEST(BitIo, RoundTripAndOverrun) {
  std::mt19937 rng(3);
  std::vector<std::pair<uint32_t, int>> values;
  std::vector<uint8_t> out;
  BitWriter w(out);
  for (int i = 0; i < 10000; ++i) {
    const int bits = static_cast<int>(rng() % 33);
    const uint32_t v = bits == 32 ? static_cast<uint32_t>(rng()) : static_cast<uint32_t>(rng() & ((1ull << bits) - 1));
    values.emplace_back(v, bits);
    w.put(v, bits);
  }
  w.flush();
  BitReader r(out);
  for (auto [v, bits] : values) ASSERT_EQ(r.get(bits), v);
  EXPECT_FALSE(r.overrun());
  r.get(16);
  EXPECT_TRUE(r.overrun());
  EXPECT_EQ(bitsFor(0), 0);
  EXPECT_EQ(bitsFor(1), 1);
  EXPECT_EQ(bitsFor(255), 8);
  EXPECT_EQ(bitsFor(256), 9);
}

}  // namespace
}  // namespace scanpress
