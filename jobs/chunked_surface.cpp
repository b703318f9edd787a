#include "jobs/chunked_surface.h"

#include <sys/stat.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <unordered_map>

#include "engine/geometry.h"
#include "jobs/commands.h"
#include "jobs/container_file.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/numbers.h"
#include "jobs/scan_store.h"

namespace scanpress {

class ChunkedSurface::Source {
 public:
  virtual ~Source() = default;
  virtual Result<std::shared_ptr<const Mesh>> load(size_t i) const = 0;
};

namespace {

// In memory: the whole mesh (no copy) or runs of its triangles.
class MeshSource : public ChunkedSurface::Source {
 public:
  MeshSource(const Mesh& mesh, uint64_t run) : mesh_(mesh), run_(run) {}
  Result<std::shared_ptr<const Mesh>> load(size_t i) const override {
    if (run_ == 0) return std::shared_ptr<const Mesh>(std::shared_ptr<const Mesh>(), &mesh_);  // not owned
    const uint64_t first = uint64_t(i) * run_, end = std::min<uint64_t>(first + run_, mesh_.triangles.size());
    auto out = std::make_shared<Mesh>();
    std::unordered_map<uint32_t, uint32_t> local;
    const bool colors = mesh_.colors.size() == mesh_.positions.size() && !mesh_.colors.empty();
    out->color_channels = colors ? mesh_.color_channels : 0;
    for (uint64_t t = first; t < end; ++t) {
      Triangle tri;
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = mesh_.triangles[t][k];
        auto [it, added] = local.try_emplace(v, uint32_t(out->positions.size()));
        if (added) {
          out->positions.push_back(mesh_.positions[v]);
          if (colors) out->colors.push_back(mesh_.colors[v]);
        }
        tri[k] = it->second;
      }
      out->triangles.push_back(tri);
    }
    return std::shared_ptr<const Mesh>(std::move(out));
  }

 private:
  const Mesh& mesh_;
  uint64_t run_;
};

// A mesh file's chunks in a scratch file: per chunk its vertex count, triangle count, positions (double),
// colors (when the file has colors) and local triangles.
class FileSource : public ChunkedSurface::Source {
 public:
  struct Chunk {
    uint64_t offset = 0;
    uint32_t vertices = 0, triangles = 0;
    bool colors = false;  // written with colors (a chunk read before the first colored vertex has none)
  };
  explicit FileSource(ScratchDir d) : dir(std::move(d)) {}
  ScratchDir dir;
  ScratchFile chunks_file;
  std::vector<Chunk> chunks;
  bool colors = false;
  uint8_t color_channels = 0;

  Result<std::shared_ptr<const Mesh>> load(size_t i) const override {
    const Chunk& c = chunks[i];
    auto m = std::make_shared<Mesh>();
    m->positions.resize(c.vertices);
    m->triangles.resize(c.triangles);
    uint64_t at = c.offset;
    SP_RETURN_IF_ERROR(chunks_file.readAt(at, m->positions.data(), c.vertices * sizeof(Vec3d)));
    at += c.vertices * sizeof(Vec3d);
    if (colors) {  // white where the file had none yet, as the in-memory reader pads them
      m->colors.assign(c.vertices, Rgba8{255, 255, 255, 255});
      m->color_channels = color_channels;
    }
    if (c.colors) {
      SP_RETURN_IF_ERROR(chunks_file.readAt(at, m->colors.data(), c.vertices * sizeof(Rgba8)));
      at += c.vertices * sizeof(Rgba8);
    }
    SP_RETURN_IF_ERROR(chunks_file.readAt(at, m->triangles.data(), c.triangles * sizeof(Triangle)));
    return std::shared_ptr<const Mesh>(std::move(m));
  }
};

// A container's tiles, one per chunk, dequantized (a tile without attributes of its own gets the gray colors the
// in-memory decode gives it).
class ContainerSource : public ChunkedSurface::Source {
 public:
  explicit ContainerSource(ContainerFile f) : file(std::move(f)) {
    for (const TileEntry& e : file.tiles()) tiles.push_back(&e);
  }
  ContainerFile file;
  std::vector<const TileEntry*> tiles;

