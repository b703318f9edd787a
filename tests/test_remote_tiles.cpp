// Tiles encoded in other processes (issue 23 part 2, jobs/remote_tiles.h), without MPI: workers are threads
// behind an in-process transport that carries the same bytes MPI carries. The independent truth is the local
// encode: the container must be byte-identical and the report's error sums equal, for every codec kind, any number
// of workers (more workers than tiles too), subsets, the target search, and workers answering out of order. A tile
// the worker cannot read fails that tile as a local failure does; a worker that cannot run the scan fails the
// encode and leaves no output. The messages themselves round-trip, and every truncation of one is refused.
#include <gtest/gtest.h>

#include <condition_variable>
#include <deque>
#include <filesystem>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "jobs/pipeline.h"
#include "jobs/remote_tiles.h"
#include "jobs_util.h"

namespace scanpress {
namespace {

namespace fs = std::filesystem;

// Workers as threads. Each answers its messages in arrival order, except that when two tiles wait it runs the later
// one first (answers out of order, as a multi-threaded worker may). `tamper` may change a message on its way to a
// worker.
class ThreadTransport : public TileTransport {
 public:
  using Tamper = std::function<void(uint32_t worker, std::vector<uint8_t>& message)>;
  explicit ThreadTransport(uint32_t workers, Tamper tamper = nullptr) : inboxes_(workers), tamper_(std::move(tamper)) {
    for (uint32_t w = 0; w < workers; ++w) threads_.emplace_back([this, w] { serve(w); });
  }
  ~ThreadTransport() override {
    for (uint32_t w = 0; w < workers(); ++w) (void)send(w, quitMessage());
    for (auto& t : threads_) t.join();
  }
  uint32_t workers() const override { return static_cast<uint32_t>(inboxes_.size()); }
  Status send(uint32_t worker, std::vector<uint8_t> message) override {
    if (tamper_) tamper_(worker, message);
    std::lock_guard lock(mutex_);
    inboxes_[worker].push_back(std::move(message));
    cv_.notify_all();
    return Status::ok();
  }
  Result<Received> receive() override {
    std::unique_lock lock(mutex_);
    cv_.wait(lock, [&] { return !outbox_.empty(); });
    Received r = std::move(outbox_.front());
    outbox_.pop_front();
    return r;
  }
  uint64_t tilesServed() const { return tiles_served_; }

 private:
  void serve(uint32_t w) {
    TileServer server;
    while (true) {
      std::vector<uint8_t> message;
      {
        std::unique_lock lock(mutex_);
        cv_.wait(lock, [&] { return !inboxes_[w].empty(); });
        auto& inbox = inboxes_[w];
        // Two tiles waiting: the later one first.
        const bool swap = inbox.size() >= 2 && inbox[0][0] == uint8_t(TileMessage::kTile) &&
                          inbox[1][0] == uint8_t(TileMessage::kTile);
        message = std::move(inbox[swap ? 1 : 0]);
        inbox.erase(inbox.begin() + (swap ? 1 : 0));
      }
      std::vector<uint8_t> reply;
      switch (message.empty() ? TileMessage::kTile : TileMessage(message[0])) {
        case TileMessage::kQuit: return;
        case TileMessage::kScan: reply = readyMessage(2, server.scan(message)); break;
        default: reply = server.tile(message); ++tiles_served_;
      }
      std::lock_guard lock(mutex_);
      outbox_.push_back({w, std::move(reply)});
      cv_.notify_all();
    }
  }

