// Storage for one scan while it is tiled: the vertex store, the triangle spill and the per-tile bins. Each keeps
// its data in memory when its share of the memory budget allows and in a file of the job's scratch directory
// otherwise, with bounded buffers, so that a scan larger than memory streams through disk.
//
// Thread safety: filling (append, get, bump, set) is single-threaded. After finalize(), VertexStore::read and
// TileBins::read may be called from many threads at once.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "engine/mesh.h"
#include "engine/status.h"
#include "spatial/tile_builder.h"

namespace scanpress {

// A scratch directory, removed with its contents when the object dies (on success and on failure), and
// registered in jobs/cleanup.h while it lives (SIGINT and SIGTERM remove it too).
class ScratchDir {
 public:
  static Result<ScratchDir> create(const std::string& parent);  // parent empty: the system temp directory
  ScratchDir() = default;
  ScratchDir(ScratchDir&& o) noexcept : path_(std::move(o.path_)), tracked_(o.tracked_) {
    o.path_.clear();
    o.tracked_ = 0;
  }
  ScratchDir& operator=(ScratchDir&&) = delete;
  ~ScratchDir();
  std::string file(const std::string& name) const { return path_ + "/" + name; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  uint64_t tracked_ = 0;  // the registration in jobs/cleanup.h
};

// Raw positional file I/O that maps errors to kIo / kDiskFull.
class ScratchFile {
 public:
  ScratchFile() = default;
  ScratchFile(const ScratchFile&) = delete;
  ScratchFile& operator=(const ScratchFile&) = delete;
  ~ScratchFile();
  Status open(const std::string& path);
  bool isOpen() const { return fd_ >= 0; }
  Status writeAt(uint64_t offset, const void* data, size_t n);
  Status readAt(uint64_t offset, void* data, size_t n) const;

 private:
  int fd_ = -1;
  std::string path_;
};

class VertexStore : public VertexSource {
 public:
  VertexStore(std::string path, uint64_t cache_bytes);
  Status append(const VertexRecord& r);
  Status get(uint64_t i, VertexRecord& r);
  Status bumpValence(uint64_t i, bool& first_use);
  Status setNormal(uint64_t i, const OctNormal& n);
  // The next vertex's scalar values (its record is appended after them). Held in memory, 4 bytes per value.
  void appendScalars(std::span<const uint32_t> row) { scalars_.insert(scalars_.end(), row.begin(), row.end()); }
  // Overwrites words [offset, offset + words.size()) of vertex i's row of `stride` words (appended before).
  Status setScalars(uint64_t i, size_t stride, size_t offset, std::span<const uint32_t> words) {
    if ((i + 1) * stride > scalars_.size() || offset + words.size() > stride)
      return makeError(ErrorCode::kInternal, "scalar values set past the vertices read");
    std::copy(words.begin(), words.end(), scalars_.begin() + ptrdiff_t(i * stride + offset));
    return Status::ok();
  }
  // Ends filling: writes dirty blocks if anything was ever spilled, then frees the cache.
  Status finalize();
  // Records for sorted, unique ids (thread-safe after finalize).
  Status read(std::span<const uint32_t> sorted_ids, std::vector<VertexRecord>& out) const override;
  Status readScalars(std::span<const uint32_t> sorted_ids, size_t stride, ScalarValues& out) const override;
  uint64_t size() const { return size_; }

 private:
  static constexpr int kBlockShift = 14;
  static constexpr uint64_t kBlockRecords = uint64_t(1) << kBlockShift;
  struct Slot {
    uint64_t block = UINT64_MAX;
    uint64_t last_use = 0;
    bool dirty = false;
    std::vector<VertexRecord> records;
  };
  // The record of vertex i, marking its block dirty when `write`.
  Result<VertexRecord*> at(uint64_t i, bool write) {
    // Fast path: scan files reference vertices with strong locality, so most accesses hit the last block.
    if ((i >> kBlockShift) == last_block_ && i < size_) {
      if (write) slots_[last_slot_].dirty = true;
      return &slots_[last_slot_].records[i & (kBlockRecords - 1)];
    }
    return atSlow(i, write);
  }
  Result<VertexRecord*> atSlow(uint64_t i, bool write);
  Result<Slot*> slotFor(uint64_t block, bool load);

  std::string path_;
  size_t max_slots_;
  std::vector<Slot> slots_;
  std::vector<int32_t> slot_of_block_;  // -1: not cached
  uint64_t size_ = 0;
  uint64_t clock_ = 0;
  ScratchFile file_;
  bool finalized_ = false;
  uint64_t last_block_ = UINT64_MAX;
  size_t last_slot_ = 0;
  ScalarValues scalars_;
};

// Triangles with their centroid (spatial/tile_builder.h), in input order, between the ingest pass and binning.
class TriangleSpill {
 public:
  // `expected` (the count from the first pass) sizes the in-memory array once instead of growing it.
  TriangleSpill(std::string path, bool in_memory, uint64_t expected = 0)
      : path_(std::move(path)), in_memory_(in_memory) {
    if (in_memory_) reserve(expected);
  }
  Status append(const SpilledTriangle& t);
  Status finish();
  uint64_t size() const { return size_; }
  // Reads records [first, first + out.size()).
  Status read(uint64_t first, std::span<SpilledTriangle> out) const;
  void release();

 private:
  void reserve(uint64_t expected);  // the in-memory array, on huge pages
  std::string path_;
  bool in_memory_;
  std::vector<SpilledTriangle> memory_;
  std::vector<SpilledTriangle> buffer_;
  ScratchFile file_;
  uint64_t size_ = 0, written_ = 0;
};

// Triangles grouped by tile: a counting sort into one array (memory) or one file (disk) where each tile's
// triangles are contiguous, in input order.
class TileBins {
 public:
  TileBins(std::string path, bool in_memory, std::span<const uint64_t> tile_counts, uint64_t buffer_bytes);
  Status add(uint32_t tile, const Triangle& t);
  Status finish();
  Status read(uint32_t tile, std::vector<Triangle>& out) const;  // thread-safe after finish

 private:
  Status flushTile(uint32_t tile);
  std::string path_;
  bool in_memory_;
  std::vector<uint64_t> begin_, cursor_;
  std::vector<Triangle> memory_;
  std::vector<std::vector<Triangle>> buffers_;
  size_t buffer_capacity_ = 0;
  ScratchFile file_;
};

}  // namespace scanpress
