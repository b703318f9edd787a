#include "jobs/mesh_io/mesh_reader.h"

#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string_view>

#include "jobs/mesh_io/input.h"
#include "jobs/mesh_io/texcoords.h"

namespace scanpress {

Status ChunkBuffer::flushVertices() {
  if (pos_.empty()) return Status::ok();
  Status s = sink_.vertices(pos_, nrm_, col_, channels_, ScalarChunk{scalar_channels_, sca_});
  pos_.clear();
  nrm_.clear();
  col_.clear();
  sca_.clear();
  return s;
}

Status ChunkBuffer::flushTriangles() {
  SP_RETURN_IF_ERROR(flushVertices());
  if (tri_.empty()) return Status::ok();
  Status s = sink_.triangles(tri_);
  tri_.clear();
  return s;
}

std::string describeDropped(std::span<const DroppedProperty> dropped) {
  std::string s;
  for (const auto& d : dropped) s += (s.empty() ? "" : ", ") + d.name + " x " + std::to_string(d.count);
  return s;
}

MeshFormat formatFromName(const std::string& path) {
  std::string name = path;
  for (auto& ch : name) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  if (name.size() > 4 && name.ends_with(".zst")) name.resize(name.size() - 4);
  if (name.ends_with(".ply")) return MeshFormat::kPly;
  if (name.ends_with(".obj")) return MeshFormat::kObj;
  if (name.ends_with(".stl")) return MeshFormat::kStl;
  if (name.ends_with(".off")) return MeshFormat::kOff;
  return MeshFormat::kUnknown;
}

bool cheapToReadAgain(const std::string& path) {
  if (formatFromName(path) != MeshFormat::kPly) return false;
  std::string lower = path;
  for (auto& ch : lower) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  if (lower.ends_with(".zst")) return false;
  // A FIFO or a device cannot be read twice (and peeking would take its header from the reader).
  struct stat st;
  if (::stat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return false;
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return false;
  char head[1024];
  const size_t n = std::fread(head, 1, sizeof head, f);
  std::fclose(f);
  const std::string_view h(head, n);
  const size_t end = h.find("end_header");
  return h.starts_with("ply") && end != std::string_view::npos && h.substr(0, end).find("\nformat binary_") != h.npos;
}

namespace {

MeshFormat sniffFormat(std::span<const uint8_t> head) {
  std::string_view s(reinterpret_cast<const char*>(head.data()), head.size());
  if (s.starts_with("ply")) return MeshFormat::kPly;
  if (s.starts_with("OFF") || s.starts_with("COFF") || s.starts_with("NOFF") || s.starts_with("CNOFF"))
    return MeshFormat::kOff;
  if (s.starts_with("solid")) return MeshFormat::kStl;
  size_t i = 0;
  while (i < s.size()) {  // OBJ: first meaningful line starts with a known record
    while (i < s.size() && std::isspace(static_cast<unsigned char>(s[i]))) ++i;
    if (i < s.size() && s[i] == '#') {
      while (i < s.size() && s[i] != '\n') ++i;
      continue;
    }
    auto rest = s.substr(i);
    if (rest.starts_with("v ") || rest.starts_with("vn ") || rest.starts_with("vt ") || rest.starts_with("f ") ||
        rest.starts_with("o ") || rest.starts_with("g ") || rest.starts_with("mtllib"))
      return MeshFormat::kObj;
    break;
  }
  if (head.size() >= 84) return MeshFormat::kStl;  // binary STL has no magic
  return MeshFormat::kUnknown;
}

}  // namespace

Status MeshCollector::vertices(std::span<const Vec3d> p, std::span<const Vec3f> n, std::span<const Rgba8> c,
                               uint8_t channels, const ScalarChunk& scalars) {
  const size_t before = mesh_.positions.size();
  if (!scalars.channels.empty()) {
    if (before == 0) mesh_.scalar_channels.assign(scalars.channels.begin(), scalars.channels.end());
    if (!std::equal(scalars.channels.begin(), scalars.channels.end(), mesh_.scalar_channels.begin(),
                    mesh_.scalar_channels.end()))
      return makeError(ErrorCode::kInternal, "scalar channels changed during a read");
    mesh_.scalars.insert(mesh_.scalars.end(), scalars.values.begin(), scalars.values.end());
  } else if (!mesh_.scalar_channels.empty()) {
    return makeError(ErrorCode::kInternal, "scalar channels changed during a read");
  }
  mesh_.positions.insert(mesh_.positions.end(), p.begin(), p.end());
  if (!n.empty()) {
    mesh_.normals.resize(before, Vec3f{0, 0, 0});
    mesh_.normals.insert(mesh_.normals.end(), n.begin(), n.end());
  }
  if (!c.empty()) {
    mesh_.colors.resize(before, Rgba8{255, 255, 255, 255});
    mesh_.colors.insert(mesh_.colors.end(), c.begin(), c.end());
    mesh_.color_channels = std::max(mesh_.color_channels, channels);
  }
  return Status::ok();
}

Status MeshCollector::triangles(std::span<const Triangle> t) {
  mesh_.triangles.insert(mesh_.triangles.end(), t.begin(), t.end());
  return Status::ok();
}

Status MeshCollector::vertexNormals(uint64_t first, std::span<const Vec3f> n) {
  if (first + n.size() > mesh_.positions.size())
    return makeError(ErrorCode::kInternal, "vertex normals past the vertex count");
  mesh_.normals.resize(mesh_.positions.size(), Vec3f{0, 0, 0});
  for (size_t i = 0; i < n.size(); ++i)
    if (!std::isnan(n[i][0])) mesh_.normals[first + i] = n[i];
  return Status::ok();
}

void MeshCollector::finish() {
  if (!mesh_.normals.empty()) mesh_.normals.resize(mesh_.positions.size(), Vec3f{0, 0, 0});
  if (!mesh_.colors.empty()) mesh_.colors.resize(mesh_.positions.size(), Rgba8{255, 255, 255, 255});
}

namespace {
// A file that can be read twice (a FIFO or a device cannot: its wedges are not split, what they hold is listed).
bool regularFile(const std::string& path) {
  struct stat st;
  return ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}
}  // namespace

Result<ReadStats> readMesh(const std::string& path, MeshSink& sink, const ReadOptions& options) {
  SP_ASSIGN_OR_RETURN(auto source, InputSource::open(path));
  Scanner in(std::move(source), path);
  MeshFormat format = formatFromName(path);
  if (format == MeshFormat::kUnknown) {
    SP_ASSIGN_OR_RETURN(auto head, in.peek(512));
    format = sniffFormat(head);
  }
  switch (format) {
    case MeshFormat::kPly: {
      if (!options.texture_coordinates || !regularFile(path)) return readPly(in, sink, options);
      // Faces' texcoord lists: a first read (which stops after the header of a file without them) plans the wedges.
      SP_ASSIGN_OR_RETURN(auto first_source, InputSource::open(path));
      Scanner first(std::move(first_source), path);
      SP_ASSIGN_OR_RETURN(WedgePlan plan, planPlyWedges(first, options));
      return readPly(in, sink, options, &plan);
    }
    case MeshFormat::kObj: {
      if ((!options.texture_coordinates && !options.corner_normals) || !regularFile(path))
        return readObj(in, sink, options);
      // Texture coordinates and normals per corner: a first read learns what faces make of them (readObj's second
      // read delivers the wedges).
      SP_ASSIGN_OR_RETURN(auto first_source, InputSource::open(path));
      Scanner first(std::move(first_source), path);
      SP_ASSIGN_OR_RETURN(WedgePlan plan, planObjWedges(first, options));
      return readObj(in, sink, options, &plan);
    }
    case MeshFormat::kStl: return readStl(in, sink, options);
    case MeshFormat::kOff: return readOff(in, sink, options);
    case MeshFormat::kUnknown: break;
  }
  return makeError(ErrorCode::kUnsupported,
                   path + ": unknown mesh format (expected .ply, .obj, .stl or .off, optionally .zst-compressed)");
}

uint32_t WedgePlan::addUv(const std::array<float, 2>& uv) {
  const auto [it, fresh] = uv_ids.emplace(uvBits(uv), uint32_t(uvs.size()));
  if (fresh) uvs.push_back(uv);
  return it->second;
}

uint32_t WedgePlan::uvId(const std::array<float, 2>& uv) const {
  const auto it = uv_ids.find(uvBits(uv));
  return it == uv_ids.end() ? kNone - 1 : it->second;
}

uint32_t WedgePlan::keyOf(uint64_t pair) {
  const auto [it, fresh] = key_ids.emplace(pair, uint32_t(keys.size()));
  if (fresh) keys.push_back({uint32_t(pair >> 32), uint32_t(pair)});
  return it->second;
}

void WedgePlan::addCorner(uint32_t v, uint32_t t, uint32_t n) {
  if (!textures) t = kNone;
  if (!normals) n = kNone;
  if (t == kNone && n == kNone) return;  // the vertex's first wedge
  const uint32_t key = keyOf(uint64_t(t) << 32 | n);
  if (first[v] == kNone) first[v] = key;
  else if (key != first[v]) wedges.push_back({v, key});
  if (wedges.size() >= 2 * deduplicated_ + 4096) {  // a vertex's corners name the same pair again and again
    finish();
    deduplicated_ = wedges.size();
  }
}

void WedgePlan::finish() {
  std::sort(wedges.begin(), wedges.end());
  wedges.erase(std::unique(wedges.begin(), wedges.end()), wedges.end());
}

std::optional<uint32_t> WedgePlan::wedgeOf(uint32_t v, uint32_t t, uint32_t n) const {
  if (!textures) t = kNone;
  if (!normals) n = kNone;
  if (t == kNone && n == kNone) return 0;
  if (v >= first.size()) return std::nullopt;
  const auto id = key_ids.find(uint64_t(t) << 32 | n);
  if (id == key_ids.end()) return std::nullopt;
  const uint32_t key = id->second;
  if (key == first[v]) return 0;
  const auto begin = std::lower_bound(wedges.begin(), wedges.end(), std::pair<uint32_t, uint32_t>{v, 0});
  const auto it = std::lower_bound(begin, wedges.end(), std::pair<uint32_t, uint32_t>{v, key});
  if (it == wedges.end() || *it != std::pair<uint32_t, uint32_t>{v, key}) return std::nullopt;
  return uint32_t(1 + (it - begin));
}

std::vector<ScalarChannel> texcoordChannels(const WedgePlan* plan) {
  if (!plan || !plan->textures) return {};
  return {{kTexcoordU, ScalarType::kFloat32}, {kTexcoordV, ScalarType::kFloat32}};
}

Result<Mesh> readMeshFile(const std::string& path, ReadStats* stats, const ReadOptions& options) {
  Mesh mesh;
  MeshCollector sink(mesh);
  SP_ASSIGN_OR_RETURN(ReadStats s, readMesh(path, sink, options));
  sink.finish();
  if (stats) *stats = s;
  return mesh;
}

}  // namespace scanpress
