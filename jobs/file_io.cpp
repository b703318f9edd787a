#include "jobs/file_io.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cctype>
#include <cerrno>
#include <filesystem>

#include "jobs/cleanup.h"
#include "jobs/errors.h"

namespace scanpress {
namespace {

namespace fs = std::filesystem;

constexpr size_t kBufferSize = 1u << 20;
constexpr int kMaxSymlinkHops = 40;  // as the kernel's ELOOP limit
std::atomic<uint64_t> g_temp_counter{0};

// What kind of non-regular file `mode` is, for a refusal; nullptr for regular files and directories.
const char* specialKind(mode_t mode) {
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  return nullptr;
}

// Refuses an existing target that is not a regular file (following symlinks); a missing one is fine.
Status checkTargetKind(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return Status::ok();  // new file, or an error the create reports
  if (S_ISDIR(st.st_mode)) return makeError(ErrorCode::kIo, path + ": is a directory");
  if (const char* kind = specialKind(st.st_mode))
    return makeError(ErrorCode::kInvalidArgument,
                     path + ": is " + kind + "; scanpress writes regular files only and will not replace it");
  return Status::ok();
}

// `path` with its symlinks followed to the final target (which need not exist: a dangling link names the file
// to create). Each hop is resolved relative to the directory of the link that names it.
Result<std::string> resolveTarget(const std::string& path) {
  std::string current = path;
  for (int hops = 0; hops < kMaxSymlinkHops; ++hops) {
    struct stat st {};
    if (::lstat(current.c_str(), &st) != 0 || !S_ISLNK(st.st_mode)) return current;  // open() reports errors
    std::string link(4096, '\0');
    const ssize_t n = ::readlink(current.c_str(), link.data(), link.size());
    if (n < 0) return errnoStatus(errno, path, "cannot read symbolic link");
    link.resize(static_cast<size_t>(n));
    const fs::path next(link);
    current = next.is_absolute() ? link : (fs::path(current).parent_path() / next).string();
  }
  return makeError(ErrorCode::kIo, path + ": too many levels of symbolic links");
}

fs::path directoryOf(const std::string& path) {
  const fs::path p(path);
  return p.has_parent_path() ? p.parent_path() : fs::path(".");
}

}  // namespace

Result<std::unique_ptr<AtomicFile>> AtomicFile::create(const std::string& path) {
  SP_RETURN_IF_ERROR(checkTargetKind(path));
  SP_ASSIGN_OR_RETURN(std::string target, resolveTarget(path));
  SP_RETURN_IF_ERROR(checkTargetKind(target));
  std::string name = ".";
  name += fs::path(target).filename().string();
  name += ".tmp-";
  name += std::to_string(::getpid());
  name += "-";
  name += std::to_string(g_temp_counter++);
  const std::string temp = (directoryOf(target) / name).string();
  // A missing output folder is created (as `mkdir -p`; it stays if the write then fails).
  if (std::error_code ec; !fs::is_directory(directoryOf(target), ec)) {
    fs::create_directories(directoryOf(target), ec);
    if (ec) return errnoStatus(ec.value(), path, "cannot create the output's folder " + directoryOf(target).string());
  }
  // Created under the cleanup registry's lock, so that a signal's cleanup either sees it or runs before it
  // exists.
  int fd = -1, err = 0;
  const uint64_t tracked = createTracked(TrackedKind::kFile, [&]() -> std::string {
    fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    err = errno;
    return fd < 0 ? std::string() : temp;
  });
  if (fd < 0) return errnoStatus(err, path, "cannot create output (temporary " + temp + ")");
  return std::unique_ptr<AtomicFile>(new AtomicFile(fd, path, std::move(target), temp, tracked));
}

AtomicFile::~AtomicFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_) ::unlink(temp_.c_str());
  untrack(tracked_);
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
  if (::rename(temp_.c_str(), target_.c_str()) != 0) return writeError("cannot rename temporary into place");
  committed_ = true;
  untrack(tracked_);
  tracked_ = 0;
  // The rename is durable only once the directory is: sync it. EINVAL: the file system cannot sync
  // directories.
  const std::string dir = directoryOf(target_).string();
  const int dir_fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir_fd < 0) return errnoStatus(errno, dir, "cannot open the output's directory to sync it");
  const int synced = ::fsync(dir_fd), err = errno;
  ::close(dir_fd);
  if (synced != 0 && err != EINVAL) return errnoStatus(err, dir, "cannot sync the output's directory");
  return Status::ok();
}

Status writeFileAtomically(const std::string& path, std::span<const uint8_t> bytes) {
  SP_ASSIGN_OR_RETURN(auto file, AtomicFile::create(path));
  SP_RETURN_IF_ERROR(file->append(bytes));
  return file->commit();
}

bool sameFile(const std::string& a, const std::string& b) {
  struct stat sa {};
  struct stat sb {};
  if (::stat(a.c_str(), &sa) == 0 && ::stat(b.c_str(), &sb) == 0)
    return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
  std::error_code ea, eb;
  const fs::path ca = fs::weakly_canonical(fs::absolute(a, ea), ea), cb = fs::weakly_canonical(fs::absolute(b, eb), eb);
  return !ea && !eb && ca == cb;
}

std::string lowerExtension(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

Status checkContainerName(const std::string& path) {
  std::string name = path;
  if (lowerExtension(name) == ".zst") name.resize(name.size() - 4);
  const std::string ext = lowerExtension(name);
  for (const char* other : {".ply", ".obj", ".stl", ".off", ".glb", ".gltf", ".png", ".jpg", ".jpeg", ".json"})
    if (ext == other)
      return makeError(ErrorCode::kInvalidArgument, path + ": a scanpress container would be written under a " + ext +
                                                        " name; name it .spz (decode writes meshes)");
  return Status::ok();
}

Status checkOutputPath(const std::string& output, const std::vector<std::string>& inputs, const std::string& what) {
  for (const std::string& in : inputs)
    if (sameFile(output, in))
      return makeError(ErrorCode::kInvalidArgument,
                       output + ": the " + what + " is the input " + in + "; refusing to overwrite it");
  return checkTargetKind(output);
}

size_t removeStaleTemporaries(const std::string& dir) {
  size_t removed = 0;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    // `.NAME.tmp-PID-N`: a dot, a name, ".tmp-", then digits, "-", digits.
    const std::string name = it->path().filename().string();
    const size_t tmp = name.rfind(".tmp-");
    if (name.size() < 2 || name[0] != '.' || tmp == std::string::npos || tmp < 2) continue;
    const std::string tail = name.substr(tmp + 5);
    const size_t dash = tail.find('-');
    auto digits = [](const std::string& t) {
      return !t.empty() && t.size() <= 12 && t.find_first_not_of("0123456789") == std::string::npos;
    };
    if (dash == std::string::npos || !digits(tail.substr(0, dash)) || !digits(tail.substr(dash + 1))) continue;
    const long long pid = std::stoll(tail.substr(0, dash));
    if (pid <= 0 || pid == ::getpid()) continue;
    if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;  // alive (or not ours to judge)
    std::error_code e2;
    if (it->is_regular_file(e2) && ::unlink(it->path().c_str()) == 0) ++removed;
  }
  return removed;
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
      return errnoStatus(errno, path_, "read failed at byte " + std::to_string(offset + done));
    }
    if (got == 0)
      return makeError(ErrorCode::kTruncated,
                       path_ + ": file shrank while reading (at byte " + std::to_string(offset + done) + ")");
    done += static_cast<size_t>(got);
  }
  return Status::ok();
}

}  // namespace scanpress
