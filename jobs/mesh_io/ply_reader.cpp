// PLY reader (Turk's format as written by the Stanford scanners, VCG/MeshLab, VTK, Open3D, ...).
//
// ascii, binary_little_endian and binary_big_endian; any property order and types; float or double x/y/z;
// optional nx/ny/nz and red/green/blue[/alpha] (uchar, other integer types or float); faces as
// `vertex_indices` or `vertex_index` lists of any integer types (fan-triangulated); `tristrips` with -1
// restarts (odd triangles flipped, the usual strip decoding); every other vertex property kept as a scalar channel
// at its type; a face's `texcoord` list of float32 (u and v per corner, MeshLab's wedge texture coordinates) kept
// as channels u and v, with vertices split into wedges where corners differ (WedgePlan: the file is read twice,
// the first read stopping after the header of a file without such lists); every other element and property is
// skipped and listed in ReadStats::dropped.
#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "engine/container/container.h"
#include "jobs/mesh_io/input.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/texcoords.h"

namespace scanpress {
namespace {

enum class PlyType : uint8_t { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };
enum class Encoding { kAscii, kLittle, kBig };
// kScalar: any other non-list vertex property (confidence, intensity, quality, flags, ...), kept at its type.
enum class Role : uint8_t {
  kNone,
  kX,
  kY,
  kZ,
  kNx,
  kNy,
  kNz,
  kRed,
  kGreen,
  kBlue,
  kAlpha,
  kIndices,
  kScalar,
  kTexcoords  // a face's `texcoord` list (float32): u and v per corner (texcoords.h)
};
enum class ElementKind { kVertex, kFace, kTristrips, kOther };

bool parseType(std::string_view s, PlyType& t) {
  struct Name {
    std::string_view name;
    PlyType type;
  };
  static constexpr Name kNames[] = {
      {"char", PlyType::kInt8},      {"int8", PlyType::kInt8},       {"uchar", PlyType::kUint8},
      {"uint8", PlyType::kUint8},    {"short", PlyType::kInt16},     {"int16", PlyType::kInt16},
      {"ushort", PlyType::kUint16},  {"uint16", PlyType::kUint16},   {"int", PlyType::kInt32},
      {"int32", PlyType::kInt32},    {"uint", PlyType::kUint32},     {"uint32", PlyType::kUint32},
      {"float", PlyType::kFloat32},  {"float32", PlyType::kFloat32}, {"double", PlyType::kFloat64},
      {"float64", PlyType::kFloat64}};
  for (const auto& n : kNames)
    if (n.name == s) return t = n.type, true;
  return false;
}

size_t typeSize(PlyType t) {
  switch (t) {
    case PlyType::kInt8:
    case PlyType::kUint8: return 1;
    case PlyType::kInt16:
    case PlyType::kUint16: return 2;
    case PlyType::kInt32:
    case PlyType::kUint32:
    case PlyType::kFloat32: return 4;
    case PlyType::kFloat64: return 8;
  }
  return 1;
}

bool isFloatType(PlyType t) { return t == PlyType::kFloat32 || t == PlyType::kFloat64; }

struct Property {
  std::string name;
  PlyType type = PlyType::kFloat32;
  bool is_list = false;
  PlyType count_type = PlyType::kUint8;
  Role role = Role::kNone;
  size_t offset = 0;  // in a fixed-size binary record
};

struct Element {
  std::string name;
  uint64_t count = 0;
  ElementKind kind = ElementKind::kOther;
  std::vector<Property> props;
  bool fixed_size = true;
  size_t record_size = 0;  // binary, when fixed_size
  size_t min_record_bytes = 0;
};

Role vertexRole(std::string_view n) {
  if (n == "x") return Role::kX;
  if (n == "y") return Role::kY;
  if (n == "z") return Role::kZ;
  if (n == "nx") return Role::kNx;
  if (n == "ny") return Role::kNy;
  if (n == "nz") return Role::kNz;
  if (n == "red" || n == "diffuse_red" || n == "r") return Role::kRed;
  if (n == "green" || n == "diffuse_green" || n == "g") return Role::kGreen;
  if (n == "blue" || n == "diffuse_blue" || n == "b") return Role::kBlue;
  if (n == "alpha" || n == "diffuse_alpha" || n == "a") return Role::kAlpha;
  return Role::kNone;
}

uint8_t colorByte(double v, PlyType t) {
  double c;
  switch (t) {
    case PlyType::kFloat32:
    case PlyType::kFloat64: c = std::round(v * 255.0); break;
    case PlyType::kInt16:
    case PlyType::kUint16: c = std::round(v / 257.0); break;
    default: c = v; break;
  }
  if (!(c >= 0.0)) c = 0.0;  // also NaN
  return static_cast<uint8_t>(std::min(c, 255.0));
}

class PlyParser {
 public:
  // `plan`: the wedges of the faces' texture coordinates (the second read); `planning`: the first read, which
  // fills it (its sink discards what it gets).
  PlyParser(Scanner& in, MeshSink& sink, const ReadOptions& options, const WedgePlan* plan = nullptr,
            WedgePlan* planning = nullptr)
      : in_(in), sink_(sink), options_(options), plan_(plan && plan->splits() ? plan : nullptr), planning_(planning) {}

