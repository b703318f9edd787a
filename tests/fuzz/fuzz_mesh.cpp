// Fuzz target: the mesh readers. The first input byte chooses the reader (0 PLY, 1 OBJ, 2 STL, 3 OFF, modulo
// 4) and the rest is the file, read from memory through the same Scanner the file readers use, into a
// MeshCollector. Chunks are small so that the readers' chunked delivery is exercised too.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <optional>
#include <vector>

#include "jobs/mesh_io/input.h"
#include "jobs/mesh_io/mesh_reader.h"

namespace {

// The input as an InputSource of known size (never compressed: the zstd layer is zstd's own code).
class MemorySource : public scanpress::InputSource {
 public:
  MemorySource(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  scanpress::Result<size_t> read(uint8_t* dst, size_t n) override {
    const size_t k = std::min(n, size_ - pos_);
    if (k) std::memcpy(dst, data_ + pos_, k);
    pos_ += k;
    return k;
  }
  std::optional<uint64_t> contentSize() const override { return size_; }
  bool compressed() const override { return false; }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace scanpress;
  if (size == 0) return 0;
  const int format = data[0] % 4;
  // Bit 2 of the first byte: PLY and OBJ read twice, a first read planning the wedges of texture coordinates and
  // normals per corner (as readMesh does), else once; bit 3: the options on (with one read: what a FIFO gets).
  const bool wedges = (data[0] & 4) != 0 && format < 2;
  const bool options_on = wedges || (data[0] & 8) != 0;
  Scanner in(std::make_unique<MemorySource>(data + 1, size - 1), "fuzz");
  Mesh mesh;
  MeshCollector sink(mesh);
  ReadOptions options;
  options.chunk = 7;
  options.texture_coordinates = options.corner_normals = options_on;
  std::optional<WedgePlan> plan;
  if (wedges) {
    Scanner first(std::make_unique<MemorySource>(data + 1, size - 1), "fuzz");
    auto planned = format == 0 ? planPlyWedges(first, options) : planObjWedges(first, options);
    if (!planned.isOk()) return 0;
    plan = std::move(*planned);
  }
  const WedgePlan* p = plan ? &*plan : nullptr;
  Result<ReadStats> r = format == 0   ? readPly(in, sink, options, p)
                        : format == 1 ? readObj(in, sink, options, p)
                        : format == 2 ? readStl(in, sink, options)
                                      : readOff(in, sink, options);
  if (r.isOk()) sink.finish();
  return 0;
}
