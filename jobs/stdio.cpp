#include "jobs/stdio.h"

#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <vector>

#include "jobs/cleanup.h"
#include "jobs/errors.h"

namespace scanpress {

namespace fs = std::filesystem;

namespace {
std::atomic<uint64_t> g_spool_counter{0};
}  // namespace

Result<StdioSpool> StdioSpool::create(const std::string& parent) {
  std::error_code ec;
  const fs::path base = parent.empty() ? fs::temp_directory_path(ec) : fs::path(parent);
  if (ec) return errnoStatus(ec.value(), "(temporary directory)", "cannot find a directory for stdin/stdout");
  const std::string dir =
      (base / ("scanpress-stdio-" + std::to_string(::getpid()) + "-" + std::to_string(g_spool_counter++))).string();
  int err = 0;
  const uint64_t tracked = createTracked(TrackedKind::kDirectory, [&]() -> std::string {
    if (::mkdir(dir.c_str(), 0700) != 0) {
      err = errno;
      return "";
    }
    return dir;
  });
  if (!tracked) return errnoStatus(err, dir, "cannot create the directory for stdin/stdout");
  return StdioSpool(dir, tracked);
}

StdioSpool::StdioSpool(StdioSpool&& other) noexcept : dir_(std::move(other.dir_)), tracked_(other.tracked_) {
  other.dir_.clear();
  other.tracked_ = 0;
}

StdioSpool::~StdioSpool() {
  if (dir_.empty()) return;
  std::error_code ec;
  fs::remove_all(dir_, ec);
  untrack(tracked_);
}

std::string StdioSpool::path(const std::string& name) const { return (fs::path(dir_) / name).string(); }

Result<std::string> StdioSpool::readStdin(const std::string& name) {
  const std::string p = path(name);
  FILE* out = nullptr;
  underRegistryLock([&] { out = std::fopen(p.c_str(), "wb"); });
  if (!out) return errnoStatus(errno, p, "cannot create the copy of stdin");
  std::vector<char> buf(1 << 20);
  size_t n;
  bool ok = true;
  while ((n = std::fread(buf.data(), 1, buf.size(), stdin)) > 0)
    if (std::fwrite(buf.data(), 1, n, out) != n) {
      ok = false;
      break;
    }
  const int read_err = std::ferror(stdin) ? errno : 0;
  const int write_err = !ok ? errno : 0;
  if (std::fclose(out) != 0 && ok) return errnoStatus(errno, p, "cannot write the copy of stdin");
  if (read_err) return errnoStatus(read_err, "<stdin>", "cannot read");
  if (!ok) return errnoStatus(write_err, p, "cannot write the copy of stdin");
  return p;
}

Status StdioSpool::writeStdout(const std::string& name) const {
  const std::string p = path(name);
  FILE* in = std::fopen(p.c_str(), "rb");
  if (!in) return errnoStatus(errno, p, "cannot open");
  std::vector<char> buf(1 << 20);
  size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), in)) > 0)
    if (std::fwrite(buf.data(), 1, n, stdout) != n) {
      const int err = errno;
      std::fclose(in);
      return errnoStatus(err, "<stdout>", "cannot write");
    }
  std::fclose(in);
  if (std::fflush(stdout) != 0) return errnoStatus(errno, "<stdout>", "cannot write");
  return Status::ok();
}

}  // namespace scanpress