  // The first read: the plan of a file whose faces have `texcoord` lists (none: it stops after the header).
  Result<WedgePlan> plan() {
    SP_RETURN_IF_ERROR(run().status());
    planning_->finish();
    return std::move(*planning_);
  }

  Result<ReadStats> run() {
    SP_RETURN_IF_ERROR(parseHeader());
    if (planning_) {
      bool lists = false;
      for (const auto& e : elements_)
        for (const auto& p : e.props) lists |= p.role == Role::kTexcoords && e.count > 0;
      if (!lists) return ReadStats();
      planning_->textures = true;
    }
    const Element* vertex = nullptr;
    for (const auto& e : elements_)
      if (e.kind == ElementKind::kVertex) vertex = &e;
    if (!vertex) return in_.errorAtLine(ErrorCode::kMalformed, "PLY header declares no 'vertex' element");
    bool has_normals = false;
    uint8_t channels = 0;
    int xyz = 0;
    for (const auto& p : vertex->props) {
      if (p.role == Role::kX || p.role == Role::kY || p.role == Role::kZ) ++xyz;
      if (p.role == Role::kNx) has_normals = true;
      if ((p.role == Role::kNx || p.role == Role::kNy || p.role == Role::kNz) && p.type == PlyType::kFloat64)
        stats_.double_normals = true;
      if (p.role == Role::kRed) channels = std::max<uint8_t>(channels, 3);
      if (p.role == Role::kAlpha) channels = 4;
    }
    if (xyz != 3) return in_.errorAtLine(ErrorCode::kMalformed, "PLY 'vertex' element lacks x, y or z");
    vertex_count_ = vertex->count;
    std::vector<ScalarChannel> scalars;
    for (const auto& p : vertex->props)
      if (p.role == Role::kScalar)
        scalars.push_back({p.name, static_cast<ScalarType>(static_cast<uint8_t>(p.type) + 1)});
    stride_ = scalarWords(scalars);
    if (plan_ && plan_->textures) {  // the faces' texture coordinates, as u and v after the vertex's own
      scalars.push_back({kTexcoordU, ScalarType::kFloat32});
      scalars.push_back({kTexcoordV, ScalarType::kFloat32});
    }
    ChunkBuffer out(sink_, options_.chunk, channels, has_normals, std::move(scalars));
    out_ = &out;
    bool seen_vertex = false;
    for (const auto& e : elements_) {
      if ((e.kind == ElementKind::kFace || e.kind == ElementKind::kTristrips) && !seen_vertex && e.count > 0)
        return in_.errorAtLine(ErrorCode::kUnsupported,
                               "PLY element '" + e.name + "' comes before 'vertex'; scanpress needs vertices first");
      if (e.kind == ElementKind::kVertex) seen_vertex = true;
      SP_RETURN_IF_ERROR(checkCount(e));
      SP_RETURN_IF_ERROR(readElement(e));
    }
    SP_RETURN_IF_ERROR(out.flush());
    if (plan_ && next_wedge_ != plan_->wedges.size())
      return makeError(ErrorCode::kIo, in_.name() + ": the file changed between its two reads");
    listDropped();
    // One texture image is kept; several (a texture per face, `texnumber`) or a name the container cannot hold are
    // listed.
    if (texture_files_ && other_textures_ == 0 && !texture_file_.empty() && validMaterialName(texture_file_))
      stats_.materials.texture = texture_file_;
    else if (texture_files_)
      stats_.dropped.push_back({other_textures_ ? "comment TextureFile (several textures: none is kept)"
                                                : "comment TextureFile (over 1024 bytes, control characters or not "
                                                  "UTF-8: not kept)",
                                texture_files_});
    stats_.vertices = out.vertices();
    stats_.source_vertices = vertex_count_;
    stats_.triangles = out.triangles();
    stats_.format = MeshFormat::kPly;
    return stats_;
  }

 private:
  // Every value the elements were read past, by name: properties of vertex and face that have no role
  // (per-vertex scalars such as confidence, intensity, quality, flags; per-face flags, quality, colors, ...)
  // and whole elements other than vertex, face and tristrips (a VCG `camera`, `edge`, `material`, ...).
  void listDropped() {
    for (const auto& e : elements_) {
      if (e.count == 0) continue;
      if (e.kind == ElementKind::kOther) {
        stats_.dropped.push_back({"element " + e.name, e.count});
        continue;
      }
      for (const auto& p : e.props)
        if (p.role == Role::kNone) stats_.dropped.push_back({e.name + "." + p.name, e.count});
        else if (p.role == Role::kTexcoords && texcoords_dropped_)
          stats_.dropped.push_back({e.name + "." + p.name, texcoords_dropped_});
    }
  }

