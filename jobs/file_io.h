// Files: outputs that appear all-or-nothing and never destroy anything, and random-access reads.
//
// AtomicFile writes to a temporary name in the target's directory (`.NAME.tmp-PID-N`), and commit() flushes,
// fsyncs and renames it over the final name, then fsyncs the directory (so that the rename survives a crash).
// If commit() is not reached (error, exception, early return) the destructor removes the temporary: a failed
// run never leaves a partial file under the final name. The temporary is registered in jobs/cleanup.h while
// it lives, so that SIGINT and SIGTERM remove it too.
//
// The target: a symlink is written through, to its final target (the temporary goes next to that file, and
// the rename replaces that file; the link stays a link). An existing FIFO, character or block device or
// socket is refused (kInvalidArgument, exit 1): renaming over it would replace it, and writing into it would
// not be all-or-nothing. An existing directory is kIo. System errors name the file and map as jobs/errors.h
// says (no space or a file-size limit: kDiskFull; anything else: kIo).
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
  // Creates the temporary next to `path` (and `path`'s folder when missing, as `mkdir -p`).
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
  AtomicFile(int fd, std::string path, std::string target, std::string temp, uint64_t tracked)
      : fd_(fd), path_(std::move(path)), target_(std::move(target)), temp_(std::move(temp)), tracked_(tracked) {}
  Status flushBuffer();
  Status writeError(const std::string& what) const;

  int fd_;
  std::string path_;    // as given (for messages)
  std::string target_;  // path_ with symlinks followed: what the rename replaces
  std::string temp_;
  uint64_t tracked_;  // the temporary's registration in jobs/cleanup.h
  std::vector<uint8_t> buffer_;
  uint64_t size_ = 0;
  bool committed_ = false;
};

// Writes `bytes` to `path` all-or-nothing.
Status writeFileAtomically(const std::string& path, std::span<const uint8_t> bytes);

// Whether two paths name one file: the same device and inode when both exist (hard links, symlinks, `./x` and
// `x`), else the same absolute path once normalized and with the symlinks of its existing part resolved.
bool sameFile(const std::string& a, const std::string& b);

// Refuses an output that would destroy something, before any work: one of `inputs` (sameFile;
// kInvalidArgument), an existing FIFO, device or socket (after following symlinks; kInvalidArgument), a
// directory (kIo). `what` names the output in the message (e.g. "output", "report").
// The extension of `path`, lowercased, with its dot (".png"; "" when none).
std::string lowerExtension(const std::string& path);
// A container's name must not claim another format: kInvalidArgument for a mesh, glTF, image or JSON extension
// (`encode X out.glb` would write a container under a glTF name).
Status checkContainerName(const std::string& path);

Status checkOutputPath(const std::string& output, const std::vector<std::string>& inputs,
                       const std::string& what = "output");

// Removes the temporaries of dead runs in `dir`: files named `.NAME.tmp-PID-N` whose PID is no live process
// (a run killed with SIGKILL, or a machine that crashed, leaves them). Returns how many were removed. A PID
// that is alive (even if reused by another program) keeps its files: they may belong to a run in progress.
size_t removeStaleTemporaries(const std::string& dir);

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
