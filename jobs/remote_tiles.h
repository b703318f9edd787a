// Tiles encoded in other processes (issue 23: one huge scan over many nodes; the MPI build in mpi/).
//
// Rank 0 reads, quantizes and tiles the scan as a local encode does, builds each tile, and sends it to a worker
// process; the worker runs the tile's work (jobs/tile_work.h) on its own threads and sends the result back; rank 0
// writes the results in tile order. A tile's result depends only on the tile and the settings, so the container
// is byte-identical to a local encode's at any number of workers.
//
// This file is the protocol, independent of MPI: the messages and their bytes, the transport rank 0 talks
// through (TileTransport), and the worker's side (TileServer). Messages are bytes in the order below; both sides
// run the same build (kWireVersion and the layout checks in the scan message catch a mix-up, and the worker
// refuses what it cannot read):
//
//   rank 0 -> worker   kScan    wire version, settings (codec, stages, codec options, measurement, knob), scan
//                               facts (grid, layout, measured, diagonal, density), threads per worker
//                      kTile    a built tile: id, quantized mesh, local-to-global ids, border flags, originals
//                      kQuit    the worker ends
//   worker -> rank 0   kReady   reply to kScan: how many tiles the worker takes at once, or why it cannot
//                      kResult  a TileResult: status, payload, decoded summary and levels, counts, error sums
//
// Within a scan, every kTile is answered by exactly one kResult; a worker may answer out of order.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "jobs/pipeline.h"
#include "jobs/tile_work.h"

namespace scanpress {

enum class TileMessage : uint8_t { kScan = 1, kTile = 2, kQuit = 3, kReady = 4, kResult = 5 };

// The tile id of a result whose tile message could not be read up to its id (no tile has it).
inline constexpr uint32_t kUnreadTile = UINT32_MAX;

// Rank 0's side of the wire. Implementations: MpiTransport (mpi/), and an in-process one in the tests.
class TileTransport {
 public:
  virtual ~TileTransport() = default;
  virtual uint32_t workers() const = 0;
  // Sends a message to worker w (0-based).
  virtual Status send(uint32_t worker, std::vector<uint8_t> message) = 0;
  // The next message from any worker (blocking), with the worker it came from.
  struct Received {
    uint32_t worker = 0;
    std::vector<uint8_t> message;
  };
  virtual Result<Received> receive() = 0;
};

// The transport every encode of this process sends its tiles through; nullptr (the default): tiles are encoded
// locally. Set once, before any encode, by a program that has workers (the MPI main); not thread-safe.
void setTileTransport(TileTransport* transport);
TileTransport* tileTransport();

// The messages' bytes.
std::vector<uint8_t> scanMessage(const EncodeSettings& settings, const TileScanFacts& scan);
std::vector<uint8_t> tileMessage(const TileMesh& tm, const std::vector<Vec3d>& originals);
std::vector<uint8_t> quitMessage();
std::vector<uint8_t> readyMessage(uint32_t slots, const Status& status);
std::vector<uint8_t> resultMessage(const TileResult& result);

// The kind of a message (kMalformed when empty or unknown).
Result<TileMessage> messageKind(std::span<const uint8_t> message);
// Rank 0 reads a worker's replies.
struct Ready {
  uint32_t slots = 0;
  Status status;  // why the worker cannot run this scan's tiles
};
Result<Ready> readReady(std::span<const uint8_t> message);
Result<TileResult> readResult(std::span<const uint8_t> message);

// A worker's side: what it makes of rank 0's messages. scan() replaces the scan (call it once no tile of the
// previous scan runs); tile() may run for many tiles at once.
class TileServer {
 public:
  TileServer() = default;
  TileServer(const TileServer&) = delete;  // the encoder refers to settings_
  TileServer& operator=(const TileServer&) = delete;

  // A kScan message: the settings and facts of the tiles that follow. The worker replies with readyMessage(the
  // tiles it takes at once, this status).
  Status scan(std::span<const uint8_t> message);
  // A kTile message: runs the tile; returns the kResult reply (a failure, even one to read the message, is in the
  // result's status).
  std::vector<uint8_t> tile(std::span<const uint8_t> message) const;
  // The threads per worker the last scan asked for (0: the worker's choice).
  int requestedThreads() const { return settings_.threads; }

 private:
  EncodeSettings settings_;
  TileScanFacts facts_;
  std::unique_ptr<TileEncoder> encoder_;
  Status scan_status_ = makeError(ErrorCode::kInternal, "a tile arrived before its scan");
};

// Rank 0's loop over the tiles of one scan: tiles `first, first + step, ...` below `count`. `build` builds a tile
// into its kTile message and returns the tile's counts and border (TileResult::input_*, border), or a failed status
// when the build failed; the messages go to the workers (each holding at most the tiles it announced), and the
// results to `write` in tile order, with the counts rank 0 built (a tile the worker could not read still reports
// what it lost). Returns once every tile sent has been answered, also after an error (a transport failure
// returns at once).
using BuildTileMessage = std::function<TileResult(uint32_t tile, std::vector<uint8_t>& message)>;
Status runRemoteTiles(TileTransport& transport, const EncodeSettings& settings, const TileScanFacts& scan,
                      uint32_t first, uint32_t step, uint32_t count, const BuildTileMessage& build,
                      const std::function<void(const TileResult&)>& write);

}  // namespace scanpress