  Status headerError(const std::string& msg) { return in_.errorAtLine(ErrorCode::kMalformed, msg); }

  Status parseHeader() {
    std::string_view line;
    SP_ASSIGN_OR_RETURN(bool got, in_.nextLine(line));
    if (!got || line != "ply") return headerError("not a PLY file (first line must be 'ply')");
    bool have_format = false;
    for (;;) {
      SP_ASSIGN_OR_RETURN(got, in_.nextLine(line));
      if (!got) return headerError("PLY header has no 'end_header'");
      if (in_.line() > 100000) return headerError("PLY header longer than 100000 lines");
      Tokenizer tok(line);
      std::string_view word;
      if (!tok.next(word)) continue;
      if (word == "comment") {
        // `comment TextureFile NAME` (MeshLab's, Metashape's): the image the texture coordinates index.
        std::string_view key;
        if (tok.next(key) && key == "TextureFile") {
          std::string_view rest = tok.rest();  // the name as written, spaces inside kept
          const auto blank = [](char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; };
          while (!rest.empty() && blank(rest.front())) rest.remove_prefix(1);
          while (!rest.empty() && blank(rest.back())) rest.remove_suffix(1);
          if (rest.empty()) continue;
          const std::string name(rest);
          if (texture_files_ == 0) texture_file_ = name;
          else if (name != texture_file_) ++other_textures_;
          ++texture_files_;
        }
        continue;
      }
      if (word == "obj_info") continue;
      if (word == "end_header") break;
      if (word == "format") {
        std::string_view enc, ver;
        if (!tok.next(enc) || !tok.next(ver)) return headerError("malformed 'format' line");
        if (enc == "ascii") encoding_ = Encoding::kAscii;
        else if (enc == "binary_little_endian") encoding_ = Encoding::kLittle;
        else if (enc == "binary_big_endian") encoding_ = Encoding::kBig;
        else return headerError("unknown PLY format '" + std::string(enc) + "'");
        if (ver != "1.0") return headerError("unsupported PLY version '" + std::string(ver) + "'");
        stats_.format_detail = "PLY " + std::string(enc);
        have_format = true;
      } else if (word == "element") {
        std::string_view name, count;
        int64_t n = 0;
        if (!tok.next(name) || !tok.next(count) || !parseInt64(count, n) || n < 0)
          return headerError("malformed 'element' line");
        Element e;
        e.name = std::string(name);
        e.count = static_cast<uint64_t>(n);
        if (name == "vertex") e.kind = ElementKind::kVertex;
        else if (name == "face") e.kind = ElementKind::kFace;
        else if (name == "tristrips") e.kind = ElementKind::kTristrips;
        for (const auto& other : elements_)
          if (other.name == e.name) return headerError("element '" + e.name + "' declared twice");
        if (e.kind == ElementKind::kVertex && e.count > kMaxVertices)
          return in_.errorAtLine(ErrorCode::kLimitExceeded,
                                 "PLY declares " + std::to_string(e.count) + " vertices (limit 2^32-2)");
        elements_.push_back(std::move(e));
      } else if (word == "property") {
        if (elements_.empty()) return headerError("'property' before any 'element'");
        Property p;
        std::string_view type, name;
        if (!tok.next(type)) return headerError("malformed 'property' line");
        if (type == "list") {
          std::string_view ct, it;
          if (!tok.next(ct) || !tok.next(it) || !tok.next(name)) return headerError("malformed 'property list' line");
          if (!parseType(ct, p.count_type) || !parseType(it, p.type))
            return headerError("unknown PLY type in 'property list'");
          if (isFloatType(p.count_type)) return headerError("list count type must be an integer type");
          p.is_list = true;
        } else {
          if (!parseType(type, p.type)) return headerError("unknown PLY type '" + std::string(type) + "'");
          if (!tok.next(name)) return headerError("malformed 'property' line");
        }
        p.name = std::string(name);
        Element& e = elements_.back();
        for (const auto& other : e.props)
          if (other.name == p.name) return headerError("property '" + p.name + "' declared twice");
        if (e.kind == ElementKind::kVertex && !p.is_list) {
          p.role = vertexRole(p.name);
          // Any other scalar is kept (at most 255 of them, with a name a container can hold; else dropped).
          if (p.role == Role::kNone && validScalarName(p.name) && scalar_count_ < 255) {
            p.role = Role::kScalar;
            ++scalar_count_;
          }
        }
        if ((e.kind == ElementKind::kFace && (p.name == "vertex_indices" || p.name == "vertex_index")) ||
            (e.kind == ElementKind::kTristrips && p.name == "vertex_indices")) {
          if (!p.is_list) return headerError("'" + p.name + "' must be a list property");
          if (isFloatType(p.type)) return headerError("'" + p.name + "' must have an integer item type");
          p.role = Role::kIndices;
        }
        e.props.push_back(std::move(p));
      } else {
        return headerError("unknown PLY header keyword '" + std::string(word) + "'");
      }
    }
    if (!have_format) return headerError("PLY header has no 'format' line");
    // A face's `texcoord` list of float32 is kept (u and v per corner) unless the vertices have a texture
    // coordinate pair of their own.
    std::vector<ScalarChannel> vertex_channels;
    for (const auto& e : elements_)
      if (e.kind == ElementKind::kVertex)
        for (const auto& p : e.props)
          if (p.role == Role::kScalar) vertex_channels.push_back({p.name, ScalarType(uint8_t(p.type) + 1)});
    // (Nor when the vertices have a channel named u or v, or too many channels for two more.)
    bool named_uv = false;
    for (const ScalarChannel& c : vertex_channels) named_uv |= c.name == kTexcoordU || c.name == kTexcoordV;
    if (options_.texture_coordinates && !findTexcoords(vertex_channels) && !named_uv && vertex_channels.size() <= 253)
      for (auto& e : elements_)
        if (e.kind == ElementKind::kFace)
          for (auto& p : e.props)
            if (p.is_list && p.name == "texcoord" && p.type == PlyType::kFloat32) p.role = Role::kTexcoords;
    for (auto& e : elements_) {
      bool has_indices = false;
      for (auto& p : e.props) {
        p.offset = e.record_size;
        if (p.is_list) {
          e.fixed_size = false;
          e.min_record_bytes += typeSize(p.count_type);
        } else {
          e.record_size += typeSize(p.type);
          e.min_record_bytes += typeSize(p.type);
        }
        has_indices |= p.role == Role::kIndices;
      }
      if ((e.kind == ElementKind::kFace || e.kind == ElementKind::kTristrips) && !has_indices)
        return headerError("PLY element '" + e.name + "' has no 'vertex_indices' list");
      if (encoding_ == Encoding::kAscii) e.min_record_bytes = std::max<size_t>(1, 2 * e.props.size()) - 1;
    }
    if (encoding_ != Encoding::kAscii) SP_RETURN_IF_ERROR(in_.consumePendingLineFeed());
    return Status::ok();
  }

