#include "jobs/scan_store.h"

#include <fcntl.h>
#include <stdlib.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <filesystem>

#include "jobs/cleanup.h"
#include "jobs/errors.h"

namespace scanpress {

namespace {

// Asks for transparent huge pages on the 2 MiB pages inside [p, p + bytes), before they are touched: a large array
// of tile data then costs one page fault per 2 MiB instead of per 4 KiB (10^7 triangles: quantization 2.4 -> 1.1 s,
// binning 0.65 -> 0.15 s; bench/RESULTS.md, "Encode on two threads"). Where the kernel's setting is "never", or the
// range holds no whole huge page, nothing changes.
void adviseHugePages(const void* p, size_t bytes) {
  constexpr uintptr_t kHuge = uintptr_t(2) << 20;
  const uintptr_t lo = (reinterpret_cast<uintptr_t>(p) + kHuge - 1) & ~(kHuge - 1);
  const uintptr_t hi = (reinterpret_cast<uintptr_t>(p) + bytes) & ~(kHuge - 1);
  if (hi > lo) (void)::madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_HUGEPAGE);
}

}  // namespace

Result<ScratchDir> ScratchDir::create(const std::string& parent) {
  std::error_code ec;
  const std::string base = parent.empty() ? std::filesystem::temp_directory_path(ec).string() : parent;
  std::string templ = base + "/scanpress-scratch-XXXXXX";
  int err = 0;
  const uint64_t tracked = createTracked(TrackedKind::kDirectory, [&]() -> std::string {
    const bool made = ::mkdtemp(templ.data()) != nullptr;
    err = errno;
    return made ? templ : std::string();
  });
  if (tracked == 0) return errnoStatus(err, templ, "cannot create scratch directory");
  ScratchDir d;
  d.path_ = templ;
  d.tracked_ = tracked;
  return d;
}

ScratchDir::~ScratchDir() {
  if (path_.empty()) return;
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
  untrack(tracked_);
}

ScratchFile::~ScratchFile() {
  if (fd_ >= 0) ::close(fd_);
}

Status ScratchFile::open(const std::string& path) {
  path_ = path;
  int err = 0;
  // Under the cleanup registry's lock: a scratch file never appears after a signal's cleanup removed its
  // directory.
  underRegistryLock([&] {
    fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    err = errno;
  });
  if (fd_ < 0) return errnoStatus(err, path, "cannot create scratch file");
  return Status::ok();
}

Status ScratchFile::writeAt(uint64_t offset, const void* data, size_t n) {
  const auto* p = static_cast<const uint8_t*>(data);
  while (n > 0) {
    const ssize_t w = ::pwrite(fd_, p, n, static_cast<off_t>(offset));
    if (w < 0) {
      if (errno == EINTR) continue;
      return errnoStatus(errno, path_, "write failed");
    }
    p += w;
    offset += static_cast<uint64_t>(w);
    n -= static_cast<size_t>(w);
  }
  return Status::ok();
}

Status ScratchFile::readAt(uint64_t offset, void* data, size_t n) const {
  auto* p = static_cast<uint8_t*>(data);
  while (n > 0) {
    const ssize_t r = ::pread(fd_, p, n, static_cast<off_t>(offset));
    if (r < 0) {
      if (errno == EINTR) continue;
      return errnoStatus(errno, path_, "read failed");
    }
    if (r == 0) return makeError(ErrorCode::kIo, path_ + ": scratch file shorter than written");
    p += r;
    offset += static_cast<uint64_t>(r);
    n -= static_cast<size_t>(r);
  }
  return Status::ok();
}

// ------------------------------------------------------------------------------------------------ VertexStore

VertexStore::VertexStore(std::string path, uint64_t cache_bytes)
    : path_(std::move(path)),
      max_slots_(std::max<uint64_t>(4, cache_bytes / (kBlockRecords * sizeof(VertexRecord)))) {}

Result<VertexStore::Slot*> VertexStore::slotFor(uint64_t block, bool load) {
  if (block >= slot_of_block_.size()) slot_of_block_.resize(block + 1, -1);
  if (slot_of_block_[block] >= 0) {
    Slot* s = &slots_[static_cast<size_t>(slot_of_block_[block])];
    s->last_use = ++clock_;
    return s;
  }
  Slot* s;
  if (slots_.size() < max_slots_) {
    slots_.emplace_back();
    s = &slots_.back();
    s->records.resize(kBlockRecords);
  } else {  // evict the least recently used block to the file
    s = &*std::min_element(slots_.begin(), slots_.end(),
                           [](const Slot& a, const Slot& b) { return a.last_use < b.last_use; });
    if (s->dirty) {
      if (!file_.isOpen()) SP_RETURN_IF_ERROR(file_.open(path_));
      SP_RETURN_IF_ERROR(file_.writeAt(s->block * kBlockRecords * sizeof(VertexRecord), s->records.data(),
                                       kBlockRecords * sizeof(VertexRecord)));
    }
    slot_of_block_[s->block] = -1;
    if (s->block == last_block_) last_block_ = UINT64_MAX;
  }
  s->block = block;
  s->dirty = false;
  s->last_use = ++clock_;
  slot_of_block_[block] = static_cast<int32_t>(s - slots_.data());
  const uint64_t first = block * kBlockRecords;
  // A block that is not cached and not new was evicted before, and eviction wrote it.
  if (load && file_.isOpen() && first < size_) {
    const uint64_t n = std::min<uint64_t>(kBlockRecords, size_ - first);
    SP_RETURN_IF_ERROR(file_.readAt(first * sizeof(VertexRecord), s->records.data(), n * sizeof(VertexRecord)));
  }
  return s;
}