  Result<std::shared_ptr<const Mesh>> load(size_t i) const override {
    bool own = true;
    SP_ASSIGN_OR_RETURN(QuantizedMesh q, file.decodeTile(*tiles[i], std::nullopt, nullptr, &own));
    const ContainerHeader& h = file.header();
    auto m = std::make_shared<Mesh>(dequantizeMesh(q, h.grid, h.layout));
    if (!own && h.layout.hasColors()) m->colors.assign(m->positions.size(), Rgba8{128, 128, 128, 255});
    return std::shared_ptr<const Mesh>(std::move(m));
  }
};

// The vertices of a mesh file while its triangles are read: in memory while they fit `cache_bytes`, else in a
// scratch file read back through a cache of blocks (least recently used goes first).
class VertexTable {
 public:
  struct Record {
    Vec3d p;
    Rgba8 c;
  };
  VertexTable(std::string path, uint64_t cache_bytes)
      : path_(std::move(path)),
        max_blocks_(std::max<uint64_t>(4, cache_bytes / (kBlock * sizeof(Record)))),
        memory_limit_(max_blocks_ * kBlock) {}

  Status append(const Record& r) {
    if (!spilled_ && memory_.size() >= memory_limit_) SP_RETURN_IF_ERROR(spill());
    if (!spilled_) {
      memory_.push_back(r);
    } else {
      pending_.push_back(r);
      if (pending_.size() == kBlock) SP_RETURN_IF_ERROR(flush());
    }
    return Status::ok();
  }
  Result<const Record*> get(uint64_t i) {
    if (!spilled_) return &memory_[i];
    if (i >= written_) SP_RETURN_IF_ERROR(flush());  // OBJ: a face may follow its vertices at once
    const uint64_t b = i / kBlock;
    if (b == last_block_) return &blocks_[last_slot_].records[i % kBlock];
    auto it = slot_of_.find(b);
    size_t slot;
    if (it != slot_of_.end()) {
      slot = it->second;
    } else {
      if (blocks_.size() < max_blocks_) {
        slot = blocks_.size();
        blocks_.emplace_back();
      } else {
        slot = 0;
        for (size_t s = 1; s < blocks_.size(); ++s)
          if (blocks_[s].used < blocks_[slot].used) slot = s;
        slot_of_.erase(blocks_[slot].block);
      }
      Block& bl = blocks_[slot];
      const uint64_t n = std::min<uint64_t>(kBlock, written_ - b * kBlock);
      bl.records.resize(n);
      SP_RETURN_IF_ERROR(file_.readAt(b * kBlock * sizeof(Record), bl.records.data(), n * sizeof(Record)));
      bl.block = b;
      slot_of_[b] = slot;
    }
    blocks_[slot].used = ++clock_;
    last_block_ = b, last_slot_ = slot;
    return &blocks_[slot].records[i % kBlock];
  }

 private:
  static constexpr uint64_t kBlock = 1 << 14;
  struct Block {
    uint64_t block = UINT64_MAX, used = 0;
    std::vector<Record> records;
  };
  Status spill() {
    SP_RETURN_IF_ERROR(file_.open(path_));
    SP_RETURN_IF_ERROR(file_.writeAt(0, memory_.data(), memory_.size() * sizeof(Record)));
    written_ = memory_.size();
    std::vector<Record>().swap(memory_);  // frees (`= {}` would keep the capacity)
    spilled_ = true;
    return Status::ok();
  }
  // Pending records to the file; a cached block they extend is read again.
  Status flush() {
    if (pending_.empty()) return Status::ok();
    SP_RETURN_IF_ERROR(file_.writeAt(written_ * sizeof(Record), pending_.data(), pending_.size() * sizeof(Record)));
    const uint64_t partial = written_ / kBlock;
    written_ += pending_.size();
    pending_.clear();
    if (auto it = slot_of_.find(partial); it != slot_of_.end()) {
      blocks_[it->second].block = UINT64_MAX;
      slot_of_.erase(it);
    }
    last_block_ = UINT64_MAX;
    return Status::ok();
  }