  // A declared count that cannot fit in the bytes left is rejected before anything is allocated or read.
  Status checkCount(const Element& e) {
    const auto left = in_.remaining();
    if (!left || e.count == 0 || e.min_record_bytes == 0) return Status::ok();
    if (e.count > *left / e.min_record_bytes + 1)
      return in_.errorAtOffset(ErrorCode::kTruncated, "PLY element '" + e.name + "' declares " +
                                                          std::to_string(e.count) + " records, but only " +
                                                          std::to_string(*left) + " bytes remain");
    return Status::ok();
  }

  // ---- scalar access ---------------------------------------------------------------------------------------

  // Binary: decodes one value of type t from raw bytes.
  double decodeBinary(const uint8_t* p, PlyType t) const {
    uint8_t b[8];
    const size_t n = typeSize(t);
    std::memcpy(b, p, n);
    if (encoding_ == Encoding::kBig) std::reverse(b, b + n);
    switch (t) {
      case PlyType::kInt8: return static_cast<int8_t>(b[0]);
      case PlyType::kUint8: return b[0];
      case PlyType::kInt16: {
        int16_t v;
        std::memcpy(&v, b, 2);
        return v;
      }
      case PlyType::kUint16: {
        uint16_t v;
        std::memcpy(&v, b, 2);
        return v;
      }
      case PlyType::kInt32: {
        int32_t v;
        std::memcpy(&v, b, 4);
        return v;
      }
      case PlyType::kUint32: {
        uint32_t v;
        std::memcpy(&v, b, 4);
        return v;
      }
      case PlyType::kFloat32: {
        float v;
        std::memcpy(&v, b, 4);
        return v;
      }
      case PlyType::kFloat64: {
        double v;
        std::memcpy(&v, b, 8);
        return v;
      }
    }
    return 0;
  }

  Status nextToken(std::string_view& token) {
    while (!tokens_.next(token)) {
      SP_ASSIGN_OR_RETURN(bool got, in_.nextLine(line_));
      if (!got) return in_.errorAtLine(ErrorCode::kTruncated, "unexpected end of file in PLY ascii data");
      tokens_ = Tokenizer(line_);
    }
    return Status::ok();
  }

