#include "spatial/tiling.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <unordered_map>

namespace scanpress {
namespace {

// Packs a coordinate of at most 21 bits per axis.
uint64_t packCoord(uint32_t x, uint32_t y, uint32_t z) { return (uint64_t(x) << 42) | (uint64_t(y) << 21) | z; }

}  // namespace

struct TileHistogram::Impl {
  openvdb::Int64Grid::Ptr counts = openvdb::Int64Grid::create(0);
  openvdb::Int64Grid::Accessor acc = counts->getAccessor();
};

TileHistogram::TileHistogram(int grid_bits, uint64_t total_triangles, uint64_t target)
    : impl_(std::make_unique<Impl>()), grid_bits_(grid_bits), target_(std::max<uint64_t>(target, 1)) {
  // A surface through R^3 cells touches on the order of R^2 of them; aim for about 1/64 of the target per touched
  // cell, so that the octree has room to adapt: R = sqrt(64 N / target), rounded up to a power of two.
  const double r = std::sqrt(64.0 * double(std::max<uint64_t>(total_triangles, 1)) / double(target_));
  int levels = 0;
  while (levels < grid_bits && (1u << levels) < r) ++levels;
  levels = std::min(levels, 21);  // fine coordinates must fit the packed keys
  shift_ = grid_bits - levels;
}

TileHistogram::~TileHistogram() = default;
TileHistogram::TileHistogram(TileHistogram&&) noexcept = default;
TileHistogram& TileHistogram::operator=(TileHistogram&&) noexcept = default;

void TileHistogram::add(const Vec3u& c) {
  const openvdb::Coord ijk(static_cast<int32_t>(c[0] >> shift_), static_cast<int32_t>(c[1] >> shift_),
                           static_cast<int32_t>(c[2] >> shift_));
  impl_->acc.setValue(ijk, impl_->acc.getValue(ijk) + 1);
  ++total_;
}

struct TileIndex::Impl {
  openvdb::Int32Grid::Ptr tiles = openvdb::Int32Grid::create(-1);
};

TileIndex::~TileIndex() = default;
TileIndex::TileIndex(TileIndex&&) noexcept = default;
TileIndex& TileIndex::operator=(TileIndex&&) noexcept = default;

TileIndex TileIndex::build(const TileHistogram& h) {
  TileIndex index;
  index.impl_ = std::make_unique<Impl>();
  index.shift_ = h.shift_;
  const int depth = h.grid_bits_ - h.shift_;  // octree depth of the fine cells
  const uint64_t target = h.target_;

  // Counts per octree node, per depth (depth 0: the root, the whole grid).
  std::vector<std::unordered_map<uint64_t, uint64_t>> counts(depth + 1);
  for (auto it = h.impl_->counts->cbeginValueOn(); it; ++it) {
    const openvdb::Coord c = it.getCoord();
    const uint64_t n = static_cast<uint64_t>(*it);
    for (int d = depth; d >= 0; --d) {
      const int s = depth - d;
      counts[d][packCoord(uint32_t(c.x()) >> s, uint32_t(c.y()) >> s, uint32_t(c.z()) >> s)] += n;
    }
  }
  // Node -> tile for the nodes that end the descent.
  std::vector<std::unordered_map<uint64_t, uint32_t>> owner(depth + 1);
  auto unpack = [](uint64_t k) { return Vec3u{uint32_t(k >> 42), uint32_t((k >> 21) & 0x1FFFFF), uint32_t(k & 0x1FFFFF)}; };
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
      const int cell_bits = h.grid_bits_ - d;  // node edge = 2^cell_bits grid units
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
  auto isLeaf = [&](int d, uint64_t n) { return n <= target || d == depth; };
  // Depth-first in Morton order; leaves accumulate into the current group while it stays within the target.
  auto visit = [&](auto&& self, int d, uint64_t key) -> void {
    const Vec3u c = unpack(key);
    for (uint32_t child = 0; child < 8; ++child) {
      const uint64_t ck = packCoord(2 * c[0] + (child & 1), 2 * c[1] + ((child >> 1) & 1), 2 * c[2] + (child >> 2));
      auto it = counts[d + 1].find(ck);
      if (it == counts[d + 1].end()) continue;
      if (isLeaf(d + 1, it->second)) {
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
  auto root = counts[0].find(0);
  if (root != counts[0].end()) {
    if (isLeaf(0, root->second)) {
      group.nodes.emplace_back(0, 0);
      group.triangles = root->second;
      closeGroup();
    } else {
      visit(visit, 0, 0);
    }
  }
  // Fine cell -> tile, in the OpenVDB index.
  auto acc = index.impl_->tiles->getAccessor();
  for (auto it = h.impl_->counts->cbeginValueOn(); it; ++it) {
    const openvdb::Coord c = it.getCoord();
    for (int d = 0; d <= depth; ++d) {
      const int s = depth - d;
      auto o = owner[d].find(packCoord(uint32_t(c.x()) >> s, uint32_t(c.y()) >> s, uint32_t(c.z()) >> s));
      if (o != owner[d].end()) {
        acc.setValue(c, static_cast<int32_t>(o->second));
        break;
      }
    }
  }
  return index;
}

uint32_t TileIndex::tileOf(const Vec3u& c) const {
  // A const tree lookup: safe from many threads (no accessor cache is shared).
  const int32_t v = impl_->tiles->tree().getValue(openvdb::Coord(static_cast<int32_t>(c[0] >> shift_),
                                                                 static_cast<int32_t>(c[1] >> shift_),
                                                                 static_cast<int32_t>(c[2] >> shift_)));
  return v < 0 ? UINT32_MAX : static_cast<uint32_t>(v);
}

}  // namespace scanpress
