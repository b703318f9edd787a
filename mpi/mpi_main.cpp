// scanpress-mpi: the scanpress command line on rank 0; every other rank encodes tiles for it (issue 23 part 2).
//
//   mpirun -np 4 scanpress-mpi encode huge.ply huge.spz [encode options]
//   srun scanpress-mpi run archive.json
//
// Rank 0 runs the command as `scanpress` would. Its encodes (`encode`, `run`, with targets too) read, quantize and
// tile each scan, then send the built tiles to the worker ranks and write their results in tile order
// (jobs/remote_tiles.h): the container is byte-identical to a `scanpress` encode. Commands that do not encode run
// on rank 0 alone. With one rank, scanpress-mpi is scanpress.
//
// Threads: rank 0 tiles and writes (its --threads serve the read and the tiling); each worker runs its tiles in its
// own oneTBB arena of --threads threads, else SLURM_CPUS_PER_TASK, else the node's cores divided among the ranks
// on that node.
//
// MPI is called from each rank's main thread only (MPI_THREAD_FUNNELED). Waiting for a message does not spin: a
// probe, then a sleep growing from 20 us to 1 ms (blocking MPI receives busy-poll a core, which on a node shared
// with workers is a core taken from them).
#include <mpi.h>
#include <oneapi/tbb/global_control.h>
#include <oneapi/tbb/info.h>
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include "jobs/cli/cli.h"
#include "jobs/process.h"
#include "jobs/remote_tiles.h"

namespace scanpress {
namespace {

constexpr int kTag = 7;
constexpr auto kFirstWait = std::chrono::microseconds(20);
constexpr auto kLongestWait = std::chrono::microseconds(1000);

// Messages on their way: sent without blocking (MPI_Isend), their buffers kept until MPI is done with them. A
// blocking send of a large message waits for the receiver to post its receive, and two ranks each sending the
// other a large message (a tile one way, a result the other) would wait for each other forever.
class Outbox {
 public:
  Status send(int rank, std::vector<uint8_t> message) {
    if (message.size() > static_cast<size_t>(INT_MAX))
      return makeError(ErrorCode::kLimitExceeded,
                       "a tile message of " + std::to_string(message.size()) +
                           " bytes is over MPI's 2 GiB per message (lower --tile-triangles)");
    progress();
    buffers_.push_back(std::move(message));
    requests_.push_back(MPI_REQUEST_NULL);
    // MPI's default error handler ends the job on a failed send: there is no status to return.
    MPI_Isend(buffers_.back().data(), static_cast<int>(buffers_.back().size()), MPI_BYTE, rank, kTag, MPI_COMM_WORLD,
              &requests_.back());
    return Status::ok();
  }
  // Releases the buffers of completed sends.
  void progress() {
    for (size_t i = 0; i < requests_.size();) {
      int done = 0;
      MPI_Test(&requests_[i], &done, MPI_STATUS_IGNORE);
      if (done) {
        requests_.erase(requests_.begin() + static_cast<std::ptrdiff_t>(i));
        buffers_.erase(buffers_.begin() + static_cast<std::ptrdiff_t>(i));
      } else {
        ++i;
      }
    }
  }
  // Every send completed (the receivers are receiving).
  void flush() {
    while (!requests_.empty()) {
      progress();
      if (!requests_.empty()) std::this_thread::sleep_for(kFirstWait);
    }
  }

 private:
  std::deque<MPI_Request> requests_;
  std::deque<std::vector<uint8_t>> buffers_;
};

// A message from `source` (or any rank), waited for without spinning; the outbox's sends progress meanwhile.
std::pair<int, std::vector<uint8_t>> receiveFrom(int source, Outbox& outbox) {
  auto wait = kFirstWait;
  MPI_Status st;
  int flag = 0;
  while (MPI_Iprobe(source, kTag, MPI_COMM_WORLD, &flag, &st), !flag) {
    outbox.progress();
    std::this_thread::sleep_for(wait);
    wait = std::min(2 * wait, kLongestWait);
  }
  int n = 0;
  MPI_Get_count(&st, MPI_BYTE, &n);
  std::vector<uint8_t> message(static_cast<size_t>(n));
  MPI_Recv(message.data(), n, MPI_BYTE, st.MPI_SOURCE, kTag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
  return {st.MPI_SOURCE, std::move(message)};
}

// Rank 0's side: worker w is rank w + 1.
class MpiTransport : public TileTransport {
 public:
  explicit MpiTransport(int ranks) : ranks_(ranks) {}
  uint32_t workers() const override { return static_cast<uint32_t>(ranks_ - 1); }
  Status send(uint32_t worker, std::vector<uint8_t> message) override {
    return outbox_.send(static_cast<int>(worker) + 1, std::move(message));
  }
  Result<Received> receive() override {
    auto [rank, message] = receiveFrom(MPI_ANY_SOURCE, outbox_);
    return Received{static_cast<uint32_t>(rank - 1), std::move(message)};
  }
  // The workers quit once every message is delivered.
  void quit() {
    for (uint32_t w = 0; w < workers(); ++w) (void)send(w, quitMessage());
    outbox_.flush();
  }

 private:
  int ranks_;
  Outbox outbox_;
};

// The ranks on this rank's node.
int localRanks() {
  MPI_Comm node;
  MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node);
  int n = 1;
  MPI_Comm_size(node, &n);
  MPI_Comm_free(&node);
  return std::max(1, n);
}

// Threads of a worker: asked for (--threads), else SLURM_CPUS_PER_TASK, else the cores shared among local ranks.
int workerThreads(int requested, int local_ranks) {
  if (requested > 0) return requested;
  if (const char* slurm = std::getenv("SLURM_CPUS_PER_TASK"))
    if (int n = std::atoi(slurm); n > 0) return n;
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()) / local_ranks);
}