  // Reads one value of type t (either encoding).
  Status readValue(PlyType t, double& v) {
    if (encoding_ == Encoding::kAscii) {
      std::string_view tok;
      SP_RETURN_IF_ERROR(nextToken(tok));
      if (isFloatType(t)) {
        if (!parseDouble(tok, v))
          return in_.errorAtLine(ErrorCode::kMalformed, "expected a number, found '" + std::string(tok) + "'");
      } else {
        int64_t i = 0;
        if (!parseInt64(tok, i))
          return in_.errorAtLine(ErrorCode::kMalformed, "expected an integer, found '" + std::string(tok) + "'");
        v = static_cast<double>(i);
      }
      return Status::ok();
    }
    uint8_t b[8];
    SP_RETURN_IF_ERROR(in_.read(b, typeSize(t)));
    v = decodeBinary(b, t);
    return Status::ok();
  }

  Status placeError(ErrorCode code, const std::string& msg) {
    return encoding_ == Encoding::kAscii ? in_.errorAtLine(code, msg) : in_.errorAtOffset(code, msg);
  }

  Status readListCount(const Property& p, uint64_t& count) {
    double c = 0;
    SP_RETURN_IF_ERROR(readValue(p.count_type, c));
    if (c < 0) return placeError(ErrorCode::kMalformed, "negative list length");
    count = static_cast<uint64_t>(c);
    return Status::ok();
  }

  // ---- elements ------------------------------------------------------------------------------------------

  Status readElement(const Element& e) {
    switch (e.kind) {
      case ElementKind::kVertex: return readVertices(e);
      case ElementKind::kFace: return readFaces(e, false);
      case ElementKind::kTristrips: return readFaces(e, true);
      case ElementKind::kOther: return skipElement(e);
    }
    return Status::ok();
  }

  Status skipElement(const Element& e) {
    std::vector<uint8_t> scratch(e.fixed_size ? e.record_size : 8);
    for (uint64_t r = 0; r < e.count; ++r) {
      if (encoding_ != Encoding::kAscii && e.fixed_size) {
        SP_RETURN_IF_ERROR(in_.read(scratch.data(), e.record_size));
        continue;
      }
      for (const auto& p : e.props) {
        double v;
        uint64_t n = 1;
        if (p.is_list) SP_RETURN_IF_ERROR(readListCount(p, n));
        for (uint64_t i = 0; i < n; ++i) SP_RETURN_IF_ERROR(readValue(p.type, v));
      }
    }
    return Status::ok();
  }

  // A scalar property's value as its bit pattern (ScalarValues' words at `w`), exactly: binary bytes as they are
  // (byte-swapped from big endian), ASCII parsed at the property's type (a float property's text rounded once, to
  // float). `raw`: the value's bytes in a fixed-size binary record, else null (read from the input).
  Status readScalarBits(const Property& p, const uint8_t* raw, uint32_t* w) {
    const size_t n = typeSize(p.type);
    if (encoding_ != Encoding::kAscii) {
      uint8_t b[8];
      if (raw) std::memcpy(b, raw, n);
      else SP_RETURN_IF_ERROR(in_.read(b, n));
      if (encoding_ == Encoding::kBig) std::reverse(b, b + n);
      uint64_t bits = 0;
      for (size_t i = 0; i < n; ++i) bits |= uint64_t(b[i]) << (8 * i);
      w[0] = uint32_t(bits);
      if (n == 8) w[1] = uint32_t(bits >> 32);
      return Status::ok();
    }
    std::string_view tok;
    SP_RETURN_IF_ERROR(nextToken(tok));
    const auto bad = [&](const char* what) {
      return in_.errorAtLine(ErrorCode::kMalformed,
                             "property '" + p.name + "': expected " + what + ", found '" + std::string(tok) + "'");
    };
    if (p.type == PlyType::kFloat32) {
      float f = 0;
      const char* b = tok.data() + (!tok.empty() && tok[0] == '+');
      const auto [ptr, ec] = std::from_chars(b, tok.data() + tok.size(), f);
      if (ptr != tok.data() + tok.size()) return bad("a number");
      if (ec == std::errc::result_out_of_range) {  // beyond float's range: infinity or zero, as strtof gives
        double d = 0;
        if (!parseDouble(tok, d)) return bad("a number");
        f = static_cast<float>(d);
      } else if (ec != std::errc()) {
        return bad("a number");
      }
      std::memcpy(w, &f, 4);
      return Status::ok();
    }
    if (p.type == PlyType::kFloat64) {
      double d = 0;
      if (!parseDouble(tok, d)) return bad("a number");
      uint64_t bits = 0;
      std::memcpy(&bits, &d, 8);
      w[0] = uint32_t(bits), w[1] = uint32_t(bits >> 32);
      return Status::ok();
    }
    int64_t i = 0;
    if (!parseInt64(tok, i)) return bad("an integer");
    const int bits = int(8 * n);
    const bool is_signed = p.type == PlyType::kInt8 || p.type == PlyType::kInt16 || p.type == PlyType::kInt32;
    const int64_t lo = is_signed ? -(int64_t{1} << (bits - 1)) : 0;
    const int64_t hi = is_signed ? (int64_t{1} << (bits - 1)) - 1 : (int64_t{1} << bits) - 1;
    if (i < lo || i > hi)
      return bad(("an integer of type " + std::string(scalarTypeName(ScalarType(uint8_t(p.type) + 1)))).c_str());
    w[0] = uint32_t(uint64_t(i) & (bits == 32 ? 0xFFFFFFFFull : (uint64_t{1} << bits) - 1));
    return Status::ok();
  }

