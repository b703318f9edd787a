// Outputs never destroy anything: no output replaces an input, a symlink is written through, FIFOs, devices
// and sockets are refused, a file-size limit and SIGINT/SIGTERM leave no temporary behind, resume removes the
// temporaries of dead runs and redoes a container that fails its checksums (issue 18, items 6 and 7).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "jobs/cleanup.h"
#include "jobs/container_file.h"
#include "jobs/file_io.h"
#include "jobs/scan_store.h"
#include "jobs_util.h"

namespace scanpress {
namespace {

using testing::kBunny;
using testing::run;

namespace fs = std::filesystem;

std::string slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

std::string quoted(const std::string& path) { return "'" + path + "'"; }

// Entries of `dir` (recursively) whose names mark a temporary: `.NAME.tmp-PID-N` or a scratch directory.
std::vector<std::string> leftovers(const std::string& dir) {
  std::vector<std::string> found;
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.find(".tmp-") != std::string::npos || name.starts_with("scanpress-scratch-"))
      found.push_back(it->path().string());
  }
  return found;
}

// The scanpress binary as a child process: `setup` runs in the child between fork and exec (for limits).
pid_t spawn(const std::vector<std::string>& args, const std::function<void()>& setup = {}) {
  std::vector<std::string> all = {SCANPRESS_BIN};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int null_fd = ::open("/dev/null", O_WRONLY);  // keep the test's output clean
    if (null_fd >= 0) ::dup2(null_fd, STDOUT_FILENO), ::dup2(null_fd, STDERR_FILENO);
    if (setup) setup();
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  return pid;
}

int waitStatus(pid_t pid) {
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return status;
}

// A PID that belonged to a process which has ended (a child that exited and was reaped).
pid_t deadPid() {
  const pid_t pid = ::fork();
  if (pid == 0) ::_exit(0);
  waitStatus(pid);
  return pid;
}

// Temporaries are registered for the signal cleanup while they live, and forgotten once committed or removed.
TEST(Outputs, TemporariesAreRegisteredWhileTheyLive) {
  testing::TempDir dir;
  const size_t before = trackedCount();
  {
    auto file = AtomicFile::create(dir.file("a.bin"));
    ASSERT_TRUE(file.isOk()) << file.status().toString();
    EXPECT_EQ(trackedCount(), before + 1);
    auto scratch = ScratchDir::create(dir.path());
    ASSERT_TRUE(scratch.isOk()) << scratch.status().toString();
    EXPECT_EQ(trackedCount(), before + 2);
    ASSERT_TRUE((*file)->append(std::string_view("bytes")).isOk());
    ASSERT_TRUE((*file)->commit().isOk());
    EXPECT_EQ(trackedCount(), before + 1);
  }
  EXPECT_EQ(trackedCount(), before);
  {
    auto file = AtomicFile::create(dir.file("b.bin"));  // never committed: removed and forgotten
    ASSERT_TRUE(file.isOk());
  }
  EXPECT_EQ(trackedCount(), before);
  EXPECT_TRUE(fs::exists(dir.file("a.bin")));
  EXPECT_FALSE(fs::exists(dir.file("b.bin")));
  EXPECT_TRUE(leftovers(dir.path()).empty());
}

