// STL reader, binary and ascii. STL is a triangle soup: corners with bit-identical positions are welded into
// one vertex (a hash map from the three float bit patterns; the only reader state that grows with the file).
// Facet normals are not kept (they are per face and recomputable from the corners, so they are not listed as
// dropped); non-zero attribute words of binary facets (colors in some writers) are listed in
// ReadStats::dropped. A binary file whose data goes on past its declared triangle count is malformed (the rest
// would be lost). Binary vs ascii: a file that starts with "solid" and has "facet" or "endsolid" in its first
// 512 bytes is ascii; anything else is binary.
#include <cmath>
#include <cstring>
#include <string>
#include <unordered_map>

#include "jobs/mesh_io/input.h"
#include "jobs/mesh_io/mesh_reader.h"

namespace scanpress {
namespace {

struct KeyHash {
  size_t operator()(const std::array<uint64_t, 3>& k) const {
    uint64_t h = k[0] * 0x9E3779B97F4A7C15ull;
    h ^= (h >> 29) ^ (k[1] * 0xC2B2AE3D27D4EB4Full);
    h ^= (h >> 31) ^ (k[2] * 0x165667B19E3779F9ull);
    return static_cast<size_t>(h ^ (h >> 32));
  }
};

class Welder {
 public:
  Welder(ChunkBuffer& out) : out_(out) {}
  Status corner(const Vec3d& p, const std::array<uint64_t, 3>& key, uint32_t& index) {
    auto [it, inserted] = map_.try_emplace(key, next_);
    if (inserted) {
      if (next_ >= kMaxVertices) return makeError(ErrorCode::kLimitExceeded, "more than 2^32-2 distinct vertices");
      SP_RETURN_IF_ERROR(out_.addVertex(p, {0, 0, 0}, {255, 255, 255, 255}));
      ++next_;
    }
    index = it->second;
    return Status::ok();
  }