Result<VertexRecord*> VertexStore::atSlow(uint64_t i, bool write) {
  if (i >= size_) return makeError(ErrorCode::kInternal, "vertex store index out of range");
  SP_ASSIGN_OR_RETURN(Slot * s, slotFor(i / kBlockRecords, true));
  last_block_ = i / kBlockRecords;
  last_slot_ = static_cast<size_t>(s - slots_.data());
  if (write) s->dirty = true;
  return &s->records[i % kBlockRecords];
}

Status VertexStore::append(const VertexRecord& r) {
  const uint64_t i = size_++;
  if (i % kBlockRecords == 0) {  // a new block: nothing of it is on disk, so claim a slot without reading
    auto s = slotFor(i / kBlockRecords, false);
    if (!s.isOk()) return s.status();
  }
  SP_ASSIGN_OR_RETURN(VertexRecord * rec, at(i, true));
  *rec = r;
  return Status::ok();
}

Status VertexStore::get(uint64_t i, VertexRecord& r) {
  SP_ASSIGN_OR_RETURN(VertexRecord * rec, at(i, false));
  r = *rec;
  return Status::ok();
}

Status VertexStore::bumpValence(uint64_t i, bool& first_use) {
  SP_ASSIGN_OR_RETURN(VertexRecord * rec, at(i, true));
  first_use = rec->valence == 0;
  ++rec->valence;
  return Status::ok();
}

Status VertexStore::setNormal(uint64_t i, const OctNormal& n) {
  SP_ASSIGN_OR_RETURN(VertexRecord * rec, at(i, true));
  rec->normal = n;
  return Status::ok();
}

Status VertexStore::finalize() {
  finalized_ = true;
  if (!file_.isOpen()) return Status::ok();  // everything is resident: reads come from the cache
  for (Slot& s : slots_) {
    if (!s.dirty) continue;
    const uint64_t first = s.block * kBlockRecords;
    const uint64_t n = std::min<uint64_t>(kBlockRecords, size_ - first);
    SP_RETURN_IF_ERROR(file_.writeAt(first * sizeof(VertexRecord), s.records.data(), n * sizeof(VertexRecord)));
  }
  slots_.clear();
  slots_.shrink_to_fit();
  slot_of_block_.clear();
  last_block_ = UINT64_MAX;
  return Status::ok();
}

Status VertexStore::readScalars(std::span<const uint32_t> ids, size_t stride, ScalarValues& out) const {
  if (scalars_.size() != size_ * stride) return makeError(ErrorCode::kInternal, "vertex store: scalars missing");
  out.resize(ids.size() * stride);
  for (size_t k = 0; k < ids.size(); ++k) {
    if (ids[k] >= size_) return makeError(ErrorCode::kInternal, "vertex store index out of range");
    std::copy_n(scalars_.begin() + ptrdiff_t(ids[k] * stride), stride, out.begin() + ptrdiff_t(k * stride));
  }
  return Status::ok();
}

Status VertexStore::read(std::span<const uint32_t> ids, std::vector<VertexRecord>& out) const {
  out.resize(ids.size());
  if (!file_.isOpen()) {
    for (size_t k = 0; k < ids.size(); ++k) {
      const uint64_t i = ids[k];
      if (i >= size_) return makeError(ErrorCode::kInternal, "vertex store index out of range");
      const Slot& s = slots_[static_cast<size_t>(slot_of_block_[i / kBlockRecords])];
      out[k] = s.records[i % kBlockRecords];
    }
    return Status::ok();
  }
  // From the file: one read per run of ids whose gaps are small (scan vertex order is spatially coherent).
  constexpr uint64_t kMaxGap = 64;
  std::vector<VertexRecord> run;
  for (size_t k = 0; k < ids.size();) {
    size_t e = k + 1;
    while (e < ids.size() && ids[e] - ids[e - 1] <= kMaxGap && ids[e] - ids[k] < 65536) ++e;
    const uint64_t first = ids[k], count = uint64_t(ids[e - 1]) - first + 1;
    if (first + count > size_) return makeError(ErrorCode::kInternal, "vertex store index out of range");
    run.resize(count);
    SP_RETURN_IF_ERROR(file_.readAt(first * sizeof(VertexRecord), run.data(), count * sizeof(VertexRecord)));
    for (size_t j = k; j < e; ++j) out[j] = run[ids[j] - first];
    k = e;
  }
  return Status::ok();
}