  std::string path_;
  uint64_t max_blocks_, memory_limit_;
  bool spilled_ = false;
  std::vector<Record> memory_, pending_;
  ScratchFile file_;
  uint64_t written_ = 0, clock_ = 0;
  std::vector<Block> blocks_;
  std::unordered_map<uint64_t, size_t> slot_of_;
  uint64_t last_block_ = UINT64_MAX;
  size_t last_slot_ = 0;
};

// Reads a mesh file into a FileSource: vertices into the table, runs of triangles into chunks.
class ChunkWriter : public MeshSink {
 public:
  ChunkWriter(FileSource& out, VertexTable& table, uint64_t run, std::function<void(const Mesh&)> survey)
      : out_(out), table_(table), run_(run), survey_(std::move(survey)) {}

  // Scalar channels are not drawn or measured.
  Status vertices(std::span<const Vec3d> p, std::span<const Vec3f>, std::span<const Rgba8> c, uint8_t channels,
                  const ScalarChunk&) override {
    if (!c.empty()) {
      out_.colors = true;
      out_.color_channels = std::max(out_.color_channels, channels);
    }
    for (size_t i = 0; i < p.size(); ++i) {
      SP_RETURN_IF_ERROR(table_.append({p[i], c.empty() ? Rgba8{255, 255, 255, 255} : c[i]}));
      box_.extend(p[i]);
    }
    return Status::ok();
  }
  Status triangles(std::span<const Triangle> tris) override {
    for (const Triangle& t : tris) {
      Triangle local;
      for (int k = 0; k < 3; ++k) {
        auto [it, added] = local_.try_emplace(t[k], uint32_t(chunk_.positions.size()));
        if (added) {
          SP_ASSIGN_OR_RETURN(const VertexTable::Record* r, table_.get(t[k]));
          chunk_.positions.push_back(r->p);
          chunk_.colors.push_back(r->c);
        }
        local[k] = it->second;
      }
      chunk_.triangles.push_back(local);
      if (chunk_.triangles.size() >= run_) SP_RETURN_IF_ERROR(finishChunk());
    }
    return Status::ok();
  }
  Status vertexNormals(uint64_t, std::span<const Vec3f>) override { return Status::ok(); }

  Status finishChunk() {
    if (chunk_.triangles.empty()) return Status::ok();
    if (!out_.colors) chunk_.colors.clear();
    FileSource::Chunk c{bytes_, uint32_t(chunk_.positions.size()), uint32_t(chunk_.triangles.size()), out_.colors};
    SP_RETURN_IF_ERROR(write(chunk_.positions.data(), chunk_.positions.size() * sizeof(Vec3d)));
    // Colors once the file has them (the table holds white for vertices read before the first colored one).
    if (c.colors) SP_RETURN_IF_ERROR(write(chunk_.colors.data(), chunk_.colors.size() * sizeof(Rgba8)));
    SP_RETURN_IF_ERROR(write(chunk_.triangles.data(), chunk_.triangles.size() * sizeof(Triangle)));
    out_.chunks.push_back(c);
    survey_(chunk_);
    chunk_ = Mesh();
    local_.clear();
    return Status::ok();
  }
  const BoundingBox& box() const { return box_; }

 private:
  Status write(const void* p, size_t n) {
    SP_RETURN_IF_ERROR(out_.chunks_file.writeAt(bytes_, p, n));
    bytes_ += n;
    return Status::ok();
  }
  FileSource& out_;
  VertexTable& table_;
  uint64_t run_;
  std::function<void(const Mesh&)> survey_;
  Mesh chunk_;
  std::unordered_map<uint32_t, uint32_t> local_;
  uint64_t bytes_ = 0;
  BoundingBox box_;
};

}  // namespace

