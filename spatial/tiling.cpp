#include "spatial/tiling.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <unordered_map>
#include <unordered_set>

// libopenvdb instantiates the Int32 grid and its tree (virtual functions and all): declared extern here, they are not
// instantiated again in this file, which took most of its compile time.
extern template class openvdb::Grid<openvdb::Int32Tree>;
extern template class openvdb::tree::Tree<openvdb::Int32Tree::RootNodeType>;

namespace scanpress {
namespace {

constexpr int kMaxDepth = 21;     // octree depth limit: node coordinates fit 21 bits per axis
constexpr int kRefineStep = 4;    // a refined cell splits 16 ways per axis
constexpr int32_t kRefined = -2;  // index marker: look at the next level
constexpr int32_t kNoTile = -1;

uint64_t packCoord(uint32_t x, uint32_t y, uint32_t z) { return (uint64_t(x) << 42) | (uint64_t(y) << 21) | z; }
Vec3u unpack(uint64_t k) { return {uint32_t(k >> 42), uint32_t((k >> 21) & 0x1FFFFF), uint32_t(k & 0x1FFFFF)}; }

openvdb::Coord cellOf(const Vec3u& c, int shift) {
  return openvdb::Coord(static_cast<int32_t>(c[0] >> shift), static_cast<int32_t>(c[1] >> shift),
                        static_cast<int32_t>(c[2] >> shift));
}

}  // namespace

struct TileHistogram::Impl {
  struct Level {
    explicit Level(int s)
        : shift(s),
          counts(openvdb::Int32Grid::create(0)),
          acc(std::make_unique<openvdb::Int32Grid::Accessor>(counts->getAccessor())) {}
    int shift;
    openvdb::Int32Grid::Ptr counts;
    std::unique_ptr<openvdb::Int32Grid::Accessor> acc;  // heap-held: stays valid when `levels` grows
    std::unordered_set<uint64_t> refined;  // cells of this level whose centroids were counted one level finer
  };
  std::vector<Level> levels;
  static void bump(Level& l, const openvdb::Coord& ijk) {
    // 32-bit counts: cells are sized to hold about target / 16 centroids, and overfull ones are refined.
    l.acc->setValue(ijk, static_cast<int32_t>(static_cast<uint32_t>(l.acc->getValue(ijk)) + 1));
  }
};

TileHistogram::TileHistogram(int grid_bits, uint64_t total_triangles, uint64_t target)
    : impl_(std::make_unique<Impl>()), grid_bits_(grid_bits), target_(std::max<uint64_t>(target, 1)) {
  // A surface through R^3 cells touches on the order of R^2 of them (about pi R^2 for a closed scan that fills
  // its box); aim for 1/16 of the target or less per touched cell: R = sqrt(16 N / target), rounded up to a
  // power of two.
  const double r = std::sqrt(16.0 * double(std::max<uint64_t>(total_triangles, 1)) / double(target_));
  int levels = 0;
  while (levels < std::min(grid_bits, kMaxDepth) && (1u << levels) < r) ++levels;
  shift_ = grid_bits - levels;
  impl_->levels.emplace_back(shift_);
}

TileHistogram::~TileHistogram() = default;
TileHistogram::TileHistogram(TileHistogram&&) noexcept = default;
TileHistogram& TileHistogram::operator=(TileHistogram&&) noexcept = default;

void TileHistogram::add(const Vec3u& c) { Impl::bump(impl_->levels.front(), cellOf(c, shift_)); }

bool TileHistogram::beginRefinement() {
  Impl::Level& last = impl_->levels.back();
  const int depth = grid_bits_ - last.shift;
  if (last.shift == 0 || depth >= kMaxDepth) return false;
  for (auto it = last.counts->cbeginValueOn(); it; ++it)
    if (static_cast<uint32_t>(*it) > target_) {
      const openvdb::Coord c = it.getCoord();
      last.refined.insert(packCoord(uint32_t(c.x()), uint32_t(c.y()), uint32_t(c.z())));
    }
  if (last.refined.empty()) return false;
  const int finer = std::max({0, last.shift - kRefineStep, grid_bits_ - kMaxDepth});
  impl_->levels.emplace_back(finer);
  return true;
}

void TileHistogram::addRefined(const Vec3u& c) {
  auto& levels = impl_->levels;
  const Impl::Level& parent = levels[levels.size() - 2];
  const openvdb::Coord p = cellOf(c, parent.shift);
  if (!parent.refined.count(packCoord(uint32_t(p.x()), uint32_t(p.y()), uint32_t(p.z())))) return;
  Impl::bump(levels.back(), cellOf(c, levels.back().shift));
}

struct TileIndex::Impl {
  std::vector<int> shifts;
  std::vector<openvdb::Int32Grid::Ptr> grids;  // per level: tile id, kRefined, or background kNoTile
};

TileIndex::~TileIndex() = default;
TileIndex::TileIndex(TileIndex&&) noexcept = default;
TileIndex& TileIndex::operator=(TileIndex&&) noexcept = default;

TileIndex TileIndex::build(const TileHistogram& h) {
  TileIndex index;
  index.impl_ = std::make_unique<Impl>();
  const uint64_t target = h.target_;
  const int bits = h.grid_bits_;
  const auto& levels = h.impl_->levels;

  // Terminal cells (counted and not refined) at their octree depth; counts of every ancestor node.
  int max_depth = 0;
  for (const auto& l : levels) max_depth = std::max(max_depth, bits - l.shift);
  std::vector<std::unordered_map<uint64_t, uint64_t>> counts(max_depth + 1);
  std::vector<std::unordered_set<uint64_t>> terminal(max_depth + 1);
  for (const auto& l : levels) {
    const int depth = bits - l.shift;
    for (auto it = l.counts->cbeginValueOn(); it; ++it) {
      const openvdb::Coord c = it.getCoord();
      const uint64_t key = packCoord(uint32_t(c.x()), uint32_t(c.y()), uint32_t(c.z()));
      if (l.refined.count(key)) continue;  // its centroids are counted one level finer
      const uint64_t n = static_cast<uint32_t>(*it);
      terminal[depth].insert(key);
      for (int d = depth; d >= 0; --d) {
        const int s = depth - d;
        counts[d][packCoord(uint32_t(c.x()) >> s, uint32_t(c.y()) >> s, uint32_t(c.z()) >> s)] += n;
      }
    }
  }
  // Node -> tile for the nodes where the descent ends.
  std::vector<std::unordered_map<uint64_t, uint32_t>> owner(max_depth + 1);
  struct Group {
    std::vector<std::pair<int, uint64_t>> nodes;
    uint64_t triangles = 0;
  } group;
  auto closeGroup = [&]() {
    if (group.nodes.empty()) return;
    TileInfo info;
    info.id = static_cast<uint32_t>(index.tiles_.size());
    info.triangles = group.triangles;
    info.lo = {UINT32_MAX, UINT32_MAX, UINT32_MAX};
    for (const auto& [d, key] : group.nodes) {
      owner[d][key] = info.id;
      const int cell_bits = bits - d;  // node edge = 2^cell_bits grid units
      const Vec3u c = unpack(key);
      for (int a = 0; a < 3; ++a) {
        const uint64_t lo = uint64_t(c[a]) << cell_bits;
        info.lo[a] = std::min<uint32_t>(info.lo[a], static_cast<uint32_t>(lo));
        info.hi[a] = std::max<uint32_t>(info.hi[a], static_cast<uint32_t>(lo + (uint64_t(1) << cell_bits) - 1));
      }
    }
    index.tiles_.push_back(info);
    group = Group();
  };
  auto isLeaf = [&](int d, uint64_t key, uint64_t n) { return n <= target || terminal[d].count(key); };
  // Depth-first in Morton order; leaves accumulate into the current group while it stays within the target.
  auto visit = [&](auto&& self, int d, uint64_t key) -> void {
    const Vec3u c = unpack(key);
    for (uint32_t child = 0; child < 8; ++child) {
      const uint64_t ck = packCoord(2 * c[0] + (child & 1), 2 * c[1] + ((child >> 1) & 1), 2 * c[2] + (child >> 2));
      auto it = counts[d + 1].find(ck);
      if (it == counts[d + 1].end()) continue;
      if (isLeaf(d + 1, ck, it->second)) {
        if (group.triangles + it->second > target) closeGroup();
        group.nodes.emplace_back(d + 1, ck);
        group.triangles += it->second;
      } else {
        closeGroup();
        self(self, d + 1, ck);
      }
    }
    closeGroup();
  };
  if (auto root = counts[0].find(0); root != counts[0].end()) {
    if (isLeaf(0, 0, root->second)) {
      group.nodes.emplace_back(0, 0);
      group.triangles = root->second;
      closeGroup();
    } else {
      visit(visit, 0, 0);
    }
  }
  // Per level: terminal cell -> tile, refined cell -> marker.
  for (const auto& l : levels) {
    const int depth = bits - l.shift;
    auto grid = openvdb::Int32Grid::create(kNoTile);
    auto acc = grid->getAccessor();
    for (auto it = l.counts->cbeginValueOn(); it; ++it) {
      const openvdb::Coord c = it.getCoord();
      const uint64_t key = packCoord(uint32_t(c.x()), uint32_t(c.y()), uint32_t(c.z()));
      if (l.refined.count(key)) {
        acc.setValue(c, kRefined);
        continue;
      }
      for (int d = 0; d <= depth; ++d) {
        const int s = depth - d;
        auto o = owner[d].find(packCoord(uint32_t(c.x()) >> s, uint32_t(c.y()) >> s, uint32_t(c.z()) >> s));
        if (o != owner[d].end()) {
          acc.setValue(c, static_cast<int32_t>(o->second));
          break;
        }
      }
    }
    index.impl_->shifts.push_back(l.shift);
    index.impl_->grids.push_back(grid);
  }
  return index;
}

uint32_t TileIndex::tileOf(const Vec3u& c) const {
  // Const tree lookups: safe from many threads (no accessor cache is shared).
  for (size_t k = 0; k < impl_->grids.size(); ++k) {
    const int32_t v = impl_->grids[k]->tree().getValue(cellOf(c, impl_->shifts[k]));
    if (v == kRefined) continue;
    return v < 0 ? UINT32_MAX : static_cast<uint32_t>(v);
  }
  return UINT32_MAX;
}

}  // namespace scanpress