  Status readVertices(const Element& e) {
    std::vector<uint8_t> record(e.record_size);
    std::vector<uint32_t> row(stride_ + (plan_ && plan_->textures ? 2 : 0));
    for (uint64_t r = 0; r < e.count; ++r) {
      Vec3d pos{0, 0, 0};
      Vec3f nrm{0, 0, 0};
      Rgba8 col{255, 255, 255, 255};
      const bool fast = encoding_ != Encoding::kAscii && e.fixed_size;
      if (fast) SP_RETURN_IF_ERROR(in_.read(record.data(), e.record_size));
      size_t word = 0;
      for (size_t k = 0; k < e.props.size(); ++k) {
        const Property& p = e.props[k];
        double v = 0;
        if (p.is_list) {  // a list on a vertex: skip it
          uint64_t n = 0;
          SP_RETURN_IF_ERROR(readListCount(p, n));
          for (uint64_t i = 0; i < n; ++i) SP_RETURN_IF_ERROR(readValue(p.type, v));
          continue;
        }
        if (p.role == Role::kScalar) {
          SP_RETURN_IF_ERROR(readScalarBits(p, fast ? record.data() + p.offset : nullptr, row.data() + word));
          word += p.type == PlyType::kFloat64 ? 2 : 1;
          continue;
        }
        if (fast) v = decodeBinary(record.data() + p.offset, p.type);
        else SP_RETURN_IF_ERROR(readValue(p.type, v));
        switch (p.role) {
          case Role::kX: pos[0] = v; break;
          case Role::kY: pos[1] = v; break;
          case Role::kZ: pos[2] = v; break;
          case Role::kNx: nrm[0] = static_cast<float>(v); break;
          case Role::kNy: nrm[1] = static_cast<float>(v); break;
          case Role::kNz: nrm[2] = static_cast<float>(v); break;
          case Role::kRed: col[0] = colorByte(v, p.type); break;
          case Role::kGreen: col[1] = colorByte(v, p.type); break;
          case Role::kBlue: col[2] = colorByte(v, p.type); break;
          case Role::kAlpha: col[3] = colorByte(v, p.type); break;
          default: break;
        }
      }
      if (!std::isfinite(pos[0]) || !std::isfinite(pos[1]) || !std::isfinite(pos[2]))
        return placeError(ErrorCode::kMalformed, "vertex " + std::to_string(r) + " has a NaN or infinite coordinate");
      if (!std::isfinite(nrm[0]) || !std::isfinite(nrm[1]) || !std::isfinite(nrm[2]))
        return placeError(ErrorCode::kMalformed, "vertex " + std::to_string(r) + " has a NaN or infinite normal");
      if (!plan_) {
        SP_RETURN_IF_ERROR(out_->addVertex(pos, nrm, col, row.data()));
        continue;
      }
      // The vertex with its first corner's texture coordinates, then its wedges (the plan's, in order).
      first_output_.push_back(uint32_t(out_->vertices()));
      auto add = [&](uint32_t key) {
        const auto uv = plan_->words(key);
        if (plan_->textures) row[stride_] = uv[0], row[stride_ + 1] = uv[1];
        return out_->addVertex(pos, nrm, col, row.data());
      };
      SP_RETURN_IF_ERROR(add(r < plan_->first.size() ? plan_->first[r] : WedgePlan::kNone));
      for (; next_wedge_ < plan_->wedges.size() && plan_->wedges[next_wedge_].first == r; ++next_wedge_) {
        if (out_->vertices() >= kMaxVertices)
          return placeError(ErrorCode::kLimitExceeded, "more than 2^32-2 vertices with the seams' wedges");
        SP_RETURN_IF_ERROR(add(plan_->wedges[next_wedge_].second));
      }
    }
    return out_->flushVertices();
  }

  Status readIndex(PlyType t, int64_t& index) {
    double v = 0;
    SP_RETURN_IF_ERROR(readValue(t, v));
    index = static_cast<int64_t>(v);
    return Status::ok();
  }

  Status checkIndex(int64_t index, uint64_t record) {
    if (index < 0 || static_cast<uint64_t>(index) >= vertex_count_)
      return placeError(ErrorCode::kMalformed, "face " + std::to_string(record) + " has vertex index " +
                                                   std::to_string(index) + " outside [0, " +
                                                   std::to_string(vertex_count_) + ")");
    return Status::ok();
  }