ChunkedSurface::ChunkedSurface(ChunkedSurface&&) noexcept = default;
ChunkedSurface& ChunkedSurface::operator=(ChunkedSurface&&) noexcept = default;
ChunkedSurface::~ChunkedSurface() = default;

void ChunkedSurface::addChunk(const Mesh& m) {
  SurfaceChunkInfo info;
  info.triangles = m.triangles.size();
  info.vertices = m.positions.size();
  for (const Vec3d& p : m.positions) info.box.extend(p);
  for (size_t i = 0; i < m.triangles.size(); ++i) {
    const Triangle& t = m.triangles[i];
    area_ += triangleArea(m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]);
    if (i % kSurfacePartTriangles == 0) info.parts.emplace_back();
    for (uint32_t v : t) used_box_.extend(m.positions[v]), info.parts.back().extend(m.positions[v]);
  }
  triangles_ += m.triangles.size();
  info_.push_back(info);
}

ChunkedSurface ChunkedSurface::whole(const Mesh& mesh) {
  ChunkedSurface s;
  s.source_ = std::make_unique<MeshSource>(mesh, 0);
  s.addChunk(mesh);
  s.box_ = boundingBox(mesh);
  if (mesh.triangles.empty()) s.used_box_ = s.box_;
  return s;
}

ChunkedSurface ChunkedSurface::pieces(const Mesh& mesh, uint64_t run) {
  run = std::max<uint64_t>(run, 1);
  ChunkedSurface s;
  auto source = std::make_unique<MeshSource>(mesh, run);
  for (uint64_t first = 0; first < mesh.triangles.size(); first += run) {
    auto chunk = source->load(size_t(first / run));
    s.addChunk(**chunk);  // cannot fail in memory
  }
  s.source_ = std::move(source);
  s.box_ = boundingBox(mesh);
  if (mesh.triangles.empty()) s.used_box_ = s.box_;
  return s;
}

Result<ChunkedSurface> ChunkedSurface::fromMeshFile(const std::string& path, uint64_t run, uint64_t cache_bytes,
                                                    const std::string& scratch_parent) {
  ChunkedSurface s;
  SP_ASSIGN_OR_RETURN(ScratchDir dir, ScratchDir::create(scratch_parent));
  auto source = std::make_unique<FileSource>(std::move(dir));
  SP_RETURN_IF_ERROR(source->chunks_file.open(source->dir.file("chunks")));
  {
    VertexTable table(source->dir.file("vertices"), cache_bytes);
    ChunkWriter writer(*source, table, std::max<uint64_t>(run, 1), [&](const Mesh& m) { s.addChunk(m); });
    SP_RETURN_IF_ERROR(readMesh(path, writer, ReadOptions::asInFile()).status());
    SP_RETURN_IF_ERROR(writer.finishChunk());
    s.box_ = writer.box();
  }
  std::error_code ec;
  std::filesystem::remove(source->dir.file("vertices"), ec);  // read; only the chunks are needed from here
  if (s.triangles_ == 0) s.used_box_ = s.box_;
  s.source_ = std::move(source);
  return s;
}

Result<ChunkedSurface> ChunkedSurface::fromContainer(const std::string& path) {
  SP_ASSIGN_OR_RETURN(ContainerFile file, ContainerFile::open(path));
  ChunkedSurface s;
  auto source = std::make_unique<ContainerSource>(std::move(file));
  for (size_t i = 0; i < source->tiles.size(); ++i) {
    SP_ASSIGN_OR_RETURN(auto m, source->load(i));
    s.addChunk(*m);
    for (const Vec3d& p : m->positions) s.box_.extend(p);
  }
  if (s.triangles_ == 0) s.used_box_ = s.box_;
  s.source_ = std::move(source);
  return s;
}

Result<std::shared_ptr<const Mesh>> ChunkedSurface::load(size_t i) const { return source_->load(i); }

