#include "jobs/cleanup.h"

#include <signal.h>
#include <string.h>
#include <unistd.h>

#include <filesystem>
#include <map>
#include <mutex>
#include <thread>

namespace scanpress {
namespace {

struct Registry {
  std::mutex mutex;
  uint64_t next_id = 1;
  std::map<uint64_t, std::pair<TrackedKind, std::string>> entries;
};

// Never destroyed: the cleanup thread may use it while static destructors run at exit.
Registry& registry() {
  static Registry* r = new Registry;
  return *r;
}

void writeStderr(const std::string& text) {
  size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(STDERR_FILENO, text.data() + done, text.size() - done);
    if (n <= 0) return;
    done += static_cast<size_t>(n);
  }
}

// The cleanup thread: waits for a signal, removes every temporary and ends the process, holding the lock
// throughout.
[[noreturn]] void cleanupOnSignal(sigset_t set) {
  int sig = 0;
  while (::sigwait(&set, &sig) != 0) {
  }
  Registry& r = registry();
  r.mutex.lock();  // never unlocked: no temporary may be created after this point
  for (const auto& [id, entry] : r.entries) {
    std::error_code ec;
    if (entry.first == TrackedKind::kFile) ::unlink(entry.second.c_str());
    if (entry.first == TrackedKind::kDirectory) std::filesystem::remove_all(entry.second, ec);
  }
  writeStderr(std::string("scanpress: interrupted by ") + ::strsignal(sig) + "; temporary files removed\n");
  ::_exit(128 + sig);
}

}  // namespace

uint64_t createTracked(TrackedKind kind, const std::function<std::string()>& create) {
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  std::string path = create();
  if (path.empty()) return 0;
  const uint64_t id = r.next_id++;
  r.entries.emplace(id, std::make_pair(kind, std::move(path)));
  return id;
}

void untrack(uint64_t id) {
  if (id == 0) return;
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  r.entries.erase(id);
}

void underRegistryLock(const std::function<void()>& fn) {
  std::lock_guard lock(registry().mutex);
  fn();
}

size_t trackedCount() {
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  return r.entries.size();
}

void installInterruptCleanup() {
  sigset_t set;
  sigemptyset(&set);
  for (const int sig : {SIGINT, SIGTERM, SIGHUP}) {
    // A signal ignored on entry stays ignored (nohup ignores SIGHUP; a shell ignores SIGINT for `cmd &`).
    struct sigaction current {};
    if (::sigaction(sig, nullptr, &current) == 0 && current.sa_handler == SIG_IGN) continue;
    sigaddset(&set, sig);
  }
  // Nothing to wait for, or the mask cannot be set: the signals keep their default actions.
  if (sigisemptyset(&set) || ::pthread_sigmask(SIG_BLOCK, &set, nullptr) != 0) return;
  // The registry is constructed here, before any signal can need it.
  registry();
  std::thread(cleanupOnSignal, set).detach();
}

}  // namespace scanpress
