// Durability (issue 18, "Hardening that stays"): a batch (`scanpress run` over a few `scanpress synth` scans)
// killed with SIGKILL at 20 seeded random moments, and resumed each time, ends with outputs byte-identical to
// an uninterrupted run, and never leaves a file under a final name that does not verify (`info --verify`). A
// run that finishes before its kill moment is checked against the uninterrupted run too, and the batch starts
// over, so that the kills keep landing inside the work.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "jobs_util.h"

namespace scanpress {
namespace {

namespace fs = std::filesystem;

std::string readWhole(const fs::path& p) { return testing::readText(p.string()); }

// Starts `scanpress run JOB --quiet` in its own process group (so that a kill reaches whatever it starts),
// output discarded.
pid_t startRun(const std::string& job) {
  const pid_t pid = fork();
  if (pid == 0) {
    setpgid(0, 0);
    const int null_fd = ::open("/dev/null", O_WRONLY);
    dup2(null_fd, 1);
    dup2(null_fd, 2);
    execl(SCANPRESS_BIN, SCANPRESS_BIN, "run", job.c_str(), "--quiet", static_cast<char*>(nullptr));
    _exit(127);
  }
  return pid;
}

int waitExit(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

void writeJob(const fs::path& job, const fs::path& inputs, const fs::path& out) {
  std::ofstream(job) << R"({"inputs": [")" << (inputs / "*.ply").string() << R"("], "output": {"directory": ")"
                     << out.string() << R"("}, "codec": {"name": "kdtree", "bits": 14}, "tiling": )"
                     << R"({"target_triangles": 2048}, "threads": 2})";
}

// Files under a final name (not a dot-file) and temporary files (".NAME.tmp-PID-N") in `dir`.
struct DirState {
  std::vector<fs::path> finals;
  std::vector<fs::path> temps;
};
DirState listDir(const fs::path& dir) {
  DirState s;
  if (!fs::exists(dir)) return s;
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    if (name.find(".tmp-") != std::string::npos) s.temps.push_back(e.path());
    else if (name[0] != '.') s.finals.push_back(e.path());
  }
  std::sort(s.finals.begin(), s.finals.end());
  return s;
}

TEST(Durability, KilledAndResumedBatchMatchesAnUninterruptedRun) {
  const fs::path dir = fs::path(::testing::TempDir()) / ("durability-" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir / "in");
  const int triangles[] = {16000, 6000, 10000, 3000};
  for (int i = 0; i < 4; ++i) {
    const std::string ply = (dir / "in" / ("scan" + std::to_string(i) + ".ply")).string();
    ASSERT_EQ(testing::runScanpress("synth '" + ply + "' --triangles " + std::to_string(triangles[i]) + " --seed " +
                                    std::to_string(i + 1) + " --quiet"),
              0);
  }
  writeJob(dir / "ref.json", dir / "in", dir / "ref");
  writeJob(dir / "kill.json", dir / "in", dir / "out");

  // The uninterrupted run, timed: the kill moments are spread over 0.8 times its duration.
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_EQ(waitExit(startRun((dir / "ref.json").string())), 0);
  const double ref_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const DirState ref = listDir(dir / "ref");
  std::vector<fs::path> ref_containers;
  for (const auto& p : ref.finals)
    if (p.extension() == ".spz") ref_containers.push_back(p);
  ASSERT_EQ(ref_containers.size(), 4u);

  std::mt19937_64 rng(18);
  std::uniform_real_distribution<double> moment(0.0, 0.8 * ref_seconds);
  auto expectSameContainers = [&](const std::string& when) {
    for (const auto& ref_path : ref_containers) {
      const fs::path p = dir / "out" / ref_path.filename();
      ASSERT_TRUE(fs::exists(p)) << when << ": " << p;
      EXPECT_TRUE(readWhole(p) == readWhole(ref_path)) << when << ": " << p << " differs from the uninterrupted run's";
    }
  };
  int killed_mid_run = 0, completed = 0, temps_seen = 0, finals_checked = 0;
  for (int k = 0; k < 20; ++k) {
    const pid_t pid = startRun((dir / "kill.json").string());
    std::this_thread::sleep_for(std::chrono::duration<double>(moment(rng)));
    kill(-pid, SIGKILL);
    kill(pid, SIGKILL);
    const int code = waitExit(pid);
    if (code == 128 + SIGKILL) ++killed_mid_run;
    // Every container under its final name is complete: its checksums and every tile verify.
    const DirState s = listDir(dir / "out");
    for (const auto& p : s.finals) {
      if (p.extension() != ".spz") continue;
      std::string out;
      EXPECT_EQ(testing::runScanpress("info --verify '" + p.string() + "'", &out), 0)
          << "after kill " << k << ": " << p << " does not verify: " << out;
      ++finals_checked;
    }
    temps_seen += static_cast<int>(s.temps.size());
    if (code == 0) {  // finished before the kill: complete and identical; start the batch over
      ++completed;
      expectSameContainers("run " + std::to_string(k) + " (finished before its kill)");
      fs::remove_all(dir / "out");
    }
  }
  // The resumed run that finishes.
  ASSERT_EQ(waitExit(startRun((dir / "kill.json").string())), 0);
  const DirState done = listDir(dir / "out");
  expectSameContainers("the final resumed run");
  // Temporary files of killed runs are removed by the next run in that output directory (their PIDs are dead).
  EXPECT_TRUE(done.temps.empty()) << done.temps.size() << " temporary files left, e.g. " << done.temps.front();
  std::printf(
      "durability: uninterrupted run %.2f s; of 20 runs, %d killed before finishing and %d finished first "
      "(identical, batch started over); %d containers under final names verified after kills; temp files "
      "seen after kills %d, left at the end %zu\n",
      ref_seconds, killed_mid_run, completed, finals_checked, temps_seen, done.temps.size());
  EXPECT_GE(killed_mid_run, 5) << "the kill moments should mostly fall inside a run";
  fs::remove_all(dir);
}

}  // namespace
}  // namespace scanpress