  Status readFaces(const Element& e, bool strips) {
    std::vector<uint32_t> poly;
    std::vector<float> uv;  // the face's texcoord list
    for (uint64_t r = 0; r < e.count; ++r) {
      bool have_uv = false;
      poly.clear();
      for (const auto& p : e.props) {
        uint64_t n = 1;
        if (p.is_list) SP_RETURN_IF_ERROR(readListCount(p, n));
        if (p.role == Role::kTexcoords) {
          if (n > 2 * uint64_t(kMaxPolygonCorners))
            return placeError(ErrorCode::kLimitExceeded, "face " + std::to_string(r) + " has " + std::to_string(n) +
                                                             " texture coordinate values");
          uv.resize(n);
          for (uint64_t i = 0; i < n; ++i) {
            double v = 0;
            SP_RETURN_IF_ERROR(readValue(p.type, v));
            uv[i] = static_cast<float>(v);
          }
          have_uv = n > 0;  // an empty list: the face has none
          continue;
        }
        if (p.role != Role::kIndices) {
          double v;
          for (uint64_t i = 0; i < n; ++i) SP_RETURN_IF_ERROR(readValue(p.type, v));
          continue;
        }
        if (strips) {
          SP_RETURN_IF_ERROR(readStrip(p, n, r));
          continue;
        }
        if (n < 3)
          return placeError(ErrorCode::kMalformed, "face " + std::to_string(r) + " has " + std::to_string(n) +
                                                       " vertices (at least 3 needed)");
        if (n > kMaxPolygonCorners)
          return placeError(ErrorCode::kLimitExceeded, "face " + std::to_string(r) + " has " + std::to_string(n) +
                                                           " vertices (limit " + std::to_string(kMaxPolygonCorners) +
                                                           ")");
        SP_RETURN_IF_ERROR(readIndexList(p.type, n, r, poly));
      }
      if (strips || poly.empty()) continue;
      if (have_uv && (plan_ || planning_)) {
        SP_RETURN_IF_ERROR(texturedCorners(r, poly, uv));
      } else if (have_uv) {
        ++texcoords_dropped_;  // read without a plan (a FIFO, or readPly called alone): listed
      } else if (plan_) {      // the vertices' first wedges
        for (uint32_t& v : poly) v = first_output_[v];
      }
      if (poly.size() > 3) ++stats_.polygons;
      for (size_t i = 1; i + 1 < poly.size(); ++i)
        SP_RETURN_IF_ERROR(out_->addTriangle({poly[0], poly[i], poly[i + 1]}));
    }
    return out_->flushTriangles();
  }

  // A face's corners with their texture coordinates (u, v per corner): the first read plans the wedges, the second
  // names them (poly: the vertices' indices in the file, then the delivered vertices').
  Status texturedCorners(uint64_t r, std::vector<uint32_t>& poly, const std::vector<float>& uv) {
    if (uv.size() != 2 * poly.size())
      return placeError(ErrorCode::kMalformed, "face " + std::to_string(r) + " has " + std::to_string(uv.size()) +
                                                   " texture coordinate values for " + std::to_string(poly.size()) +
                                                   " corners (2 per corner)");
    for (size_t i = 0; i < poly.size(); ++i) {
      const std::array<float, 2> value{uv[2 * i], uv[2 * i + 1]};
      if (planning_) {
        // Sized when the vertices have been read (a declared count is not trusted for allocation).
        if (planning_->first.size() != vertex_count_) planning_->resizeVertices(vertex_count_);
        if (planning_->keys.size() >= kMaxVertices)
          return placeError(ErrorCode::kLimitExceeded, "more than 2^32-2 distinct texture coordinates");
        planning_->addCorner(poly[i], planning_->addUv(value), WedgePlan::kNone);
        continue;
      }
      if (!plan_) continue;
      const std::optional<uint32_t> wedge = plan_->wedgeOf(poly[i], plan_->uvId(value), WedgePlan::kNone);
      if (!wedge || poly[i] >= first_output_.size())
        return makeError(ErrorCode::kIo, in_.name() + ": the file changed between its two reads");
      poly[i] = first_output_[poly[i]] + *wedge;
    }
    return Status::ok();
  }