bool isContainerPath(const std::string& path) {
  const std::string ext = ".spz";
  return path.size() >= ext.size() && path.compare(path.size() - ext.size(), ext.size(), ext) == 0;
}

Result<Mesh> readSurfaceFile(const std::string& path) {
  if (!isContainerPath(path)) return readMeshFile(path, nullptr, ReadOptions::asInFile());
  ContainerHeader header;
  SP_ASSIGN_OR_RETURN(QuantizedMesh q, decodeContainer(path, std::nullopt, &header));
  return dequantizeMesh(q, header.grid, header.layout);
}

uint64_t inMemorySurfaceBytes(const std::string& path) {
  if (isContainerPath(path)) {
    auto file = ContainerFile::open(path);
    if (!file.isOk()) return 0;  // the reader reports what is wrong with it
    uint64_t faces = 0;
    for (const TileEntry& e : file->tiles()) faces += e.faces;
    return faces * kInMemoryBytesPerTriangle;
  }
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return 0;
  // About 19 bytes per triangle in a binary PLY (fewer compressed: zstd takes scans to about a fifth); text
  // formats are larger per triangle, which only errs on the side of the budget.
  const bool zst = path.size() > 4 && path.compare(path.size() - 4, 4, ".zst") == 0;
  const uint64_t triangles = uint64_t(st.st_size) * (zst ? 5 : 1) / 19;
  return triangles * kInMemoryBytesPerTriangle;
}

uint64_t searchIndexBytes(uint64_t triangles, uint64_t vertices) {
  // SurfaceIndex's own arrays (float vertices 12 B per vertex, spheres 16 B per triangle), Embree's BVH (about
  // 100 B per triangle) and the chunk's mesh (24 B per vertex, 12 per triangle), rounded up; the peaks this gives
  // are in bench/RESULTS.md, "Measure and render under a memory budget".
  constexpr uint64_t kPerTriangle = 140, kPerVertex = 40;
  return triangles * kPerTriangle + vertices * kPerVertex;
}

Result<ChunkedSurface> openSurface(const std::string& path, uint64_t memory_budget, const std::string& scratch_parent) {
  if (isContainerPath(path)) {
    if (memory_budget > 0) {
      SP_ASSIGN_OR_RETURN(ContainerFile file, ContainerFile::open(path));
      for (const TileEntry& e : file.tiles()) {
        const uint64_t need = searchIndexBytes(e.faces, e.vertices);
        if (need > surfaceCacheBytes(memory_budget))
          return makeError(ErrorCode::kLimitExceeded,
                           path + ": tile " + std::to_string(e.tile_id) + " (" + std::to_string(e.faces) +
                               " faces) needs about " + humanBytes(need) +
                               " to search, more than half the memory budget of " + humanBytes(memory_budget) +
                               ": give --memory-budget " + std::to_string((2 * need >> 20) + 1) + "M or more");
      }
    }
    return ChunkedSurface::fromContainer(path);
  }
  // Runs whose indexes take a sixteenth of the budget: the cache (half of it) holds eight, enough for the pieces
  // of surface around a point; the vertex cache takes an eighth while the file is read.
  const uint64_t share = memory_budget == 0 ? uint64_t(1) << 30 : memory_budget / 8;
  const uint64_t run = std::clamp<uint64_t>(share / 2 / 160, 4096, uint64_t(1) << 22);
  return ChunkedSurface::fromMeshFile(path, run, share, scratch_parent);
}

uint64_t surfaceCacheBytes(uint64_t memory_budget) { return memory_budget == 0 ? UINT64_MAX : memory_budget / 2; }

bool needsChunks(const std::vector<std::string>& paths, uint64_t memory_budget) {
  uint64_t need = 0;
  for (const std::string& p : paths) {
    if (isContainerPath(p)) return true;
    need += inMemorySurfaceBytes(p);
  }
  return memory_budget > 0 && need > memory_budget;
}

}  // namespace scanpress