  std::vector<std::deque<std::vector<uint8_t>>> inboxes_;
  std::deque<Received> outbox_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<std::thread> threads_;
  Tamper tamper_;
  std::atomic<uint64_t> tiles_served_{0};
};

// Installs a transport for the scope.
struct UseTransport {
  explicit UseTransport(TileTransport* t) { setTileTransport(t); }
  ~UseTransport() { setTileTransport(nullptr); }
};

class RemoteTiles : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir;
    std::string out;
    ASSERT_EQ(testing::runScanpress("synth '" + dir_->file("a.ply") + "' --triangles 40000 --seed 5", &out), 0) << out;
  }
  static void TearDownTestSuite() { delete dir_; }
  static EncodeSettings settings(const std::string& codec, const std::string& out) {
    EncodeSettings s;
    s.input = dir_->file("a.ply");
    s.output = dir_->file(out);
    s.codec = codec;
    s.tile_triangles = 2048;
    s.threads = 2;
    s.measure.enabled = true;
    s.measure.samples_per_triangle = 0.5;
    return s;
  }
  // Local encode and remote encode at `workers`; both must succeed with identical bytes and reports.
  static void expectSame(const EncodeSettings& local_settings, uint32_t workers) {
    auto local = encodeFile(local_settings);
    ASSERT_TRUE(local.isOk()) << local.status().toString();
    EncodeSettings remote_settings = local_settings;
    remote_settings.output += ".remote";
    ThreadTransport transport(workers);
    UseTransport use(&transport);
    auto remote = encodeFile(remote_settings);
    ASSERT_TRUE(remote.isOk()) << remote.status().toString();
    EXPECT_EQ(testing::readBytes(remote_settings.output), testing::readBytes(local_settings.output));
    EXPECT_GT(local->tiles.size(), 1u);
    EXPECT_EQ(transport.tilesServed() > 0, !local->tiles.empty());
    EXPECT_EQ(remote->bytes, local->bytes);
    EXPECT_EQ(remote->failed_tiles, 0u);
    ASSERT_EQ(remote->tiles.size(), local->tiles.size());
    for (size_t t = 0; t < local->tiles.size(); ++t) {
      EXPECT_EQ(remote->tiles[t].bytes, local->tiles[t].bytes);
      EXPECT_EQ(remote->tiles[t].border_vertices, local->tiles[t].border_vertices);
      EXPECT_EQ(remote->tiles[t].knob_cells, local->tiles[t].knob_cells);
    }
    // The same samples, in the same order: equal to the bit.
    EXPECT_EQ(remote->forward.count, local->forward.count);
    EXPECT_EQ(remote->forward.sum_sq, local->forward.sum_sq);
    EXPECT_EQ(remote->backward.max, local->backward.max);
    EXPECT_EQ(remote->measured, local->measured);
    if (local->target) {
      ASSERT_TRUE(remote->target.has_value());
      EXPECT_EQ(remote->target->bits, local->target->bits);
      EXPECT_EQ(remote->target->error, local->target->error);
    }
  }
  static testing::TempDir* dir_;
};
testing::TempDir* RemoteTiles::dir_ = nullptr;

TEST_F(RemoteTiles, ByteIdenticalToALocalEncodeForEveryCodecKind) {
#if defined(__SANITIZE_ADDRESS__)  // the slow sanitizer build: one worker count
  const std::vector<uint32_t> worker_counts = {3};
#else
  const std::vector<uint32_t> worker_counts = {1, 3};
#endif
  for (const char* codec : {"edgebreaker", "kdtree", "pm"}) {
    for (uint32_t workers : worker_counts) {
      SCOPED_TRACE(std::string(codec) + " workers=" + std::to_string(workers));
      expectSame(settings(codec, std::string(codec) + ".spz"), workers);
    }
  }
}

TEST_F(RemoteTiles, StagesAndPointClouds) {
  EncodeSettings s = settings("octree", "smooth.spz");
  StageSpec smooth;
  smooth.smooth.iterations = 3;
  s.stages.push_back(smooth);
  expectSame(s, 2);
  // A point cloud: its tiles have vertices and no triangles.
  const std::string cloud = dir_->file("cloud.ply");
  {
    std::FILE* f = std::fopen(cloud.c_str(), "w");
    ASSERT_NE(f, nullptr);
    const int n = 20000;
    std::fprintf(f,
                 "ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
                 "property float z\nend_header\n",
                 n);
    for (int i = 0; i < n; ++i) std::fprintf(f, "%d %d %d\n", (i * 7919) % 1000, (i * 104729) % 997, i % 991);
    std::fclose(f);
  }
  EncodeSettings p = settings("kdtree", "cloud.spz");
  p.input = cloud;
  expectSame(p, 2);
}

