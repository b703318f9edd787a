#include "jobs/synth.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <set>
#include <unordered_map>

#include "engine/mesh.h"
#include "engine/shapes.h"
#include "jobs/file_io.h"
#include "jobs/mesh_io/mesh_reader.h"

namespace scanpress {
namespace {

Vec3d add(const Vec3d& a, const Vec3d& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
Vec3d sub(const Vec3d& a, const Vec3d& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3d mul(const Vec3d& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
Vec3d cross(const Vec3d& a, const Vec3d& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double norm(const Vec3d& a) { return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]); }
Vec3d normalized(const Vec3d& a) {
  const double l = norm(a);
  return l > 0 ? mul(a, 1.0 / l) : Vec3d{0, 0, 1};
}

// Value noise on an integer lattice, smoothstep-interpolated; deterministic for a seed.
class Noise {
 public:
  explicit Noise(uint64_t seed) : seed_(seed * 0x9E3779B97F4A7C15ull + 0x632BE59BD9B4E019ull) {}
  double value(const Vec3d& p) const {
    const double fx = std::floor(p[0]), fy = std::floor(p[1]), fz = std::floor(p[2]);
    const int64_t x = static_cast<int64_t>(fx), y = static_cast<int64_t>(fy), z = static_cast<int64_t>(fz);
    const double tx = smooth(p[0] - fx), ty = smooth(p[1] - fy), tz = smooth(p[2] - fz);
    double c[2][2][2];
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j)
        for (int k = 0; k < 2; ++k) c[i][j][k] = lattice(x + i, y + j, z + k);
    auto lerp = [](double a, double b, double t) { return a + (b - a) * t; };
    return lerp(lerp(lerp(c[0][0][0], c[1][0][0], tx), lerp(c[0][1][0], c[1][1][0], tx), ty),
                lerp(lerp(c[0][0][1], c[1][0][1], tx), lerp(c[0][1][1], c[1][1][1], tx), ty), tz);
  }

 private:
  static double smooth(double t) { return t * t * (3 - 2 * t); }
  double lattice(int64_t x, int64_t y, int64_t z) const {
    uint64_t h = seed_ ^ (uint64_t(x) * 0xC2B2AE3D27D4EB4Full) ^ (uint64_t(y) * 0x165667B19E3779F9ull) ^
                 (uint64_t(z) * 0x27D4EB2F165667C5ull);
    h ^= h >> 33;
    h *= 0xFF51AFD7ED558CCDull;
    h ^= h >> 33;
    h *= 0xC4CEB9FE1A85EC53ull;
    h ^= h >> 33;
    return double(h >> 11) / double(1ull << 53) * 2.0 - 1.0;  // [-1, 1)
  }
  uint64_t seed_;
};

// The built-in base: an icosphere with coarse bumps, so the blob is not a sphere (radius 1 +- 0.25).
Mesh bumpyIcosphere(int levels, uint64_t seed) {
  Mesh m = icosphere(levels);
  Noise noise(seed ^ 0xB10Bull);
  for (auto& p : m.positions) p = mul(p, 1.0 + 0.25 * noise.value(mul(p, 1.7)) + 0.08 * noise.value(mul(p, 4.1)));
  return m;
}

class Writer {
 public:
  explicit Writer(AtomicFile& f) : f_(f) { buf_.reserve(1u << 20); }
  template <typename T>
  Status put(T v) {
    uint8_t b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    buf_.insert(buf_.end(), b, b + sizeof(T));
    if (buf_.size() >= (1u << 20) - 64) return flush();
    return Status::ok();
  }
  Status flush() {
    Status s = f_.append(buf_);
    buf_.clear();
    return s;
  }

 private:
  AtomicFile& f_;
  std::vector<uint8_t> buf_;
};

}  // namespace

Result<SynthResult> synthesize(const SynthSettings& s) {
  if (s.triangles == 0 || s.triangles > (uint64_t(1) << 31) - 1)
    return makeError(ErrorCode::kInvalidArgument, "--triangles must be in [1, 2^31-1]");
  SP_RETURN_IF_ERROR(checkOutputPath(s.output, s.from.empty() ? std::vector<std::string>{} : std::vector{s.from}));
  Mesh base;
  if (s.from.empty()) {
    base = bumpyIcosphere(4, s.seed);
  } else {
    SP_ASSIGN_OR_RETURN(base, readMeshFile(s.from, nullptr, ReadOptions::asInFile()));
  }
  // Base triangles with three distinct, finite corners.
  std::vector<Triangle> faces;
  for (const auto& f : base.triangles)
    if (f[0] != f[1] && f[1] != f[2] && f[0] != f[2] &&
        norm(cross(sub(base.positions[f[1]], base.positions[f[0]]), sub(base.positions[f[2]], base.positions[f[0]]))) >
            0)
      faces.push_back(f);
  if (faces.empty()) return makeError(ErrorCode::kMalformed, s.from + ": no usable triangle to build from");
  const uint64_t F = faces.size();
  const size_t V = base.positions.size();

  // Area-weighted vertex normals and the mean edge length.
  std::vector<Vec3d> normals(V, Vec3d{0, 0, 0});
  double edge_sum = 0;
  for (const auto& f : faces) {
    const Vec3d n =
        cross(sub(base.positions[f[1]], base.positions[f[0]]), sub(base.positions[f[2]], base.positions[f[0]]));
    for (uint32_t v : f) normals[v] = add(normals[v], n);
    for (int k = 0; k < 3; ++k) edge_sum += norm(sub(base.positions[f[(k + 1) % 3]], base.positions[f[k]]));
  }
  for (auto& n : normals) n = normalized(n);
  const double mean_edge = edge_sum / (3.0 * F);

  uint32_t m = 1;
  while (F * uint64_t(m) * m < s.triangles) ++m;
  const uint64_t per_face = uint64_t(m) * m;
  const uint64_t full = s.triangles / per_face, rest = s.triangles % per_face;

  // Edges: canonical (lo, hi) -> id.
  std::unordered_map<uint64_t, uint32_t> edge_id;
  std::vector<std::pair<uint32_t, uint32_t>> edges;
  auto edgeOf = [&](uint32_t a, uint32_t b) {
    const uint64_t key = (uint64_t(std::min(a, b)) << 32) | std::max(a, b);
    auto [it, inserted] = edge_id.try_emplace(key, static_cast<uint32_t>(edges.size()));
    if (inserted) edges.emplace_back(std::min(a, b), std::max(a, b));
    return it->second;
  };
  const uint64_t used_faces = full + (rest ? 1 : 0);
  for (uint64_t f = 0; f < used_faces; ++f)
    for (int k = 0; k < 3; ++k) edgeOf(faces[f][k], faces[f][(k + 1) % 3]);

  // A point of face f at lattice (i, j) (P = a + i/m (b - a) + j/m (c - a)) is a corner, an edge point (edge,
  // s in 1..m-1 from the edge's lower vertex) or an interior point.
  struct Point {
    int kind;  // 0 corner, 1 edge, 2 interior
    uint32_t id;
    uint32_t s;
  };
  auto classify = [&](uint64_t f, uint32_t i, uint32_t j) -> Point {
    const Triangle& t = faces[f];
    if (i == 0 && j == 0) return {0, t[0], 0};
    if (i == m && j == 0) return {0, t[1], 0};
    if (i == 0 && j == m) return {0, t[2], 0};
    auto along = [&](uint32_t from, uint32_t to, uint32_t steps) -> Point {
      const uint32_t e = edgeOf(from, to);
      return {1, e, from < to ? steps : m - steps};
    };
    if (j == 0) return along(t[0], t[1], i);
    if (i == 0) return along(t[0], t[2], j);
    if (i + j == m) return along(t[1], t[2], j);
    return {2, 0, 0};
  };
  // The first `count` sub-triangles of a face in row order: up (i,j)(i+1,j)(i,j+1), then down
  // (i+1,j)(i+1,j+1)(i,j+1). Full faces are emitted in the same order.
  using Lattice = std::array<std::pair<uint32_t, uint32_t>, 3>;
  auto subTriangles = [&](uint64_t count) {
    std::vector<Lattice> out;
    for (uint32_t j = 0; j < m && out.size() < count; ++j)
      for (uint32_t i = 0; i + j < m && out.size() < count; ++i) {
        out.push_back({{{i, j}, {i + 1, j}, {i, j + 1}}});
        if (i + j + 1 < m && out.size() < count) out.push_back({{{i + 1, j}, {i + 1, j + 1}, {i, j + 1}}});
      }
    return out;
  };

  // Which points are used: all of the full faces, and those of the partial face's first `rest` triangles.
  std::vector<uint8_t> vertex_used(V, 0), edge_full(edges.size(), 0);
  for (uint64_t f = 0; f < full; ++f)
    for (int k = 0; k < 3; ++k) {
      vertex_used[faces[f][k]] = 1;
      edge_full[edgeOf(faces[f][k], faces[f][(k + 1) % 3])] = 1;
    }
  std::map<uint32_t, std::set<uint32_t>> edge_partial;       // edge -> used s, for edges of no full face
  std::set<std::pair<uint32_t, uint32_t>> interior_partial;  // (i, j) of the partial face
  const std::vector<Lattice> partial_tris = subTriangles(rest);
  for (const Lattice& tri : partial_tris) {
    for (auto [i, j] : tri) {
      const Point p = classify(full, i, j);
      if (p.kind == 0) vertex_used[p.id] = 1;
      else if (p.kind == 1 && !edge_full[p.id]) edge_partial[p.id].insert(p.s);
      else if (p.kind == 2) interior_partial.insert({i, j});
    }
  }
  // Numbering: used base vertices, then edge points by edge, then interior points by face.
  std::vector<uint32_t> vertex_index(V, UINT32_MAX);
  uint64_t next = 0;
  for (size_t v = 0; v < V; ++v)
    if (vertex_used[v]) vertex_index[v] = static_cast<uint32_t>(next++);
  std::vector<uint64_t> edge_base(edges.size(), 0);
  std::map<std::pair<uint32_t, uint32_t>, uint32_t> partial_edge_index;
  for (uint32_t e = 0; e < edges.size(); ++e) {
    edge_base[e] = next;
    if (edge_full[e]) next += m - 1;
    else if (auto it = edge_partial.find(e); it != edge_partial.end())
      for (uint32_t sp : it->second) partial_edge_index[{e, sp}] = static_cast<uint32_t>(next++);
  }
  const uint64_t interior_per_face = m >= 3 ? uint64_t(m - 1) * (m - 2) / 2 : 0;
  const uint64_t interior_base = next;
  next += full * interior_per_face;
  std::map<std::pair<uint32_t, uint32_t>, uint32_t> partial_interior_index;
  for (const auto& ij : interior_partial) partial_interior_index[ij] = static_cast<uint32_t>(next++);
  const uint64_t total_vertices = next;
  if (total_vertices > 0xFFFFFFFEull) return makeError(ErrorCode::kLimitExceeded, "too many vertices");

  // Interior lattice points of one face, in the order they are numbered.
  auto interiorOffset = [&](uint32_t i, uint32_t j) {  // rows j = 1..m-2, i = 1..m-1-j
    const uint64_t before = uint64_t(j - 1) * (m - 2) - uint64_t(j - 1) * (j - 2) / 2;
    return before + (i - 1);
  };
  auto indexOf = [&](uint64_t f, uint32_t i, uint32_t j) -> uint32_t {
    const Point p = classify(f, i, j);
    if (p.kind == 0) return vertex_index[p.id];
    if (p.kind == 1)
      return edge_full[p.id] ? static_cast<uint32_t>(edge_base[p.id] + p.s - 1) : partial_edge_index.at({p.id, p.s});
    if (f < full) return static_cast<uint32_t>(interior_base + f * interior_per_face + interiorOffset(i, j));
    return partial_interior_index.at({i, j});
  };

  // Displacement: octaves from 4 base edges down to 2 sub-edges; amplitude 3% of the wavelength.
  const Noise noise(s.seed);
  const double finest = 2.0 * mean_edge / m, coarsest = 4.0 * mean_edge;
  auto displaced = [&](const Vec3d& p, const Vec3d& n) {
    double d = 0;
    int octave = 0;
    for (double w = coarsest; w >= finest * 0.999 && octave < 16; w *= 0.5, ++octave)
      d += 0.03 * w * noise.value(add(mul(p, 1.0 / w), Vec3d{17.0 * octave, 31.0 * octave, 7.0 * octave}));
    return add(p, mul(n, d));
  };
  auto lerpPoint = [&](uint32_t a, uint32_t b, double t, Vec3d& p, Vec3d& n) {
    p = add(base.positions[a], mul(sub(base.positions[b], base.positions[a]), t));
    n = normalized(add(normals[a], mul(sub(normals[b], normals[a]), t)));
  };

  SP_ASSIGN_OR_RETURN(auto file, AtomicFile::create(s.output));
  std::string header = "ply\nformat binary_little_endian 1.0\ncomment scanpress synth: " + std::to_string(s.triangles) +
                       " triangles, seed " + std::to_string(s.seed) + ", m " + std::to_string(m) + "\n";
  header += "element vertex " + std::to_string(total_vertices) +
            "\nproperty float x\nproperty float y\nproperty float z\n";
  header += "element face " + std::to_string(s.triangles) + "\nproperty list uchar int vertex_indices\nend_header\n";
  SP_RETURN_IF_ERROR(file->append(header));
  Writer w(*file);
  auto emit = [&](const Vec3d& p) -> Status {
    for (double c : p) SP_RETURN_IF_ERROR(w.put(static_cast<float>(c)));
    return Status::ok();
  };
  for (size_t v = 0; v < V; ++v)
    if (vertex_used[v]) SP_RETURN_IF_ERROR(emit(displaced(base.positions[v], normals[v])));
  for (uint32_t e = 0; e < edges.size(); ++e) {
    // Not a structured binding: clang 14 (the fuzz build) cannot capture one in a lambda.
    const auto a = edges[e].first, b = edges[e].second;
    auto point = [&](uint32_t sp) -> Status {
      Vec3d p, n;
      lerpPoint(a, b, double(sp) / m, p, n);
      return emit(displaced(p, n));
    };
    if (edge_full[e]) {
      for (uint32_t sp = 1; sp < m; ++sp) SP_RETURN_IF_ERROR(point(sp));
    } else if (auto it = edge_partial.find(e); it != edge_partial.end()) {
      for (uint32_t sp : it->second) SP_RETURN_IF_ERROR(point(sp));
    }
  }
  auto interiorPoint = [&](uint64_t f, uint32_t i, uint32_t j) -> Status {
    const Triangle& t = faces[f];
    const double u = double(i) / m, v = double(j) / m, wgt = 1.0 - u - v;
    const Vec3d p =
        add(add(mul(base.positions[t[0]], wgt), mul(base.positions[t[1]], u)), mul(base.positions[t[2]], v));
    const Vec3d n = normalized(add(add(mul(normals[t[0]], wgt), mul(normals[t[1]], u)), mul(normals[t[2]], v)));
    return emit(displaced(p, n));
  };
  for (uint64_t f = 0; f < full; ++f)
    for (uint32_t j = 1; j + 2 <= m; ++j)
      for (uint32_t i = 1; i + j < m; ++i) SP_RETURN_IF_ERROR(interiorPoint(f, i, j));
  for (const auto& [i, j] : interior_partial) SP_RETURN_IF_ERROR(interiorPoint(full, i, j));

  auto face = [&](uint64_t f, const Lattice& c) -> Status {
    SP_RETURN_IF_ERROR(w.put<uint8_t>(3));
    for (auto [i, j] : c) SP_RETURN_IF_ERROR(w.put<int32_t>(static_cast<int32_t>(indexOf(f, i, j))));
    return Status::ok();
  };
  for (uint64_t f = 0; f < full; ++f)
    for (uint32_t j = 0; j < m; ++j)
      for (uint32_t i = 0; i + j < m; ++i) {
        SP_RETURN_IF_ERROR(face(f, {{{i, j}, {i + 1, j}, {i, j + 1}}}));
        if (i + j + 1 < m) SP_RETURN_IF_ERROR(face(f, {{{i + 1, j}, {i + 1, j + 1}, {i, j + 1}}}));
      }
  for (const auto& c : partial_tris) SP_RETURN_IF_ERROR(face(full, c));
  SP_RETURN_IF_ERROR(w.flush());
  SP_RETURN_IF_ERROR(file->commit());
  return SynthResult{total_vertices, s.triangles, m, F};
}

}  // namespace scanpress
