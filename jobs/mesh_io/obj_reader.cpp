// Wavefront OBJ reader: `v x y z [w | r g b [a]]`, `vn`, `vt u [v [w]]`, `f` with corners `a`, `a/b`, `a//c`,
// `a/b/c`, negative (relative) indices, polygons (fan-triangulated), `mtllib` and one `usemtl` (ReadStats'
// material names; a file naming several materials keeps none, listed). Every other record (g, o, s, l, p, ...) is
// skipped and listed in ReadStats::dropped as "obj KEYWORD" with its count ("s off" and "s 0" state nothing and
// are not listed). A vertex's normal is the `vn` its first face corner names; those arrive at the end
// (vertexNormals) because OBJ states them only in faces. Also listed: `vn` records no face names ("obj vn
// unused"), face corners naming another normal than their vertex's first one ("obj vn per corner"), `v` weights
// other than 1 ("obj v w") and `v` colors after a first `v` without them ("obj v colors").
//
// Texture coordinates and normals per corner (ReadOptions::texture_coordinates, corner_normals; texcoords.h): when
// faces name `vt` or `vn` records, the file is read twice. The first read (planObjWedges) learns, per `v`, the
// distinct (texture coordinate, normal) values its corners name (compared by value: records that repeat a value
// are one); the second delivers each vertex with the first of them (u and v as float32 scalar channels, the normal
// through vertexNormals), followed at once by one more vertex, a wedge at the same position, per further distinct
// value, and faces name the wedge of their corner. So a seam keeps both sides' coordinates and a crease both sides'
// normals, and vertices stay in file order with their wedges beside them. A corner that names neither takes its
// vertex's first; one that names only one of them is a wedge of its own, without the other (as the file has it;
// WedgePlan). A vertex no corner gives a `vt` gets (0, 0). Listed: `vt` records no face names ("obj vt unused"),
// third numbers other than 0 ("obj vt w"), records that are not finite numbers as float (read as 0 0) and corners
// without `vt`. Memory: 4 bytes per `v`, `vt` and `vn`, about 60 per distinct value and 8 per wedge (the first
// read), and 4 more per `v` in the second.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <set>
#include <string>
#include <unordered_map>
#include <vector>

#include "engine/container/container.h"
#include "jobs/mesh_io/input.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/texcoords.h"

namespace scanpress {
namespace {

// Resolves a 1-based (or negative, relative) OBJ index against `count` elements seen so far.
bool resolveIndex(int64_t raw, uint64_t count, uint32_t& out) {
  int64_t idx;
  if (raw > 0) idx = raw - 1;
  else if (raw < 0) idx = static_cast<int64_t>(count) + raw;
  else return false;
  if (idx < 0 || static_cast<uint64_t>(idx) >= count) return false;
  out = static_cast<uint32_t>(idx);
  return true;
}

// Counts of skipped records by keyword, in order of first appearance; distinct keywords and their length are
// capped so that a hostile file cannot grow the list without bound (the rest count as "other kinds").
class SkippedRecords {
 public:
  void add(std::string_view keyword) {
    for (auto& d : list_)
      if (d.name.size() == 4 + keyword.size() && d.name.compare(4, std::string::npos, keyword) == 0) {
        ++d.count;
        return;
      }
    if (list_.size() < kMaxKeywords && keyword.size() <= kMaxKeywordLength) {
      list_.push_back({"obj " + std::string(keyword), 1});
      return;
    }
    ++other_;
  }
  // The list for ReadStats::dropped, `extra` appended.
  std::vector<DroppedProperty> take(std::vector<DroppedProperty> extra) {
    if (other_) list_.push_back({"obj records of other kinds", other_});
    for (auto& d : extra)
      if (d.count) list_.push_back(std::move(d));
    return std::move(list_);
  }