 private:
  ChunkBuffer& out_;
  std::unordered_map<std::array<uint64_t, 3>, uint32_t, KeyHash> map_;
  uint32_t next_ = 0;
};

template <typename T>
std::array<uint64_t, 3> bitsKey(const T (&c)[3]) {
  std::array<uint64_t, 3> k{};
  for (int i = 0; i < 3; ++i) std::memcpy(&k[i], &c[i], sizeof(T));
  return k;
}

Status readBinary(Scanner& in, ChunkBuffer& out, ReadStats& stats) {
  uint8_t header[80];
  SP_RETURN_IF_ERROR(in.read(header, 80));
  uint32_t count = 0;
  SP_RETURN_IF_ERROR(in.read(&count, 4));
  if (auto left = in.remaining(); left && uint64_t(count) * 50 > *left)
    return in.errorAtOffset(ErrorCode::kTruncated, "binary STL declares " + std::to_string(count) + " triangles (" +
                                                       std::to_string(uint64_t(count) * 50) + " bytes) but " +
                                                       std::to_string(*left) + " bytes remain");
  Welder welder(out);
  uint8_t rec[50];
  uint64_t attributes = 0;  // facets with a non-zero attribute word
  for (uint32_t t = 0; t < count; ++t) {
    SP_RETURN_IF_ERROR(in.read(rec, 50));
    Triangle tri;
    for (int c = 0; c < 3; ++c) {
      float p[3];
      std::memcpy(p, rec + 12 + 12 * c, 12);
      if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
        return makeError(ErrorCode::kMalformed, in.name() + ": byte " +
                                                    std::to_string(in.offset() - 50 + 12 + 12 * c) + ": triangle " +
                                                    std::to_string(t) + " has a NaN or infinite coordinate");
      SP_RETURN_IF_ERROR(welder.corner({p[0], p[1], p[2]}, bitsKey(p), tri[c]));
    }
    uint16_t attribute;  // "attribute byte count": 0 by the standard, colors in some writers (VisCAM, Magics)
    std::memcpy(&attribute, rec + 48, 2);
    attributes += attribute != 0;
    SP_RETURN_IF_ERROR(out.addTriangle(tri));
  }
  if (attributes) stats.dropped.push_back({"stl facet attribute", attributes});
  // Data past the declared triangles: the count in the header is too low (a writer that did not update it, or a
  // concatenation), and the rest of the scan would be lost without a word.
  const uint64_t end = in.offset();
  SP_ASSIGN_OR_RETURN(auto more, in.peek(1));
  if (!more.empty()) {
    const auto left = in.remaining();
    const std::string place = in.name() + ": byte " + std::to_string(end) +
                              (in.compressedInput() ? " of the decompressed data" : "");
    return makeError(ErrorCode::kMalformed,
                     place + ": binary STL declares " + std::to_string(count) + " triangles, which end at byte " +
                         std::to_string(end) + ", but the data goes on" +
                         (left ? " to byte " + std::to_string(end + *left) + " (" + std::to_string(*left) +
                                     " more bytes, " + std::to_string(*left / 50) + " triangles and " +
                                     std::to_string(*left % 50) + " bytes)"
                               : "") +
                         ": the triangle count in the header is wrong");
  }
  stats.format_detail = "STL binary";
  stats.source_vertices = uint64_t(count) * 3;
  return Status::ok();
}

Status readAscii(Scanner& in, ChunkBuffer& out, ReadStats& stats) {
  Welder welder(out);
  std::string_view line, word;
  enum { kOutside, kInSolid, kInFacet, kInLoop } state = kOutside;
  Triangle tri{};
  int corners = 0;
  uint64_t facets = 0;
  for (;;) {
    SP_ASSIGN_OR_RETURN(bool got, in.nextLine(line));
    if (!got) break;
    Tokenizer tok(line);
    if (!tok.next(word)) continue;
    auto fail = [&](const std::string& msg) { return in.errorAtLine(ErrorCode::kMalformed, msg); };
    if (word == "solid") {
      if (state != kOutside) return fail("'solid' inside a solid");
      state = kInSolid;
    } else if (word == "endsolid") {
      if (state != kInSolid) return fail("'endsolid' outside a solid or inside a facet");
      state = kOutside;
    } else if (word == "facet") {
      if (state != kInSolid) return fail("'facet' outside a solid or inside a facet");
      state = kInFacet;
      corners = 0;
    } else if (word == "outer") {
      if (state != kInFacet) return fail("'outer loop' outside a facet");
      state = kInLoop;
    } else if (word == "vertex") {
      if (state != kInLoop) return fail("'vertex' outside 'outer loop'");
      if (corners == 3) return fail("facet with more than 3 vertices");
      double p[3];
      std::string_view t;
      for (double& v : p)
        if (!tok.next(t) || !parseDouble(t, v)) return fail("'vertex' needs three numbers");
      for (double v : p)
        if (!std::isfinite(v)) return fail("NaN or infinite vertex coordinate");
      // ascii STL coordinates are floats: weld on the float value so "1.0" and "1.00" are one vertex.
      const float f[3] = {static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2])};
      SP_RETURN_IF_ERROR(welder.corner({f[0], f[1], f[2]}, bitsKey(f), tri[corners]));
      ++corners;
    } else if (word == "endloop") {
      if (state != kInLoop) return fail("'endloop' outside a loop");
      state = kInFacet;
    } else if (word == "endfacet") {
      if (state != kInFacet) return fail("'endfacet' outside a facet");
      if (corners != 3) return fail("facet with " + std::to_string(corners) + " vertices (3 needed)");
      SP_RETURN_IF_ERROR(out.addTriangle(tri));
      ++facets;
      state = kInSolid;
    } else {
      return fail("unexpected '" + std::string(word) + "' in ascii STL");
    }
  }
  if (state != kOutside) return in.errorAtLine(ErrorCode::kTruncated, "ascii STL ends inside a solid");
  stats.format_detail = "STL ascii";
  stats.source_vertices = facets * 3;
  return Status::ok();
}

}  // namespace

Result<ReadStats> readStl(Scanner& in, MeshSink& sink, const ReadOptions& options) {
  ReadStats stats;
  stats.format = MeshFormat::kStl;
  ChunkBuffer out(sink, options.chunk, 0, false);
  SP_ASSIGN_OR_RETURN(auto head, in.peek(512));
  std::string_view s(reinterpret_cast<const char*>(head.data()), head.size());
  size_t i = 0;
  while (i < s.size() && (s[i] == ' ' || s[i] == '\t' || s[i] == '\r' || s[i] == '\n')) ++i;
  const bool ascii = s.substr(i).starts_with("solid") &&
                     (s.find("facet") != std::string_view::npos || s.find("endsolid") != std::string_view::npos);
  if (ascii) SP_RETURN_IF_ERROR(readAscii(in, out, stats));
  else SP_RETURN_IF_ERROR(readBinary(in, out, stats));
  SP_RETURN_IF_ERROR(out.flush());
  stats.vertices = out.vertices();
  stats.triangles = out.triangles();
  return stats;
}

}  // namespace scanpress
