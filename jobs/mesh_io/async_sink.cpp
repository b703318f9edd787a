// A MeshSink on its own thread: see jobs/mesh_io/async_sink.h.
#include "jobs/mesh_io/async_sink.h"

#include "jobs/errors.h"

namespace scanpress {

AsyncSink::AsyncSink(MeshSink& sink, size_t depth) : sink_(sink), depth_(std::max<size_t>(1, depth)) {
  thread_ = std::thread([this] { run(); });
}

AsyncSink::~AsyncSink() { (void)finish(); }

Status AsyncSink::push(Call call) {
  std::unique_lock lock(mutex_);
  changed_.wait(lock, [&] { return queue_.size() < depth_ || !status_.isOk(); });
  if (!status_.isOk()) return status_;
  queue_.push_back(std::move(call));
  changed_.notify_all();
  return Status::ok();
}

// A call whose buffers come from a delivered one (no allocation once the queue is full).
#define SP_ASYNC_CALL(call)            \
  Call call;                           \
  {                                    \
    std::lock_guard lock(mutex_);      \
    if (!spare_.empty()) {             \
      call = std::move(spare_.back()); \
      spare_.pop_back();               \
    }                                  \
  }

Status AsyncSink::vertices(std::span<const Vec3d> positions, std::span<const Vec3f> normals,
                           std::span<const Rgba8> colors, uint8_t color_channels, const ScalarChunk& scalars) {
  SP_ASYNC_CALL(call);
  call.kind = Kind::kVertices;
  call.positions.assign(positions.begin(), positions.end());
  call.normals.assign(normals.begin(), normals.end());
  call.colors.assign(colors.begin(), colors.end());
  call.channels = color_channels;
  call.scalar_channels.assign(scalars.channels.begin(), scalars.channels.end());
  call.scalars.assign(scalars.values.begin(), scalars.values.end());
  return push(std::move(call));
}

Status AsyncSink::triangles(std::span<const Triangle> triangles) {
  SP_ASYNC_CALL(call);
  call.kind = Kind::kTriangles;
  call.triangles.assign(triangles.begin(), triangles.end());
  return push(std::move(call));
}

Status AsyncSink::vertexNormals(uint64_t first, std::span<const Vec3f> normals) {
  SP_ASYNC_CALL(call);
  call.kind = Kind::kVertexNormals;
  call.first = first;
  call.normals.assign(normals.begin(), normals.end());
  return push(std::move(call));
}

#undef SP_ASYNC_CALL

void AsyncSink::run() {
  while (true) {
    Call call;
    {
      std::unique_lock lock(mutex_);
      changed_.wait(lock, [&] { return !queue_.empty() || closing_; });
      if (queue_.empty()) return;  // closing, and everything delivered
      call = std::move(queue_.front());
      queue_.pop_front();
    }
    Status s;
    try {
      switch (call.kind) {
        case Kind::kVertices:
          s = sink_.vertices(call.positions, call.normals, call.colors, call.channels,
                             ScalarChunk{call.scalar_channels, call.scalars});
          break;
        case Kind::kTriangles: s = sink_.triangles(call.triangles); break;
        case Kind::kVertexNormals: s = sink_.vertexNormals(call.first, call.normals); break;
      }
    } catch (...) {
      s = statusFromException();
    }
    std::lock_guard lock(mutex_);
    if (!s.isOk()) {  // the reader's next call returns it; nothing more is delivered
      status_ = std::move(s);
      queue_.clear();
      closing_ = true;
    } else if (spare_.size() < depth_) {
      spare_.push_back(std::move(call));
    }
    changed_.notify_all();
    if (!status_.isOk()) return;
  }
}

Status AsyncSink::finish() {
  {
    std::lock_guard lock(mutex_);
    if (finished_) return status_;
    finished_ = true;
    closing_ = true;
    changed_.notify_all();
  }
  thread_.join();
  return status_;
}

}  // namespace scanpress