  // Reads a face's n indices into `poly`, checking each. Binary lists are read in one call and converted with the
  // type dispatch outside the loop (the common `list uchar int` face costs one read).
  Status readIndexList(PlyType t, uint64_t n, uint64_t record, std::vector<uint32_t>& poly) {
    poly.resize(n);
    if (encoding_ == Encoding::kAscii) {
      for (uint64_t i = 0; i < n; ++i) {
        int64_t idx = 0;
        SP_RETURN_IF_ERROR(readIndex(t, idx));
        SP_RETURN_IF_ERROR(checkIndex(idx, record));
        poly[i] = static_cast<uint32_t>(idx);
      }
      return Status::ok();
    }
    const size_t size = typeSize(t);
    list_bytes_.resize(n * size);
    SP_RETURN_IF_ERROR(in_.read(list_bytes_.data(), list_bytes_.size()));
    const bool swap = encoding_ == Encoding::kBig;
    auto convert = [&](auto tag) -> Status {
      using T = decltype(tag);
      for (uint64_t i = 0; i < n; ++i) {
        T v;
        std::memcpy(&v, list_bytes_.data() + i * sizeof(T), sizeof(T));
        if (swap) v = byteswap(v);
        const int64_t idx = static_cast<int64_t>(v);
        if (idx < 0 || static_cast<uint64_t>(idx) >= vertex_count_) return checkIndex(idx, record);
        poly[i] = static_cast<uint32_t>(idx);
      }
      return Status::ok();
    };
    switch (t) {
      case PlyType::kInt8: return convert(int8_t{});
      case PlyType::kUint8: return convert(uint8_t{});
      case PlyType::kInt16: return convert(int16_t{});
      case PlyType::kUint16: return convert(uint16_t{});
      case PlyType::kInt32: return convert(int32_t{});
      case PlyType::kUint32: return convert(uint32_t{});
      default: return placeError(ErrorCode::kMalformed, "face indices must be integers");
    }
  }

  template <typename T>
  static T byteswap(T v) {
    uint8_t b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    std::reverse(b, b + sizeof(T));
    std::memcpy(&v, b, sizeof(T));
    return v;
  }

  // A strip v0 v1 v2 v3 ... gives (v0 v1 v2), (v2 v1 v3), (v2 v3 v4), ...: odd triangles are flipped so that all
  // keep one orientation. -1 restarts the strip.
  Status readStrip(const Property& p, uint64_t n, uint64_t record) {
    uint32_t a = 0, b = 0;
    int have = 0;
    bool odd = false;
    for (uint64_t i = 0; i < n; ++i) {
      int64_t idx = 0;
      SP_RETURN_IF_ERROR(readIndex(p.type, idx));
      if (idx == -1) {
        have = 0;
        odd = false;
        continue;
      }
      SP_RETURN_IF_ERROR(checkIndex(idx, record));
      const uint32_t c = plan_ ? first_output_[size_t(idx)] : static_cast<uint32_t>(idx);
      if (have < 2) {
        (have == 0 ? a : b) = c;
        ++have;
        continue;
      }
      SP_RETURN_IF_ERROR(out_->addTriangle(odd ? Triangle{b, a, c} : Triangle{a, b, c}));
      odd = !odd;
      a = b;
      b = c;
    }
    return Status::ok();
  }

  Scanner& in_;
  MeshSink& sink_;
  ReadOptions options_;
  const WedgePlan* plan_ = nullptr;
  WedgePlan* planning_ = nullptr;
  std::vector<uint32_t> first_output_;  // with a plan: per vertex in the file, its first delivered vertex's index
  size_t next_wedge_ = 0;               // the plan's next wedge to deliver
  uint64_t texcoords_dropped_ = 0;      // faces whose texcoord list was read past (no plan)
  ChunkBuffer* out_ = nullptr;
  Encoding encoding_ = Encoding::kAscii;
  std::vector<Element> elements_;
  uint64_t vertex_count_ = 0;
  size_t scalar_count_ = 0;  // vertex properties kept as scalar channels
  size_t stride_ = 0;        // their words per vertex
  ReadStats stats_;
  std::string texture_file_;  // the first `comment TextureFile`'s name
  uint64_t texture_files_ = 0, other_textures_ = 0;
  std::string_view line_;
  Tokenizer tokens_{std::string_view()};
  std::vector<uint8_t> list_bytes_;
};

}  // namespace

Result<ReadStats> readPly(Scanner& in, MeshSink& sink, const ReadOptions& options, const WedgePlan* plan) {
  PlyParser parser(in, sink, options, plan);
  return parser.run();
}

namespace {
// The first read's sink: keeps nothing.
class DiscardSink : public MeshSink {
 public:
  Status vertices(std::span<const Vec3d>, std::span<const Vec3f>, std::span<const Rgba8>, uint8_t,
                  const ScalarChunk&) override {
    return Status::ok();
  }
  Status triangles(std::span<const Triangle>) override { return Status::ok(); }
  Status vertexNormals(uint64_t, std::span<const Vec3f>) override { return Status::ok(); }
};
}  // namespace

Result<WedgePlan> planPlyWedges(Scanner& in, const ReadOptions& options) {
  DiscardSink discard;
  WedgePlan plan;
  PlyParser parser(in, discard, options, nullptr, &plan);
  return parser.plan();
}

}  // namespace scanpress
