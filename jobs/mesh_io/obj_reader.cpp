// Wavefront OBJ reader: `v x y z [w | r g b [a]]`, `vn`, `f` with corners `a`, `a/b`, `a//c`, `a/b/c`, negative
// (relative) indices, polygons (fan-triangulated). Every other record (vt, g, o, s, usemtl, mtllib, l, p, ...)
// is skipped and listed in ReadStats::dropped as "obj KEYWORD" with its count ("s off" and "s 0" state nothing
// and are not listed). A vertex's normal is the `vn` its first face corner names; those arrive at the end
// (vertexNormals) because OBJ states them only in faces. Also listed: `vn` records no face names ("obj vn
// unused"), face corners naming another normal than their vertex's first one ("obj vn per corner"), `v`
// weights other than 1 ("obj v w") and `v` colors after a first `v` without them ("obj v colors").
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "jobs/mesh_io/input.h"
#include "jobs/mesh_io/mesh_reader.h"

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

}  // namespace

Result<ReadStats> readObj(Scanner& in, MeshSink& sink, const ReadOptions& options) {
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
        out.emplace(sink, options.chunk, channels, false);
      }
      if (n == 4 && c[3] != 1.0) ++weights;
      if (n >= 6 && channels == 0) ++late_colors;
      Rgba8 col{255, 255, 255, 255};
      if (n >= 6)
        for (int k = 0; k < n - 3 && k < 4; ++k) {
          const double v = std::round(c[3 + k] * 255.0);
          col[k] = static_cast<uint8_t>(v < 0 || !(v == v) ? 0 : (v > 255 ? 255 : v));
        }
      if (vertex_count >= kMaxVertices) return in.errorAtLine(ErrorCode::kLimitExceeded, "more than 2^32-2 vertices");
      SP_RETURN_IF_ERROR(out->addVertex({c[0], c[1], c[2]}, {0, 0, 0}, col));
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
        if (s1 != std::string_view::npos) {
          const size_t s2 = t.find('/', s1 + 1);
          if (s2 != std::string_view::npos && s2 + 1 < t.size()) {
            int64_t rn = 0;
            if (!parseInt64(t.substr(s2 + 1), rn) || !resolveIndex(rn, vn.size(), n))
              return in.errorAtLine(ErrorCode::kMalformed, "bad normal index in face corner '" + std::string(t) + "'");
          }
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
        else if (vertex_normal[poly[i]] != poly_normals[i]) ++corner_normals;
      }
    } else if (word == "s") {
      std::string_view t;
      if (!tok.next(t) || !(t == "off" || t == "0")) skipped.add(word);
    } else {
      skipped.add(word);
    }
  }
  if (out) SP_RETURN_IF_ERROR(out->flush());
  if (!vertex_normal.empty()) {
    std::vector<Vec3f> chunk;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (uint64_t first = 0; first < vertex_count; first += options.chunk) {
      chunk.clear();
      for (uint64_t v = first; v < std::min<uint64_t>(vertex_count, first + options.chunk); ++v)
        chunk.push_back(v < vertex_normal.size() && vertex_normal[v] != UINT32_MAX ? vn[vertex_normal[v]]
                                                                                   : Vec3f{nan, nan, nan});
      SP_RETURN_IF_ERROR(sink.vertexNormals(first, chunk));
    }
  }
  const uint64_t vn_unused = static_cast<uint64_t>(std::count(vn_used.begin(), vn_used.end(), false));
  stats.dropped = skipped.take({{"obj vn unused", vn_unused},
                                {"obj vn per corner", corner_normals},
                                {"obj v w", weights},
                                {"obj v colors", late_colors}});
  stats.vertices = stats.source_vertices = vertex_count;
  stats.triangles = out ? out->triangles() : 0;
  return stats;
}

}  // namespace scanpress