TEST(Outputs, EncodeOrDecodeOntoTheInputIsRefused) {
  testing::TempDir dir;
  const std::string scan = dir.file("scan.ply.zst");
  fs::copy_file(kBunny, scan);
  const std::string original = slurp(scan);
  std::string out;
  // The same path, another spelling of it, a hard link and a symlink to it: all the input itself.
  fs::create_directories(dir.file("sub"));
  fs::create_hard_link(scan, dir.file("hard.ply.zst"));
  fs::create_symlink("scan.ply.zst", dir.file("soft.ply.zst"));
  for (const std::string& target :
       {scan, dir.file("sub/../scan.ply.zst"), dir.file("hard.ply.zst"), dir.file("soft.ply.zst")}) {
    SCOPED_TRACE(target);
    EXPECT_EQ(run("encode " + quoted(scan) + " " + quoted(target), &out), 1) << out;
    EXPECT_NE(out.find("refusing to overwrite"), std::string::npos) << out;
    EXPECT_TRUE(slurp(scan) == original) << "the input changed";
  }
  EXPECT_TRUE(fs::is_symlink(dir.file("soft.ply.zst")));
  // The report must not replace the container nor the input.
  EXPECT_EQ(run("encode " + quoted(scan) + " " + quoted(dir.file("o.spz")) + " --report " + quoted(dir.file("o.spz")),
                &out),
            1)
      << out;
  EXPECT_EQ(run("encode " + quoted(scan) + " " + quoted(dir.file("o.spz")) + " --report " + quoted(scan), &out), 1)
      << out;
  EXPECT_TRUE(slurp(scan) == original) << "the input changed";
  EXPECT_FALSE(fs::exists(dir.file("o.spz")));

  // decode IN OUT where OUT is IN: a container that happens to have a mesh extension, and a link to a
  // container.
  // (encode refuses to write a container under a mesh name, but one can be renamed.)
  ASSERT_EQ(run("encode " + quoted(scan) + " " + quoted(dir.file("c.spz")) + " --quiet", &out), 0) << out;
  fs::rename(dir.file("c.spz"), dir.file("c.ply"));
  const std::string container = slurp(dir.file("c.ply"));
  EXPECT_EQ(run("decode " + quoted(dir.file("c.ply")) + " " + quoted(dir.file("c.ply")), &out), 1) << out;
  fs::create_symlink("c.ply", dir.file("link.ply"));
  EXPECT_EQ(run("decode " + quoted(dir.file("c.ply")) + " " + quoted(dir.file("link.ply")), &out), 1) << out;
  EXPECT_TRUE(slurp(dir.file("c.ply")) == container) << "changed";
  EXPECT_EQ(run("info --verify " + quoted(dir.file("c.ply")), &out), 0) << out;
  EXPECT_TRUE(leftovers(dir.path()).empty());
}

