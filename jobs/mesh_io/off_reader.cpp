// OFF reader: headers OFF, COFF (colors), NOFF (normals), CNOFF; counts on the header line or the next one;
// `#` comments; faces `n i1 .. in [color]` (fan-triangulated; face colors, and vertex values past those kept, are
// listed in ReadStats::dropped). Binary OFF is not supported (clear error).
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "jobs/mesh_io/input.h"
#include "jobs/mesh_io/mesh_reader.h"

namespace scanpress {

Result<ReadStats> readOff(Scanner& in, MeshSink& sink, const ReadOptions& options) {
  ReadStats stats;
  stats.format = MeshFormat::kOff;
  std::string_view line;
  // Next non-empty, non-comment line, with comments stripped.
  auto meaningful = [&](std::string_view& out) -> Result<bool> {
    for (;;) {
      SP_ASSIGN_OR_RETURN(bool got, in.nextLine(out));
      if (!got) return false;
      if (auto h = out.find('#'); h != std::string_view::npos) out = out.substr(0, h);
      Tokenizer t(out);
      std::string_view w;
      if (t.next(w)) return true;
    }
  };
  SP_ASSIGN_OR_RETURN(bool got, meaningful(line));
  if (!got) return in.errorAtLine(ErrorCode::kMalformed, "empty OFF file");
  Tokenizer tok(line);
  std::string_view word;
  tok.next(word);
  bool colors = false, normals = false;
  if (word == "OFF") {
  } else if (word == "COFF") colors = true;
  else if (word == "NOFF") normals = true;
  else if (word == "CNOFF") colors = normals = true;
  else return in.errorAtLine(ErrorCode::kMalformed, "not an OFF file (header '" + std::string(word) + "')");
  stats.format_detail = std::string(word);
  std::string_view t;
  int64_t counts[3] = {0, 0, 0};
  int have = 0;
  if (tok.next(t)) {
    if (t == "BINARY") return in.errorAtLine(ErrorCode::kUnsupported, "binary OFF is not supported");
    if (!parseInt64(t, counts[have++])) return in.errorAtLine(ErrorCode::kMalformed, "bad OFF counts");
    while (have < 3 && tok.next(t))
      if (!parseInt64(t, counts[have++])) return in.errorAtLine(ErrorCode::kMalformed, "bad OFF counts");
  }
  if (have == 0) {
    SP_ASSIGN_OR_RETURN(got, meaningful(line));
    if (!got) return in.errorAtLine(ErrorCode::kTruncated, "OFF file ends before its counts");
    Tokenizer ct(line);
    while (have < 3 && ct.next(t))
      if (!parseInt64(t, counts[have++])) return in.errorAtLine(ErrorCode::kMalformed, "bad OFF counts");
  }
  if (have < 2 || counts[0] < 0 || counts[1] < 0)
    return in.errorAtLine(ErrorCode::kMalformed, "OFF counts need 'vertices faces [edges]'");
  const uint64_t nv = static_cast<uint64_t>(counts[0]), nf = static_cast<uint64_t>(counts[1]);
  if (nv > kMaxVertices) return in.errorAtLine(ErrorCode::kLimitExceeded, "more than 2^32-2 vertices");
  if (auto left = in.remaining(); left && (nv + nf) > *left / 2 + 1)
    return in.errorAtLine(ErrorCode::kTruncated, "OFF declares " + std::to_string(nv) + " vertices and " +
                                                     std::to_string(nf) + " faces, but only " + std::to_string(*left) +
                                                     " bytes remain");
  ChunkBuffer out(sink, options.chunk, colors ? 4 : 0, normals);
  uint64_t vertex_extra = 0, face_extra = 0;  // lines with values past what is kept (ReadStats::dropped)
  for (uint64_t v = 0; v < nv; ++v) {
    SP_ASSIGN_OR_RETURN(got, meaningful(line));
    if (!got) return in.errorAtLine(ErrorCode::kTruncated, "OFF file ends after " + std::to_string(v) + " vertices");
    Tokenizer vt(line);
    double c[10];
    bool fractional[10] = {};
    int n = 0;
    while (n < 10 && vt.next(t)) {
      if (!parseDouble(t, c[n]))
        return in.errorAtLine(ErrorCode::kMalformed, "expected a number, found '" + std::string(t) + "'");
      fractional[n] = t.find_first_of(".eE") != std::string_view::npos;
      ++n;
    }
    const int need = 3 + (normals ? 3 : 0) + (colors ? 3 : 0);
    if (n < need) return in.errorAtLine(ErrorCode::kMalformed, "vertex line has " + std::to_string(n) + " numbers");
    for (int k = 0; k < 3 + (normals ? 3 : 0); ++k)
      if (!std::isfinite(c[k])) return in.errorAtLine(ErrorCode::kMalformed, "NaN or infinite value");
    const int used = colors ? std::min(n, need + 1) : need;  // a fourth color value is alpha
    if (n > used || vt.next(t)) ++vertex_extra;
    Vec3f nrm{0, 0, 0};
    if (normals) nrm = {static_cast<float>(c[3]), static_cast<float>(c[4]), static_cast<float>(c[5])};
    Rgba8 col{255, 255, 255, 255};
    if (colors) {
      const int base = normals ? 6 : 3;
      const int channels = std::min(4, n - base);
      bool floats = false;  // OFF colors are 0..1 floats or 0..255 integers: written as floats means the former
      for (int k = 0; k < channels; ++k) floats |= fractional[base + k];
      for (int k = 0; k < channels; ++k) {
        double x = floats ? c[base + k] * 255.0 : c[base + k];
        x = std::round(x);
        col[k] = static_cast<uint8_t>(!(x > 0) ? 0 : (x > 255 ? 255 : x));
      }
    }
    SP_RETURN_IF_ERROR(out.addVertex({c[0], c[1], c[2]}, nrm, col));
  }
  std::vector<uint32_t> poly;
  for (uint64_t f = 0; f < nf; ++f) {
    SP_ASSIGN_OR_RETURN(got, meaningful(line));
    if (!got) return in.errorAtLine(ErrorCode::kTruncated, "OFF file ends after " + std::to_string(f) + " faces");
    Tokenizer ft(line);
    int64_t n = 0;
    if (!ft.next(t) || !parseInt64(t, n)) return in.errorAtLine(ErrorCode::kMalformed, "bad face line");
    if (n < 3) return in.errorAtLine(ErrorCode::kMalformed, "face with " + std::to_string(n) + " vertices");
    if (n > kMaxPolygonCorners) return in.errorAtLine(ErrorCode::kLimitExceeded, "face with too many vertices");
    poly.clear();
    for (int64_t k = 0; k < n; ++k) {
      int64_t idx = 0;
      if (!ft.next(t) || !parseInt64(t, idx))
        return in.errorAtLine(ErrorCode::kMalformed, "face needs " + std::to_string(n) + " indices");
      if (idx < 0 || static_cast<uint64_t>(idx) >= nv)
        return in.errorAtLine(ErrorCode::kMalformed, "vertex index " + std::to_string(idx) + " out of range");
      poly.push_back(static_cast<uint32_t>(idx));
    }
    if (ft.next(t)) ++face_extra;  // a face color (or anything else after the indices)
    if (n > 3) ++stats.polygons;
    for (size_t i = 1; i + 1 < poly.size(); ++i) SP_RETURN_IF_ERROR(out.addTriangle({poly[0], poly[i], poly[i + 1]}));
  }
  SP_RETURN_IF_ERROR(out.flush());
  if (vertex_extra) stats.dropped.push_back({"off vertex extra values", vertex_extra});
  if (face_extra) stats.dropped.push_back({"off face colors", face_extra});
  stats.vertices = stats.source_vertices = out.vertices();
  stats.triangles = out.triangles();
  return stats;
}

}  // namespace scanpress