TEST_F(RemoteTiles, MoreWorkersThanTiles) {
  EncodeSettings s = settings("edgebreaker", "few.spz");
  s.tile_triangles = 16384;  // a handful of tiles
  expectSame(s, 12);
}

TEST_F(RemoteTiles, SubsetsAndTargets) {
  EncodeSettings s = settings("edgebreaker", "part.spz");
  s.subset_index = 1;
  s.subset_count = 3;
  expectSame(s, 2);
#if !defined(__SANITIZE_ADDRESS__)  // several measured encodes: Release only (tests/cluster/mpi_test.sh has one too)
  EncodeSettings t = settings("pm", "target.spz");
  t.target.kind = TargetKind::kMaxError;
  t.target.max_error = 2e-4;
  t.target.metric = ErrorMetric::kRms;
  expectSame(t, 2);
#endif
}

TEST_F(RemoteTiles, ATileTheWorkerCannotReadFailsThatTileOnly) {
  EncodeSettings s = settings("edgebreaker", "bad-tile.spz");
  s.measure.enabled = false;
  // Tile 2's message loses its last byte on the way.
  ThreadTransport transport(2, [](uint32_t, std::vector<uint8_t>& m) {
    if (m.size() > 5 && m[0] == uint8_t(TileMessage::kTile) && m[1] == 2 && m[2] == 0 && m[3] == 0 && m[4] == 0)
      m.pop_back();
  });
  UseTransport use(&transport);
  auto r = encodeFile(s);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_EQ(r->failed_tiles, 1u);
  ASSERT_GT(r->tiles.size(), 2u);
  EXPECT_FALSE(r->tiles[2].status.isOk());
  EXPECT_NE(r->tiles[2].status.message().find("worker: tile message"), std::string::npos)
      << r->tiles[2].status.message();
  EXPECT_GT(r->tiles[2].faces, 0u);  // the report says what the tile lost
}

TEST_F(RemoteTiles, AWorkerThatCannotRunTheScanFailsTheEncodeAndWritesNothing) {
  EncodeSettings s = settings("edgebreaker", "refused.spz");
  ThreadTransport transport(3, [](uint32_t worker, std::vector<uint8_t>& m) {
    if (worker == 1 && m[0] == uint8_t(TileMessage::kScan)) m[1] ^= 0x40;  // another wire version
  });
  UseTransport use(&transport);
  auto r = encodeFile(s);
  ASSERT_FALSE(r.isOk());
  EXPECT_NE(r.status().message().find("worker 1"), std::string::npos) << r.status().toString();
  EXPECT_NE(r.status().message().find("wire version"), std::string::npos) << r.status().toString();
  EXPECT_FALSE(fs::exists(s.output));
}