 private:
  static constexpr size_t kMaxKeywords = 32, kMaxKeywordLength = 32;
  std::vector<DroppedProperty> list_;
  uint64_t other_ = 0;
};

// The `vt` field of a face corner (`a/b`, `a/b/c`), empty when it has none (`a`, `a//c`).
std::string_view texcoordField(std::string_view corner) {
  const size_t s1 = corner.find('/');
  if (s1 == std::string_view::npos) return {};
  const size_t s2 = corner.find('/', s1 + 1);
  return corner.substr(s1 + 1, s2 == std::string_view::npos ? std::string_view::npos : s2 - s1 - 1);
}

// The `vn` field of a face corner (`a//c`, `a/b/c`), empty when it has none.
std::string_view normalField(std::string_view corner) {
  const size_t s1 = corner.find('/');
  if (s1 == std::string_view::npos) return {};
  const size_t s2 = corner.find('/', s1 + 1);
  return s2 == std::string_view::npos ? std::string_view() : corner.substr(s2 + 1);
}

// Parses a `vt` record's numbers: u [v [w]], finite as float. False when malformed.
bool parseTexcoord(Tokenizer& tok, std::array<float, 2>& uv, bool& nonzero_w) {
  double c[3] = {0, 0, 0};
  int n = 0;
  std::string_view t;
  while (tok.next(t)) {
    if (t[0] == '#') break;
    if (n == 3 || !parseDouble(t, c[n]) || !std::isfinite(static_cast<float>(c[n]))) return false;
    ++n;
  }
  uv = {float(c[0]), float(c[1])};
  nonzero_w = c[2] != 0;
  return n >= 1;
}

}  // namespace

Result<WedgePlan> planObjWedges(Scanner& in, const ReadOptions& options) {
  WedgePlan plan;
  plan.textures = options.texture_coordinates;
  plan.normals = options.corner_normals;
  struct NormalBits {
    std::array<uint32_t, 3> b;
    bool operator==(const NormalBits&) const = default;
  };
  struct NormalHash {
    size_t operator()(const NormalBits& n) const {
      return size_t((uint64_t(n.b[0]) * 0x9E3779B97F4A7C15ull) ^ (uint64_t(n.b[1]) << 21) ^ (uint64_t(n.b[2]) << 42) ^
                    n.b[2]);
    }
  };
  std::unordered_map<NormalBits, uint32_t, NormalHash> distinct_normal;
  std::string_view line;
  uint64_t vertices = 0;
  bool named = false;  // a `vt` or `vn` was seen: faces from here may name them
  // Lenient: a record this read cannot use is passed over; the second read reports it. The first read counts `v`,
  // `vt` and `vn` records as the second does (every line whose first word is the keyword).
  for (;;) {
    SP_ASSIGN_OR_RETURN(bool got, in.nextLine(line));
    if (!got) break;
    Tokenizer tok(line);
    std::string_view word;
    if (!tok.next(word)) continue;
    if (word == "v") {
      if (++vertices > kMaxVertices) return in.errorAtLine(ErrorCode::kLimitExceeded, "more than 2^32-2 vertices");
      if (named) plan.resizeVertices(vertices);
    } else if (word == "vt" || word == "vn") {
      if (!named) plan.resizeVertices(vertices), named = true;
      if (plan.uv_of.size() + plan.normal_of.size() >= kMaxVertices)
        return in.errorAtLine(ErrorCode::kLimitExceeded, "more than 2^32-2 'vt' and 'vn' records");
      if (word == "vt") {
        std::array<float, 2> uv{0, 0};
        bool w = false;
        if (!parseTexcoord(tok, uv, w)) uv = {0, 0};
        plan.uv_of.push_back(plan.addUv(uv));
        plan.vt_used.push_back(false);
      } else {
        NormalBits n{{0, 0, 0}};
        std::string_view t;
        for (uint32_t& b : n.b) {
          double c = 0;
          if (!tok.next(t) || !parseDouble(t, c)) break;
          b = std::bit_cast<uint32_t>(static_cast<float>(c));
        }
        const auto [it, fresh] = distinct_normal.emplace(n, uint32_t(distinct_normal.size()));
        plan.normal_of.push_back(it->second);
      }
    } else if (word == "f" && named) {
      std::string_view t;
      while (tok.next(t)) {
        if (t[0] == '#') break;
        int64_t raw = 0;
        uint32_t v = 0, vt = WedgePlan::kNone, vn = WedgePlan::kNone;
        if (!parseInt64(t.substr(0, t.find('/')), raw) || !resolveIndex(raw, vertices, v)) continue;
        // A field this read cannot resolve names nothing here (the second read fails on it, or ignores a `vt` field
        // when texture coordinates are off): the corner's other field still counts.
        if (const std::string_view field = texcoordField(t); !field.empty() && plan.textures)
          if (!parseInt64(field, raw) || !resolveIndex(raw, plan.uv_of.size(), vt)) vt = WedgePlan::kNone;
        if (const std::string_view field = normalField(t); !field.empty())
          if (!parseInt64(field, raw) || !resolveIndex(raw, plan.normal_of.size(), vn)) vn = WedgePlan::kNone;
        if (vt != WedgePlan::kNone) plan.vt_used[vt] = true;
        if (plan.keys.size() >= kMaxVertices)
          return in.errorAtLine(ErrorCode::kLimitExceeded, "more than 2^32-2 distinct vt and vn pairs");
        plan.addCorner(v, vt == WedgePlan::kNone ? vt : plan.uv_of[vt],
                       vn == WedgePlan::kNone ? vn : plan.normal_of[vn]);
      }
    }
  }
  // No face names a `vt`: the second read lists them dropped and delivers no u and v.
  if (std::find(plan.vt_used.begin(), plan.vt_used.end(), true) == plan.vt_used.end()) plan.textures = false;
  plan.finish();
  return plan;
}

Result<ReadStats> readObj(Scanner& in, MeshSink& sink, const ReadOptions& options, const WedgePlan* plan) {
  if (plan && !plan->splits()) plan = nullptr;
  std::vector<uint32_t> first_output;  // with a plan: per `v`, the index of its first delivered vertex
  size_t next_wedge = 0;               // the plan's next wedge to deliver
  uint64_t texcoord_count = 0, texcoord_w = 0, texcoord_malformed = 0, corners_without_vt = 0;
  ReadStats stats;
  stats.format = MeshFormat::kObj;
  stats.format_detail = "OBJ";
  // Colors are known only when the first `v` line is seen; the buffer is created then.
  std::optional<ChunkBuffer> out;
  uint8_t channels = 0;
  std::vector<Vec3f> vn;                // all `vn` records (needed until the end: faces may reference any)
  std::vector<uint32_t> vertex_normal;  // per vertex: index into vn, or UINT32_MAX
  std::vector<uint32_t> poly;
  std::vector<uint32_t> poly_normals;
  std::string_view line;
  uint64_t vertex_count = 0;
  SkippedRecords skipped;
  std::vector<bool> vn_used;  // per `vn`: named by a face corner
  uint64_t weights = 0, late_colors = 0, corner_normals = 0;
  // Materials: the library files (each once, in order), the first `usemtl` name, how many name another.
  std::string libraries, first_material;
  std::set<std::string> library_names;
  uint64_t usemtl_records = 0, other_materials = 0, triangles_before_usemtl = 0, mtllib_records = 0;
  for (;;) {
    SP_ASSIGN_OR_RETURN(bool got, in.nextLine(line));
    if (!got) break;
    Tokenizer tok(line);
    std::string_view word;
    if (!tok.next(word) || word[0] == '#') continue;
    if (word == "v") {
      double c[7];
      int n = 0;
      std::string_view t;
      while (tok.next(t)) {
        if (t[0] == '#') break;
        if (n == 7) return in.errorAtLine(ErrorCode::kMalformed, "'v' record with more than 7 numbers");
        if (!parseDouble(t, c[n]))
          return in.errorAtLine(ErrorCode::kMalformed, "expected a number, found '" + std::string(t) + "'");
        ++n;
      }
      if (n < 3) return in.errorAtLine(ErrorCode::kMalformed, "'v' record needs x y z");
      for (int k = 0; k < 3; ++k)
        if (!std::isfinite(c[k])) return in.errorAtLine(ErrorCode::kMalformed, "NaN or infinite vertex coordinate");
      if (!out) {
        channels = (n >= 6) ? (n == 7 ? 4 : 3) : 0;
        out.emplace(sink, options.chunk, channels, false, texcoordChannels(plan));
      }
      if (n == 4 && c[3] != 1.0) ++weights;
      if (n >= 6 && channels == 0) ++late_colors;
      Rgba8 col{255, 255, 255, 255};
      if (n >= 6)
        for (int k = 0; k < n - 3 && k < 4; ++k) {
          const double v = std::round(c[3 + k] * 255.0);
          col[k] = static_cast<uint8_t>(v < 0 || !(v == v) ? 0 : (v > 255 ? 255 : v));
        }
      if (vertex_count >= kMaxVertices || out->vertices() >= kMaxVertices)
        return in.errorAtLine(ErrorCode::kLimitExceeded, "more than 2^32-2 vertices");
      if (!plan) {
        SP_RETURN_IF_ERROR(out->addVertex({c[0], c[1], c[2]}, {0, 0, 0}, col));
      } else {
        // The vertex with its first corner's texture coordinates, then its wedges (the plan's, in order).
        first_output.push_back(uint32_t(out->vertices()));
        const uint32_t first = vertex_count < plan->first.size() ? plan->first[vertex_count] : WedgePlan::kNone;
        SP_RETURN_IF_ERROR(out->addVertex({c[0], c[1], c[2]}, {0, 0, 0}, col, plan->words(first).data()));
        for (; next_wedge < plan->wedges.size() && plan->wedges[next_wedge].first == vertex_count; ++next_wedge) {
          if (out->vertices() >= kMaxVertices)
            return in.errorAtLine(ErrorCode::kLimitExceeded, "more than 2^32-2 vertices with the seams' wedges");
          SP_RETURN_IF_ERROR(out->addVertex({c[0], c[1], c[2]}, {0, 0, 0}, col,
                                            plan->words(plan->wedges[next_wedge].second).data()));
        }
      }
      ++vertex_count;
    } else if (word == "vn") {
      double c[3];
      std::string_view t;
      for (double& v : c)
        if (!tok.next(t) || !parseDouble(t, v) || !std::isfinite(v))
          return in.errorAtLine(ErrorCode::kMalformed, "'vn' record needs three finite numbers");
      if (vn.size() >= kMaxVertices) return in.errorAtLine(ErrorCode::kLimitExceeded, "too many 'vn' records");
      vn.push_back({static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2])});
      vn_used.push_back(false);
    } else if (word == "vt" && plan && plan->textures) {
      // A record that is not one to three finite numbers (as float) reads as (0, 0), listed (as the first read has it).
      std::array<float, 2> uv;
      bool w = false;
      if (parseTexcoord(tok, uv, w)) texcoord_w += w;
      else ++texcoord_malformed;
      ++texcoord_count;
    } else if (word == "f") {
      poly.clear();
      poly_normals.clear();
      std::string_view t;
      while (tok.next(t)) {
        if (t[0] == '#') break;
        // corner: v | v/t | v//n | v/t/n
        const size_t s1 = t.find('/');
        int64_t raw = 0;
        if (!parseInt64(t.substr(0, s1), raw))
          return in.errorAtLine(ErrorCode::kMalformed, "bad face corner '" + std::string(t) + "'");
        uint32_t v = 0;
        if (!resolveIndex(raw, vertex_count, v))
          return in.errorAtLine(ErrorCode::kMalformed, "face index " + std::to_string(raw) +
                                                           " does not name one of the " +
                                                           std::to_string(vertex_count) + " vertices so far");
        uint32_t n = UINT32_MAX;
        if (const std::string_view field = normalField(t); !field.empty()) {
          int64_t rn = 0;
          if (!parseInt64(field, rn) || !resolveIndex(rn, vn.size(), n))
            return in.errorAtLine(ErrorCode::kMalformed, "bad normal index in face corner '" + std::string(t) + "'");
        }
        if (plan) {  // the corner's wedge: its vertex's first, or the one its `vt` and `vn` made
          uint32_t vt = WedgePlan::kNone;
          if (const std::string_view field = texcoordField(t); plan->textures && !field.empty()) {
            int64_t rt = 0;
            if (!parseInt64(field, rt) || !resolveIndex(rt, texcoord_count, vt))
              return in.errorAtLine(ErrorCode::kMalformed,
                                    "bad texture coordinate index in face corner '" + std::string(t) + "'");
          } else if (plan->textures) {
            ++corners_without_vt;  // it takes its vertex's first coordinates (naming no `vn` either), or (0, 0)
          }
          if ((vt != WedgePlan::kNone && vt >= plan->uv_of.size()) ||
              (n != UINT32_MAX && plan->normals && n >= plan->normal_of.size()))
            return in.errorAtLine(ErrorCode::kIo, "the file changed between its two reads");
          const std::optional<uint32_t> wedge =
              plan->wedgeOf(v, vt == WedgePlan::kNone ? vt : plan->uv_of[vt],
                            n == UINT32_MAX || !plan->normals ? WedgePlan::kNone : plan->normal_of[n]);
          if (!wedge) return in.errorAtLine(ErrorCode::kIo, "the file changed between its two reads");
          v = first_output[v] + *wedge;
        }
        if (poly.size() >= kMaxPolygonCorners)
          return in.errorAtLine(ErrorCode::kLimitExceeded, "face with more than 65536 corners");
        poly.push_back(v);
        poly_normals.push_back(n);
      }
      if (poly.size() < 3)
        return in.errorAtLine(ErrorCode::kMalformed,
                              "face with " + std::to_string(poly.size()) + " corners (at least 3 needed)");
      if (!out) out.emplace(sink, options.chunk, 0, false);
      if (poly.size() > 3) ++stats.polygons;
      for (size_t i = 1; i + 1 < poly.size(); ++i)
        SP_RETURN_IF_ERROR(out->addTriangle({poly[0], poly[i], poly[i + 1]}));
      for (size_t i = 0; i < poly.size(); ++i) {
        if (poly_normals[i] == UINT32_MAX) continue;
        vn_used[poly_normals[i]] = true;
        if (vertex_normal.size() <= poly[i]) vertex_normal.resize(poly[i] + 1, UINT32_MAX);
        if (vertex_normal[poly[i]] == UINT32_MAX) vertex_normal[poly[i]] = poly_normals[i];
        else if (std::memcmp(&vn[vertex_normal[poly[i]]], &vn[poly_normals[i]], sizeof(Vec3f)) != 0) ++corner_normals;
      }
    } else if (word == "mtllib") {
      ++mtllib_records;
      for (std::string_view t; tok.next(t) && t[0] != '#';)  // (bounded: past the limit nothing is kept)
        if (libraries.size() <= kMaxMaterialBytes && library_names.insert(std::string(t)).second) {
          if (!libraries.empty()) libraries += ' ';
          libraries.append(t);
        }
    } else if (word == "usemtl") {
      std::string name;  // the rest of the line, single-spaced
      for (std::string_view t; tok.next(t) && t[0] != '#';) {
        if (!name.empty()) name += ' ';
        name.append(t);
      }
      if (usemtl_records++ == 0) first_material = name, triangles_before_usemtl = out ? out->triangles() : 0;
      else if (name != first_material) ++other_materials;
    } else if (word == "s") {
      std::string_view t;
      if (!tok.next(t) || !(t == "off" || t == "0")) skipped.add(word);
    } else {
      skipped.add(word);
    }
  }
  if (out) SP_RETURN_IF_ERROR(out->flush());
  if (plan && ((plan->textures && texcoord_count != plan->uv_of.size()) || next_wedge != plan->wedges.size()))
    return makeError(ErrorCode::kIo, in.name() + ": the file changed between its two reads");
  const uint64_t delivered = out ? out->vertices() : 0;
  if (!vertex_normal.empty()) {
    std::vector<Vec3f> chunk;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (uint64_t first = 0; first < delivered; first += options.chunk) {
      chunk.clear();
      for (uint64_t v = first; v < std::min<uint64_t>(delivered, first + options.chunk); ++v)
        chunk.push_back(v < vertex_normal.size() && vertex_normal[v] != UINT32_MAX ? vn[vertex_normal[v]]
                                                                                   : Vec3f{nan, nan, nan});
      SP_RETURN_IF_ERROR(sink.vertexNormals(first, chunk));
    }
  }
  const uint64_t vn_unused = static_cast<uint64_t>(std::count(vn_used.begin(), vn_used.end(), false));
  const uint64_t vt_unused = plan && plan->textures
                                 ? static_cast<uint64_t>(std::count(plan->vt_used.begin(), plan->vt_used.end(), false))
                                 : 0;
  // One material for every triangle is kept; several (or triangles before the first `usemtl`, which have none) are
  // not: a material per face is not kept yet.
  const bool one_material = usemtl_records && other_materials == 0 && triangles_before_usemtl == 0;
  const bool material_valid = !first_material.empty() && validMaterialName(first_material);
  if (one_material && material_valid) stats.materials.material = first_material;
  const bool library_kept = validMaterialName(libraries);
  if (library_kept) stats.materials.library = libraries;
  const std::string unfit = " (over " + std::to_string(kMaxMaterialBytes) +
                            " bytes, control characters or not UTF-8: not kept)";
  stats.dropped = skipped.take({{"obj usemtl (several materials or faces without one: none is kept)",
                                 one_material ? 0 : usemtl_records},
                                {"obj usemtl" + (first_material.empty() ? std::string(" (no name)") : unfit),
                                 one_material && !material_valid ? usemtl_records : 0},
                                {"obj mtllib" + unfit, library_kept ? 0 : mtllib_records},
                                {"obj vn unused", vn_unused},
                                {"obj vn per corner", corner_normals},
                                {"obj v w", weights},
                                {"obj v colors", late_colors},
                                {"obj vt unused", vt_unused},
                                {"obj vt w", texcoord_w},
                                {"obj vt malformed (read as 0 0)", texcoord_malformed},
                                {"obj f corners without vt", corners_without_vt}});
  stats.vertices = delivered;
  stats.source_vertices = vertex_count;
  stats.triangles = out ? out->triangles() : 0;
  return stats;
}

}  // namespace scanpress