TEST(Outputs, JobOutputsMustNotReplaceInputsNorEachOther) {
  testing::TempDir dir;
  fs::create_directories(dir.file("scans"));
  const std::string scan = dir.file("scans/a.ply.zst");
  fs::copy_file(kBunny, scan);
  const std::string original = slurp(scan);
  struct Case {
    const char* name;
    std::string output;  // the "output" object
    const char* pointer;
  };
  const std::vector<Case> cases = {
      // The container named as the input, in the input's directory.
      {"container_is_input", R"({"directory": "scans", "name": "{name}"})", "/output/name"},
      // The report named as the input.
      {"report_is_input", R"({"directory": "scans", "report": "{name}"})", "/output/report"},
      // The summary named as the input.
      {"summary_is_input", R"({"directory": "scans", "summary": "a.ply.zst"})", "/output/summary"},
      // The report named as the container: literally, and only once substituted.
      {"report_is_container", R"({"directory": "out", "name": "{stem}.spz", "report": "{stem}.spz"})",
       "/output/report"},
      {"report_is_container_substituted", R"({"directory": "out", "name": "{name}.x", "report": "{stem}.ply.zst.x"})",
       "/output/report"},
      {"summary_is_report", R"({"directory": "out", "report": "{stem}.json", "summary": "a.json"})", "/output/summary"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string job = dir.file(std::string(c.name) + ".json");
    testing::writeBytes(job, R"({"inputs": ["scans"], "output": )" + c.output + "}");
    std::string out;
    EXPECT_EQ(run("run " + quoted(job) + " --quiet", &out), 1) << out;
    EXPECT_NE(out.find(c.pointer), std::string::npos) << "expected '" << c.pointer << "' in: " << out;
    EXPECT_TRUE(slurp(scan) == original) << "the input changed";
    EXPECT_FALSE(fs::exists(dir.file("out"))) << "something was written";
    EXPECT_EQ(std::distance(fs::directory_iterator(dir.file("scans")), fs::directory_iterator()), 1);
  }
}

TEST(Outputs, SymlinksAreWrittenThroughAtomically) {
  testing::TempDir dir;
  fs::create_directories(dir.file("archive"));
  fs::create_directories(dir.file("links"));
  testing::writeBytes(dir.file("archive/scan.spz"), "old contents");
  // A relative link in another directory, and a link to that link.
  fs::create_symlink("../archive/scan.spz", dir.file("links/scan.spz"));
  fs::create_symlink(dir.file("links/scan.spz"), dir.file("chain.spz"));
  std::string out;
  ASSERT_EQ(run("encode " + quoted(kBunny) + " " + quoted(dir.file("chain.spz")) + " --quiet", &out), 0) << out;
  EXPECT_TRUE(fs::is_symlink(dir.file("chain.spz")));
  EXPECT_TRUE(fs::is_symlink(dir.file("links/scan.spz")));
  EXPECT_TRUE(fs::is_regular_file(fs::symlink_status(dir.file("archive/scan.spz"))));
  EXPECT_EQ(run("info --verify " + quoted(dir.file("archive/scan.spz")), &out), 0) << out;
  // A dangling link names the file to create.
  fs::create_symlink("archive/new.spz", dir.file("new.spz"));
  ASSERT_EQ(run("encode " + quoted(kBunny) + " " + quoted(dir.file("new.spz")) + " --quiet", &out), 0) << out;
  EXPECT_TRUE(fs::is_symlink(dir.file("new.spz")));
  EXPECT_EQ(run("info --verify " + quoted(dir.file("archive/new.spz")), &out), 0) << out;
  // Decode's mesh writer goes through the same code.
  testing::writeBytes(dir.file("archive/mesh.ply"), "old");
  fs::create_symlink("archive/mesh.ply", dir.file("mesh.ply"));
  ASSERT_EQ(run("decode " + quoted(dir.file("new.spz")) + " " + quoted(dir.file("mesh.ply")) + " --quiet", &out), 0)
      << out;
  EXPECT_TRUE(fs::is_symlink(dir.file("mesh.ply")));
  EXPECT_GT(fs::file_size(dir.file("archive/mesh.ply")), 100000u);
  EXPECT_TRUE(leftovers(dir.path()).empty());
}

TEST(Outputs, FifosDevicesAndSocketsAreRefused) {
  testing::TempDir dir;
  std::vector<std::string> specials;
  ASSERT_EQ(::mkfifo(dir.file("fifo.spz").c_str(), 0644), 0);
  specials.push_back(dir.file("fifo.spz"));
  fs::create_symlink("fifo.spz", dir.file("link-to-fifo.spz"));
  specials.push_back(dir.file("link-to-fifo.spz"));
  if (::mknod(dir.file("null.spz").c_str(), S_IFCHR | 0666, makedev(1, 3)) == 0)
    specials.push_back(dir.file("null.spz"));
  const int sock = ::socket(AF_UNIX, SOCK_STREAM, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  const std::string sock_path = dir.file("sock.spz");
  if (sock >= 0 && sock_path.size() < sizeof addr.sun_path) {
    std::strcpy(addr.sun_path, sock_path.c_str());
    if (::bind(sock, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0) specials.push_back(sock_path);
  }
  for (const std::string& target : specials) {
    SCOPED_TRACE(target);
    const auto kind = fs::status(target).type();
    std::string out;
    EXPECT_EQ(run("encode " + quoted(kBunny) + " " + quoted(target), &out), 1) << out;
    EXPECT_NE(out.find("regular files only"), std::string::npos) << out;
    EXPECT_EQ(fs::status(target).type(), kind) << "replaced";
  }
  if (sock >= 0) ::close(sock);
  EXPECT_TRUE(leftovers(dir.path()).empty());
}

TEST(Outputs, FileSizeLimitExitsThreeWithoutTemporary) {
  testing::TempDir dir;
  // The child keeps SIGXFSZ's default action (terminate): scanpress itself must ignore it.
  const pid_t pid = spawn({"encode", kBunny, dir.file("o.spz")}, [] {
    ::signal(SIGXFSZ, SIG_DFL);
    const rlimit limit{64 * 1024, 64 * 1024};
    ::setrlimit(RLIMIT_FSIZE, &limit);
  });
  const int status = waitStatus(pid);
  ASSERT_TRUE(WIFEXITED(status)) << "killed by signal " << (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
  EXPECT_EQ(WEXITSTATUS(status), 3);
  EXPECT_FALSE(fs::exists(dir.file("o.spz")));
  EXPECT_TRUE(leftovers(dir.path()).empty());
}

// Waits until `dir` holds a temporary or scratch directory whose path contains `marker` (the encode reached
// that step), at most `seconds`.
bool waitForTemporary(const std::string& dir, const std::string& marker, pid_t pid, double seconds) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    for (const std::string& path : leftovers(dir))
      if (path.find(marker) != std::string::npos) return true;
    if (::waitpid(pid, nullptr, WNOHANG) != 0) return false;  // ended already
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return false;
}

TEST(Outputs, InterruptRemovesTemporariesAndScratch) {
  testing::TempDir dir;
  const std::string scan = dir.file("big.ply");
  std::string out;
  ASSERT_EQ(run("synth " + quoted(scan) + " --triangles 2000000 --quiet", &out), 0) << out;
  fs::create_directories(dir.file("work"));
  // The smallest budget puts the tile data in scratch files (from the second pass on); the output's temporary
  // appears when the tiles start encoding. SIGTERM as soon as the scratch directory appears, SIGINT as soon
  // as the output's temporary does (both well before the encode could finish: it has 2M triangles to write).
  for (const auto& [sig, marker] :
       {std::pair<int, std::string>{SIGTERM, "scanpress-scratch-"}, {SIGINT, ".o.spz.tmp-"}}) {
    SCOPED_TRACE(sig);
    const pid_t pid = spawn({"encode", scan, dir.file("work/o.spz"), "--memory-budget", "16M", "--scratch-dir",
                             dir.file("work"), "--threads", "2"});
    const bool underway = waitForTemporary(dir.file("work"), marker, pid, 60);
    ::kill(pid, sig);
    const int status = waitStatus(pid);
    ASSERT_TRUE(underway) << "the encode ended before creating " << marker;
    ASSERT_TRUE(WIFEXITED(status)) << "killed by signal " << (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
    EXPECT_EQ(WEXITSTATUS(status), 128 + sig);
    EXPECT_FALSE(fs::exists(dir.file("work/o.spz")));
    const auto left = leftovers(dir.file("work"));
    EXPECT_TRUE(left.empty()) << left.front();
  }
}

// A job over a scans/ folder holding the bunny, writing to out/: returns the job file.
std::string bunnyJob(testing::TempDir& dir) {
  fs::create_directories(dir.file("scans"));
  fs::copy_file(kBunny, dir.file("scans/bunny.ply.zst"));
  const std::string job = dir.file("job.json");
  testing::writeBytes(job, R"({"inputs": ["scans"], "output": {"directory": "out"}})");
  return job;
}

TEST(Outputs, ResumeRemovesTemporariesOfDeadRuns) {
  testing::TempDir dir;
  const std::string job = bunnyJob(dir);
  std::string out;
  ASSERT_EQ(run("run " + quoted(job) + " --quiet", &out), 0) << out;
  // What kill -9 leaves: a partial temporary named with a PID that no longer runs. One of a live PID (this
  // test) may belong to a run in progress and stays.
  const std::string dead = dir.file("out/.bunny.spz.tmp-" + std::to_string(deadPid()) + "-0");
  const std::string live = dir.file("out/.bunny.spz.tmp-" + std::to_string(::getpid()) + "-0");
  testing::writeBytes(dead, "partial");
  testing::writeBytes(live, "partial");
  ASSERT_EQ(run("run " + quoted(job) + " --quiet", &out), 0) << out;
  EXPECT_FALSE(fs::exists(dead));
  EXPECT_TRUE(fs::exists(live));
  EXPECT_EQ(removeStaleTemporaries(dir.file("out")), 0u);
  EXPECT_TRUE(fs::exists(live));
}

TEST(Outputs, ResumeRedoesAContainerThatFailsItsChecksums) {
  testing::TempDir dir;
  const std::string job = bunnyJob(dir);
  std::string out;
  ASSERT_EQ(run("run " + quoted(job) + " --quiet", &out), 0) << out;
  const std::string container = dir.file("out/bunny.spz");
  // Flip one byte in the middle of the first tile's payload: header, index and footer stay valid.
  uint64_t at = 0;
  {
    auto file = ContainerFile::open(container);
    ASSERT_TRUE(file.isOk()) << file.status().toString();
    const TileEntry& tile = file->tiles().at(0);
    at = tile.offset + tile.chunk_bytes / 2;
  }
  auto bytes = testing::readBytes(container);
  bytes.at(at) ^= 0x40;
  testing::writeBytes(container, std::string(bytes.begin(), bytes.end()));
  ASSERT_TRUE(ContainerFile::open(container).isOk());
  ASSERT_EQ(run("info --verify " + quoted(container), &out), 2) << out;

  ASSERT_EQ(run("run " + quoted(job) + " --quiet", &out), 0) << out;
  const auto summary = nlohmann::json::parse(slurp(dir.file("out/summary.json")));
  ASSERT_EQ(summary["files"].size(), 1u);
  EXPECT_EQ(summary["files"][0]["status"], "ok");
  EXPECT_EQ(run("info --verify " + quoted(container), &out), 0) << out;
  // Now intact: the next run skips it.
  ASSERT_EQ(run("run " + quoted(job) + " --quiet", &out), 0) << out;
  EXPECT_EQ(nlohmann::json::parse(slurp(dir.file("out/summary.json")))["files"][0]["status"], "skipped");
}

}  // namespace
}  // namespace scanpress