TEST(RemoteTileMessages, RoundTripAndEveryTruncationIsRefused) {
  TileResult t;
  t.tile = 7;
  t.status = makeError(ErrorCode::kMalformed, "something");
  t.encoded.payload = {1, 2, 3, 4, 5};
  t.encoded.decoded.vertices = 11;
  t.encoded.decoded.faces = 13;
  t.encoded.decoded.lo = {1, 2, 3};
  t.encoded.decoded.hi = {4, 5, 6};
  CodecLevel level;
  level.level = 3;
  level.end_bytes = 99;
  level.kind = LevelKind::kSimplified;
  level.complete = true;
  level.vertices = 17;
  level.max_error = 0.25;
  t.encoded.levels.assign(30, level);  // as many levels as kdtree makes at 24 bits, and more
  t.border = 5;
  t.input_vertices = 20;
  t.input_faces = 30;
  t.forward.add(0.5);
  t.backward.add(0.25);
  t.knob_cells = 1.5;
  t.target_met = false;
  t.knob_trials = 4;
  const std::vector<uint8_t> m = resultMessage(t);
  auto back = readResult(m);
  ASSERT_TRUE(back.isOk()) << back.status().toString();
  EXPECT_EQ(resultMessage(*back), m);
  EXPECT_EQ(back->status.message(), "something");
  EXPECT_EQ(back->encoded.levels.size(), 30u);
  EXPECT_EQ(back->encoded.levels[1].max_error, 0.25);
  for (size_t n = 0; n < m.size(); ++n) {
    auto cut = readResult(std::span(m).first(n));
    EXPECT_FALSE(cut.isOk()) << n;
  }
  std::vector<uint8_t> longer = m;
  longer.push_back(0);
  EXPECT_FALSE(readResult(longer).isOk());

  auto ready = readReady(readyMessage(6, makeError(ErrorCode::kIo, "no device")));
  ASSERT_TRUE(ready.isOk());
  EXPECT_EQ(ready->slots, 6u);
  EXPECT_EQ(ready->status.code(), ErrorCode::kIo);

  // A worker given garbage answers with a failed result (or a refusal), never crashes.
  {
    TileServer worker;
    EncodeSettings settings;
    TileScanFacts facts;
    facts.grid.bits = 12;
    ASSERT_TRUE(worker.scan(scanMessage(settings, facts)).isOk());
    TileMesh tm;
    tm.tile_id = 3;
    tm.mesh.positions = {{1, 2, 3}, {4, 5, 6}, {7, 8, 9}};
    tm.mesh.triangles = {{0, 1, 2}};
    tm.local_to_global = {0, 1, 2};
    tm.border = {0, 0, 0};
    auto good = readResult(worker.tile(tileMessage(tm, {})));
    ASSERT_TRUE(good.isOk());
    EXPECT_TRUE(good->status.isOk()) << good->status.toString();
    EXPECT_EQ(good->tile, 3u);
    // An index past the vertices, a coordinate off the 12-bit grid, a border flag missing: refused before any
    // codec sees the tile.
    for (int damage = 0; damage < 3; ++damage) {
      TileMesh bad = tm;
      if (damage == 0) bad.mesh.triangles[0][2] = 7;
      if (damage == 1) bad.mesh.positions[1][0] = 4096;
      if (damage == 2) bad.border.pop_back();
      auto refused = readResult(worker.tile(tileMessage(bad, {})));
      ASSERT_TRUE(refused.isOk());
      EXPECT_FALSE(refused->status.isOk()) << damage;
      EXPECT_EQ(refused->tile, 3u);
      EXPECT_TRUE(refused->encoded.payload.empty());
    }
    // Scan facts out of range.
    facts.grid.bits = 40;
    EXPECT_FALSE(worker.scan(scanMessage(settings, facts)).isOk());
    facts.grid.bits = 12;
    facts.layout.color_channels = 7;
    EXPECT_FALSE(worker.scan(scanMessage(settings, facts)).isOk());
  }
  TileServer server;
  EXPECT_FALSE(server.scan(std::vector<uint8_t>{1, 2, 3}).isOk());
  auto answer = readResult(server.tile(std::vector<uint8_t>{2, 0, 0, 0}));
  ASSERT_TRUE(answer.isOk());
  EXPECT_FALSE(answer->status.isOk());
  EXPECT_EQ(answer->tile, kUnreadTile);  // its id could not be read: it matches no tile sent
  EXPECT_FALSE(messageKind({}).isOk());
  EXPECT_FALSE(messageKind(std::vector<uint8_t>{9}).isOk());
}

}  // namespace
}  // namespace scanpress
