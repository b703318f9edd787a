#include "jobs/file_io.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <filesystem>

#include "jobs/errors.h"

namespace scanpress {
namespace {

constexpr size_t kBufferSize = 1u << 20;
std::atomic<uint64_t> g_temp_counter{0};

}  // namespace

Result<std::unique_ptr<AtomicFile>> AtomicFile::create(const std::string& path) {
  namespace fs = std::filesystem;
  const fs::path target(path);
  const fs::path dir = target.has_parent_path() ? target.parent_path() : fs::path(".");
  std::error_code ec;
  if (fs::is_directory(target, ec)) return makeError(ErrorCode::kIo, path + ": is a directory");
  std::string name = ".";
  name += target.filename().string();
  name += ".tmp-";
  name += std::to_string(::getpid());
  name += "-";
  name += std::to_string(g_temp_counter++);
  const std::string temp = (dir / name).string();
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) return errnoStatus(errno, path, "cannot create output (temporary " + temp + ")");
  return std::unique_ptr<AtomicFile>(new AtomicFile(fd, path, temp));
}

AtomicFile::~AtomicFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_) ::unlink(temp_.c_str());
}

Status AtomicFile::writeError(const std::string& what) const { return errnoStatus(errno, path_, what); }

Status AtomicFile::flushBuffer() {
  size_t done = 0;
  while (done < buffer_.size()) {
    const ssize_t n = ::write(fd_, buffer_.data() + done, buffer_.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      return writeError("write failed");
    }
    done += static_cast<size_t>(n);
  }
  buffer_.clear();
  return Status::ok();
}

Status AtomicFile::append(std::span<const uint8_t> bytes) {
  if (committed_) return makeError(ErrorCode::kInternal, path_ + ": append after commit");
  size_ += bytes.size();
  if (buffer_.size() + bytes.size() > kBufferSize) SP_RETURN_IF_ERROR(flushBuffer());
  if (bytes.size() >= kBufferSize) {
    buffer_.assign(bytes.begin(), bytes.end());
    return flushBuffer();
  }
  buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
  return Status::ok();
}

Status AtomicFile::writeAt(uint64_t offset, std::span<const uint8_t> bytes) {
  SP_RETURN_IF_ERROR(flushBuffer());
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::pwrite(fd_, bytes.data() + done, bytes.size() - done, static_cast<off_t>(offset + done));
    if (n < 0) {
      if (errno == EINTR) continue;
      return writeError("write failed");
    }
    done += static_cast<size_t>(n);
  }
  return Status::ok();
}

Status AtomicFile::commit() {
  SP_RETURN_IF_ERROR(flushBuffer());
  if (::fsync(fd_) != 0) return writeError("fsync failed");
  if (::close(fd_) != 0) {
    fd_ = -1;
    return writeError("close failed");
  }
  fd_ = -1;
  if (::rename(temp_.c_str(), path_.c_str()) != 0) return writeError("cannot rename temporary into place");
  committed_ = true;
  return Status::ok();
}

Status writeFileAtomically(const std::string& path, std::span<const uint8_t> bytes) {
  SP_ASSIGN_OR_RETURN(auto file, AtomicFile::create(path));
  SP_RETURN_IF_ERROR(file->append(bytes));
  return file->commit();
}

Result<std::unique_ptr<RandomAccessFile>> RandomAccessFile::open(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return errnoStatus(errno, path, "cannot open");
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return makeError(ErrorCode::kIo, path + ": not a regular file");
  }
  return std::unique_ptr<RandomAccessFile>(new RandomAccessFile(fd, path, static_cast<uint64_t>(st.st_size)));
}

RandomAccessFile::~RandomAccessFile() { ::close(fd_); }

Status RandomAccessFile::read(uint64_t offset, size_t n, std::vector<uint8_t>& out) const {
  if (offset > size_ || n > size_ - offset)
    return makeError(ErrorCode::kTruncated, path_ + ": byte " + std::to_string(offset) + ": needs " +
                                                std::to_string(n) + " bytes, file has " + std::to_string(size_));
  out.resize(n);
  size_t done = 0;
  while (done < n) {
    const ssize_t got = ::pread(fd_, out.data() + done, n - done, static_cast<off_t>(offset + done));
    if (got < 0) {
      if (errno == EINTR) continue;
      return errnoStatus(errno, path_, "read failed");
    }
    if (got == 0) return makeError(ErrorCode::kTruncated, path_ + ": file shrank while reading");
    done += static_cast<size_t>(got);
  }
  return Status::ok();
}

}  // namespace scanpress
