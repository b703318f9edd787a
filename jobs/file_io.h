// Files: outputs that appear all-or-nothing, and random-access reads.
//
// AtomicFile writes to a temporary name in the target's directory (`.NAME.tmp-PID-N`), and commit() flushes,
// fsyncs and renames it over the final name. If commit() is not reached (error, exception, early return) the
// destructor removes the temporary: a failed run never leaves a partial file under the final name. System errors
// name the file and map as jobs/errors.h says (no space: kDiskFull; anything else: kIo).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "engine/container/container.h"
#include "engine/status.h"

namespace scanpress {

class AtomicFile : public ByteSink {
 public:
  static Result<std::unique_ptr<AtomicFile>> create(const std::string& path);
  ~AtomicFile() override;
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  Status append(std::span<const uint8_t> bytes) override;
  Status append(std::string_view text) {
    return append(std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
  }
  Status writeAt(uint64_t offset, std::span<const uint8_t> bytes) override;
  Status commit();
  const std::string& path() const { return path_; }
  uint64_t size() const { return size_; }

 private:
  AtomicFile(int fd, std::string path, std::string temp) : fd_(fd), path_(std::move(path)), temp_(std::move(temp)) {}
  Status flushBuffer();
  Status writeError(const std::string& what) const;

  int fd_;
  std::string path_, temp_;
  std::vector<uint8_t> buffer_;
  uint64_t size_ = 0;
  bool committed_ = false;
};

// Writes `bytes` to `path` all-or-nothing.
Status writeFileAtomically(const std::string& path, std::span<const uint8_t> bytes);

// Read-only random access.
class RandomAccessFile {
 public:
  static Result<std::unique_ptr<RandomAccessFile>> open(const std::string& path);
  ~RandomAccessFile();
  uint64_t size() const { return size_; }
  // Reads exactly [offset, offset+n) or fails (kTruncated if the file is shorter).
  Status read(uint64_t offset, size_t n, std::vector<uint8_t>& out) const;
  const std::string& path() const { return path_; }

 private:
  RandomAccessFile(int fd, std::string path, uint64_t size) : fd_(fd), path_(std::move(path)), size_(size) {}
  int fd_;
  std::string path_;
  uint64_t size_;
};

}  // namespace scanpress
