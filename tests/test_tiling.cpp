// The tiler (spatial/tiling.h): tiles adapt to density, cover every centroid, and are deterministic.
#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <vector>

#include "spatial/tiling.h"

namespace scanpress {
namespace {

TEST(Tiling, TilesCoverEveryCentroidDeterministically) {
  std::mt19937 rng(9);
  std::vector<Vec3u> centroids;
  // A dense cluster and a sparse shell: tiles must adapt.
  for (int i = 0; i < 200000; ++i) {
    const bool dense = i % 2;
    const uint32_t base = dense ? 30000 : 0, span = dense ? 2000 : 65535;
    centroids.push_back({base + static_cast<uint32_t>(rng() % span), base + static_cast<uint32_t>(rng() % span),
                         base + static_cast<uint32_t>(rng() % span)});
  }
  auto build = [&] {
    TileHistogram h(16, centroids.size(), 8192);
    for (const auto& c : centroids) h.add(c);
    while (h.beginRefinement())
      for (const auto& c : centroids) h.addRefined(c);
    return TileIndex::build(h);
  };
  const TileIndex a = build(), b = build();
  ASSERT_EQ(a.tiles().size(), b.tiles().size());
  std::vector<uint64_t> counted(a.tiles().size(), 0);
  for (const auto& c : centroids) {
    const uint32_t t = a.tileOf(c);
    ASSERT_LT(t, a.tiles().size());
    ASSERT_EQ(t, b.tileOf(c));
    ++counted[t];
    const TileInfo& info = a.tiles()[t];
    for (int k = 0; k < 3; ++k) ASSERT_TRUE(c[k] >= info.lo[k] && c[k] <= info.hi[k]);
  }
  uint64_t total = 0;
  double dense_size = 0, sparse_size = 0;
  int dense_n = 0, sparse_n = 0;
  for (size_t t = 0; t < counted.size(); ++t) {
    EXPECT_EQ(counted[t], a.tiles()[t].triangles);
    EXPECT_GT(counted[t], 0u);
    EXPECT_LE(counted[t], 8192u);
    total += counted[t];
    const auto& info = a.tiles()[t];
    const double size = double(info.hi[0] - info.lo[0] + 1);
    if (info.lo[0] >= 30000 && info.hi[0] < 32000) dense_size += size, ++dense_n;
    else sparse_size += size, ++sparse_n;
  }
  EXPECT_EQ(total, centroids.size());
  ASSERT_GT(dense_n, 0);
  ASSERT_GT(sparse_n, 0);
  EXPECT_LT(dense_size / dense_n, sparse_size / sparse_n) << "dense regions should get smaller tiles";
}

}  // namespace
}  // namespace scanpress
