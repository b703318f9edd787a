// The simplifier (engine/simplify/simplify.h) on every real scan of ../shared/data: each reaches 10% of its faces
// with a valid result (replayed independently, pass by pass), on the 16-bit grid the codecs use. The readers weld
// the STL soups, as simplify() requires.
#include <gtest/gtest.h>

#include <filesystem>

#include "engine/quantize.h"
#include "engine/simplify/simplify.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs_util.h"
#include "simplify_util.h"

namespace scanpress {
namespace {

class SimplifyScans : public ::testing::TestWithParam<const char*> {};

TEST_P(SimplifyScans, ReachesTenPercentWithAValidMesh) {
  const std::string path = testing::sharedDataDir() + "/" + GetParam();
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
  auto mesh = readMeshFile(path);
  ASSERT_TRUE(mesh.isOk()) << mesh.status().toString();
  auto grid = makeGrid(usedBoundingBox(*mesh), 16);
  ASSERT_TRUE(grid.isOk());
  auto q = quantizeMesh(*mesh, *grid, AttributeLayout{}, nullptr);
  ASSERT_TRUE(q.isOk()) << q.status().toString();
  for (SimplifyWeights w : {SimplifyWeights::kShapePreserving, SimplifyWeights::kPlain}) {
    SimplifyOptions o;
    o.weights = w;
    o.target_faces = q->triangles.size() / 10;
    auto s = simplify(*q, {}, o);
    ASSERT_TRUE(s.isOk()) << s.status().toString();
    testing::expectValidSimplification(*q, {}, *s);
    EXPECT_LE(s->mesh.triangles.size(), o.target_faces) << "weights " << int(w);
  }
}

INSTANTIATE_TEST_SUITE_P(Data, SimplifyScans,
                         ::testing::Values("igea.ply.zst", "rs1_normals.ply.zst", "turbineblade.ply.zst",
                                           "lucy.ply.zst", "horse.ply.zst", "armadillo.obj.zst", "bun_zipper.ply.zst",
                                           "bunny.stl.zst", "aneurysm_data.stl.zst", "lato000.ply.zst",
                                           "parasaurolophus_low_normals2.ply.zst", "gargo.ply.zst", "screwdriver.ply",
                                           "decimated-max.obj", "fandisk.obj"),
                         [](const auto& info) {
  std::string n = info.param;
  for (char& c : n)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return n;
});

}  // namespace
}  // namespace scanpress