// ---------------------------------------------------------------------------------------------- TriangleSpill

namespace {
constexpr size_t kSpillBuffer = 1u << 16;  // records per write
}

void TriangleSpill::reserve(uint64_t expected) {
  memory_.reserve(expected);
  adviseHugePages(memory_.data(), expected * sizeof(SpilledTriangle));
}

Status TriangleSpill::append(const SpilledTriangle& t) {
  ++size_;
  if (in_memory_) {
    memory_.push_back(t);
    return Status::ok();
  }
  buffer_.push_back(t);
  if (buffer_.size() < kSpillBuffer) return Status::ok();
  return finish();
}

Status TriangleSpill::finish() {
  if (in_memory_ || buffer_.empty()) return Status::ok();
  if (!file_.isOpen()) SP_RETURN_IF_ERROR(file_.open(path_));
  SP_RETURN_IF_ERROR(file_.writeAt(written_ * sizeof(SpilledTriangle), buffer_.data(),
                                   buffer_.size() * sizeof(SpilledTriangle)));
  written_ += buffer_.size();
  buffer_.clear();
  return Status::ok();
}

Status TriangleSpill::read(uint64_t first, std::span<SpilledTriangle> out) const {
  if (first + out.size() > size_) return makeError(ErrorCode::kInternal, "spill read past the end");
  if (in_memory_) {
    std::copy_n(memory_.begin() + static_cast<ptrdiff_t>(first), out.size(), out.begin());
    return Status::ok();
  }
  return file_.readAt(first * sizeof(SpilledTriangle), out.data(), out.size() * sizeof(SpilledTriangle));
}

void TriangleSpill::release() {
  std::vector<SpilledTriangle>().swap(memory_);  // frees (`= {}` would keep the capacity)
  std::vector<SpilledTriangle>().swap(buffer_);
}

// ------------------------------------------------------------------------------------------------- TileBins

TileBins::TileBins(std::string path, bool in_memory, std::span<const uint64_t> counts, uint64_t buffer_bytes)
    : path_(std::move(path)), in_memory_(in_memory) {
  begin_.resize(counts.size() + 1, 0);
  for (size_t t = 0; t < counts.size(); ++t) begin_[t + 1] = begin_[t] + counts[t];
  cursor_.assign(begin_.begin(), begin_.end() - 1);
  if (in_memory_) {
    memory_.reserve(begin_.back());
    adviseHugePages(memory_.data(), begin_.back() * sizeof(Triangle));
    memory_.resize(begin_.back());
  } else {
    buffers_.resize(counts.size());
    buffer_capacity_ =
        std::clamp<uint64_t>(buffer_bytes / sizeof(Triangle) / std::max<size_t>(1, counts.size()), 64, 16384);
  }
}

Status TileBins::add(uint32_t tile, const Triangle& t) {
  if (tile >= cursor_.size() || cursor_[tile] >= begin_[tile + 1])
    return makeError(ErrorCode::kInternal, "tile bin overflow for tile " + std::to_string(tile));
  if (in_memory_) {
    memory_[cursor_[tile]++] = t;
    return Status::ok();
  }
  auto& b = buffers_[tile];
  b.push_back(t);
  if (b.size() >= buffer_capacity_) return flushTile(tile);
  return Status::ok();
}

Status TileBins::flushTile(uint32_t tile) {
  auto& b = buffers_[tile];
  if (b.empty()) return Status::ok();
  if (!file_.isOpen()) SP_RETURN_IF_ERROR(file_.open(path_));
  SP_RETURN_IF_ERROR(file_.writeAt(cursor_[tile] * sizeof(Triangle), b.data(), b.size() * sizeof(Triangle)));
  cursor_[tile] += b.size();
  b.clear();
  return Status::ok();
}

Status TileBins::finish() {
  if (!in_memory_)
    for (uint32_t t = 0; t < buffers_.size(); ++t) SP_RETURN_IF_ERROR(flushTile(t));
  std::vector<std::vector<Triangle>>().swap(buffers_);
  for (size_t t = 0; t + 1 < begin_.size(); ++t)
    if (cursor_[t] != begin_[t + 1])
      return makeError(ErrorCode::kInternal, "tile bin " + std::to_string(t) + " incomplete");
  return Status::ok();
}

Status TileBins::read(uint32_t tile, std::vector<Triangle>& out) const {
  if (tile + 1 >= begin_.size()) return makeError(ErrorCode::kInternal, "no such tile bin");
  const uint64_t first = begin_[tile], n = begin_[tile + 1] - first;
  out.resize(n);
  if (in_memory_) {
    std::copy_n(memory_.begin() + static_cast<ptrdiff_t>(first), n, out.begin());
    return Status::ok();
  }
  if (n == 0) return Status::ok();
  return file_.readAt(first * sizeof(Triangle), out.data(), n * sizeof(Triangle));
}

}  // namespace scanpress