// A worker rank: serves rank 0's scans and tiles until told to quit. Tiles run in a oneTBB arena; their results
// queue here and the main thread sends them.
int serve(int local_ranks) {
  TileServer server;
  Outbox outbox;
  std::unique_ptr<tbb::global_control> allow;
  std::unique_ptr<tbb::task_arena> arena;
  std::mutex mutex;
  std::condition_variable cv;
  std::deque<std::vector<uint8_t>> done;
  int running = 0;

  auto sendDone = [&] {
    std::deque<std::vector<uint8_t>> ready;
    {
      std::lock_guard lock(mutex);
      ready.swap(done);
    }
    for (auto& m : ready) {
      // A result MPI cannot carry (over 2 GiB) is answered as a failed tile, so rank 0 is not left waiting.
      uint32_t tile = kUnreadTile;
      if (m.size() >= 5) std::memcpy(&tile, m.data() + 1, 4);
      if (Status sent = outbox.send(0, std::move(m)); !sent.isOk()) {
        TileResult failed;
        failed.tile = tile;
        failed.status = sent.withContext("worker");
        (void)outbox.send(0, resultMessage(failed));
      }
    }
  };
  // Every tile running now answered: before a new scan replaces the settings, and before quitting.
  auto drain = [&] {
    while (true) {
      {
        std::unique_lock lock(mutex);
        cv.wait(lock, [&] { return !done.empty() || running == 0; });
        if (done.empty() && running == 0) return;
      }
      sendDone();
    }
  };

  auto wait = kFirstWait;
  while (true) {
    sendDone();
    int flag = 0;
    MPI_Status st;
    MPI_Iprobe(0, kTag, MPI_COMM_WORLD, &flag, &st);
    if (!flag) {
      outbox.progress();
      std::unique_lock lock(mutex);
      cv.wait_for(lock, wait, [&] { return !done.empty(); });
      wait = std::min(2 * wait, kLongestWait);
      continue;
    }
    wait = kFirstWait;
    auto message = std::make_shared<std::vector<uint8_t>>(receiveFrom(0, outbox).second);
    auto kind = messageKind(*message);
    if (!kind.isOk()) {
      std::fprintf(stderr, "scanpress-mpi: error: internal error: %s\n", kind.status().toString().c_str());
      MPI_Abort(MPI_COMM_WORLD, 4);
    }
    switch (*kind) {
      case TileMessage::kQuit:
        drain();
        outbox.flush();
        return 0;
      case TileMessage::kScan: {
        drain();
        const Status status = server.scan(*message);
        const int threads = workerThreads(server.requestedThreads(), local_ranks);
        if (!arena || arena->max_concurrency() != threads) {
          arena.reset();
          // More threads than cores when asked for: oneTBB's worker limit must allow them (as the pipeline does).
          allow =
              std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    std::max<size_t>(threads + 1, tbb::info::default_concurrency()));
          // No slot reserved for this thread, which stays out of the arena: `threads` workers run the tiles.
          arena = std::make_unique<tbb::task_arena>(threads, 0);
        }
        (void)outbox.send(0, readyMessage(2 * static_cast<uint32_t>(threads), status));
        break;
      }
      case TileMessage::kTile: {
        {
          std::lock_guard lock(mutex);
          ++running;
        }
        arena->enqueue([&, message] {
          std::vector<uint8_t> result = server.tile(*message);
          std::lock_guard lock(mutex);
          done.push_back(std::move(result));
          --running;
          cv.notify_all();
        });
        break;
      }
      default:
        std::fprintf(stderr, "scanpress-mpi: error: internal error: a worker was sent message kind %d\n",
                     static_cast<int>(*kind));
        MPI_Abort(MPI_COMM_WORLD, 4);
    }
  }
}

}  // namespace
}  // namespace scanpress

int main(int argc, char** argv) {
  scanpress::tuneAllocator();  // every rank: rank 0's cliMain sets it too, the workers only here
  int provided = 0;
  MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
  if (provided < MPI_THREAD_FUNNELED) {
    std::fprintf(stderr, "scanpress-mpi: error: this MPI cannot be used with threads (MPI_THREAD_FUNNELED)\n");
    MPI_Abort(MPI_COMM_WORLD, 3);
  }
  int rank = 0, ranks = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &ranks);
  const int local_ranks = scanpress::localRanks();
  int code = 0;
  if (rank == 0) {
    std::optional<scanpress::MpiTransport> transport;
    if (ranks > 1) {
      transport.emplace(ranks);
      scanpress::setTileTransport(&*transport);
    }
    code = scanpress::cliMain(argc, argv);
    scanpress::setTileTransport(nullptr);
    if (transport) transport->quit();
  } else {
    code = scanpress::serve(local_ranks);
  }
  MPI_Finalize();
  return code;
}
