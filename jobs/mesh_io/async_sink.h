// A MeshSink that runs another sink on its own thread: the reader parses the next chunk while the sink works on
// this one (issue 23: the encode's read and quantization passes were serial, capping a 2-thread encode at 1.3x).
//
// Each call copies its chunk into a queue of at most `depth` chunks and returns; one thread delivers them to the
// wrapped sink in the order they came, so the sink sees exactly the calls it would have seen. An error of the
// wrapped sink is returned by the next call (the reader then stops) and by finish(). The wrapped sink must not be
// used by anyone else until finish() returns.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <thread>
#include <vector>

#include "jobs/mesh_io/mesh_reader.h"

namespace scanpress {

class AsyncSink : public MeshSink {
 public:
  explicit AsyncSink(MeshSink& sink, size_t depth = 4);
  ~AsyncSink() override;  // finishes if finish() was not called
  AsyncSink(const AsyncSink&) = delete;
  AsyncSink& operator=(const AsyncSink&) = delete;

  Status vertices(std::span<const Vec3d> positions, std::span<const Vec3f> normals, std::span<const Rgba8> colors,
                  uint8_t color_channels, const ScalarChunk& scalars) override;
  Status triangles(std::span<const Triangle> triangles) override;
  Status vertexNormals(uint64_t first, std::span<const Vec3f> normals) override;
  // Waits until the wrapped sink has seen every call; its first error, if any.
  Status finish();

 private:
  enum class Kind : uint8_t { kVertices, kTriangles, kVertexNormals };
  struct Call {
    Kind kind = Kind::kVertices;
    std::vector<Vec3d> positions;
    std::vector<Vec3f> normals;
    std::vector<Rgba8> colors;
    uint8_t channels = 0;
    std::vector<ScalarChannel> scalar_channels;
    ScalarValues scalars;
    std::vector<Triangle> triangles;
    uint64_t first = 0;
  };
  Status push(Call call);
  void run();

  MeshSink& sink_;
  size_t depth_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<Call> queue_;
  std::vector<Call> spare_;  // delivered calls, their buffers reused
  bool closing_ = false, finished_ = false;
  Status status_;  // the wrapped sink's first error
  std::thread thread_;
};

}  // namespace scanpress
