// scanpress-compare --rd: the lossy anchors of issue 19 and pm's points against their lower envelope.
//
// Every point is measured the same way (jobs/measure.h, symmetric, one sample per original triangle plus the
// vertices) against the scan as read, and its size is given in bits per ORIGINAL vertex, so that a simplified
// result and a full-resolution one are on one axis.
#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>
#include <meshoptimizer.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <tuple>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include "bench/compare.h"
#include "engine/codecs/codec.h"
#include "jobs/commands.h"
#include "jobs/measure.h"
#include "jobs/pipeline.h"

namespace scanpress {
namespace {

namespace fs = std::filesystem;

// Draco -cl `cl` at -qp `qp` on float positions; fills `out` with the decoded mesh and returns the byte count
// (0 on failure).
size_t dracoRoundTrip(const std::vector<Vec3d>& positions, const std::vector<Triangle>& tris, int qp, int cl,
                      Mesh& out) {
  draco::Mesh dm;
  dm.set_num_points(static_cast<uint32_t>(positions.size()));
  draco::GeometryAttribute ga;
  ga.Init(draco::GeometryAttribute::POSITION, nullptr, 3, draco::DT_FLOAT32, false, 12, 0);
  const int att = dm.AddAttribute(ga, true, static_cast<uint32_t>(positions.size()));
  for (size_t i = 0; i < positions.size(); ++i) {
    const float f[3] = {static_cast<float>(positions[i][0]), static_cast<float>(positions[i][1]),
                        static_cast<float>(positions[i][2])};
    dm.attribute(att)->SetAttributeValue(draco::AttributeValueIndex(static_cast<uint32_t>(i)), f);
  }
  for (const auto& t : tris) dm.AddFace({draco::PointIndex(t[0]), draco::PointIndex(t[1]), draco::PointIndex(t[2])});
  draco::Encoder enc;
  enc.SetAttributeQuantization(draco::GeometryAttribute::POSITION, qp);
  enc.SetSpeedOptions(10 - cl, 10 - cl);
  enc.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
  draco::EncoderBuffer buffer;
  if (!enc.EncodeMeshToBuffer(dm, &buffer).ok()) return 0;
  draco::DecoderBuffer in;
  in.Init(buffer.data(), buffer.size());
  draco::Decoder dec;
  auto r = dec.DecodeMeshFromBuffer(&in);
  if (!r.ok()) return 0;
  const auto& decoded = *r.value();
  const draco::PointAttribute* pa = decoded.GetNamedAttribute(draco::GeometryAttribute::POSITION);
  out = Mesh{};
  out.positions.resize(decoded.num_points());
  for (uint32_t i = 0; i < decoded.num_points(); ++i) {
    float f[3];
    pa->GetMappedValue(draco::PointIndex(i), f);
    out.positions[i] = {f[0], f[1], f[2]};
  }
  for (uint32_t f = 0; f < decoded.num_faces(); ++f) {
    const auto& face = decoded.face(draco::FaceIndex(f));
    out.triangles.push_back({face[0].value(), face[1].value(), face[2].value()});
  }
  return buffer.size();
}

// The triangles of the mesh that use referenced vertices only, compacted.
void compact(const std::vector<Vec3d>& positions, const std::vector<uint32_t>& indices, std::vector<Vec3d>& pos_out,
             std::vector<Triangle>& tris_out) {
  std::vector<uint32_t> remap(positions.size(), UINT32_MAX);
  pos_out.clear();
  tris_out.clear();
  for (size_t i = 0; i + 2 < indices.size(); i += 3) {
    Triangle t;
    for (int k = 0; k < 3; ++k) {
      uint32_t& r = remap[indices[i + k]];
      if (r == UINT32_MAX) r = static_cast<uint32_t>(pos_out.size()), pos_out.push_back(positions[indices[i + k]]);
      t[k] = r;
    }
    tris_out.push_back(t);
  }
}

// A column-major 4x4 transform.
using Mat4 = std::array<double, 16>;
Mat4 identity() { return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}; }
Mat4 multiply(const Mat4& a, const Mat4& b) {
  Mat4 c{};
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      for (int k = 0; k < 4; ++k) c[j * 4 + i] += a[k * 4 + i] * b[j * 4 + k];
  return c;
}
Mat4 nodeMatrix(const nlohmann::json& node) {
  if (node.contains("matrix")) {
    Mat4 m;
    for (int i = 0; i < 16; ++i) m[i] = node["matrix"][i].get<double>();
    return m;
  }
  Mat4 t = identity(), r = identity(), s = identity();
  if (node.contains("translation"))
    for (int i = 0; i < 3; ++i) t[12 + i] = node["translation"][i].get<double>();
  if (node.contains("rotation")) {
    const double x = node["rotation"][0], y = node["rotation"][1], z = node["rotation"][2], w = node["rotation"][3];
    r = {1 - 2 * (y * y + z * z),
         2 * (x * y + z * w),
         2 * (x * z - y * w),
         0,
         2 * (x * y - z * w),
         1 - 2 * (x * x + z * z),
         2 * (y * z + x * w),
         0,
         2 * (x * z + y * w),
         2 * (y * z - x * w),
         1 - 2 * (x * x + y * y),
         0,
         0,
         0,
         0,
         1};
  }
  if (node.contains("scale"))
    for (int i = 0; i < 3; ++i) s[i * 5] = node["scale"][i].get<double>();
  return multiply(t, multiply(r, s));
}

// Reads the triangles of every mesh instance of an uncompressed .glb (positions as float, or integers with
// KHR_mesh_quantization, dequantized by the node transforms) into `out`. False when the file is not understood.
bool readGlb(const std::string& path, Mesh& out) {
  std::ifstream f(path, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  auto u32 = [&](size_t at) {
    uint32_t v = 0;
    if (at + 4 <= bytes.size()) std::memcpy(&v, bytes.data() + at, 4);
    return v;
  };
  if (bytes.size() < 20 || u32(0) != 0x46546C67u) return false;
  const uint32_t json_len = u32(12);
  if (20 + size_t{json_len} + 8 > bytes.size()) return false;
  const auto doc = nlohmann::json::parse(bytes.begin() + 20, bytes.begin() + 20 + json_len, nullptr, false);
  if (doc.is_discarded()) return false;
  const size_t bin = 20 + json_len + 8, bin_len = u32(20 + json_len);
  if (bin + bin_len > bytes.size()) return false;
  // Reads accessor `a` as doubles (components per element in `n`); normalized integers are mapped as glTF says.
  auto accessor = [&](int a, int& n) {
    std::vector<double> v;
    const auto& acc = doc["accessors"][a];
    const auto& view = doc["bufferViews"][acc["bufferView"].get<int>()];
    const std::string type = acc["type"];
    n = type == "SCALAR" ? 1 : type == "VEC3" ? 3 : type == "VEC4" ? 4 : 2;
    const int ct = acc["componentType"];
    const size_t size = ct == 5126 || ct == 5125 ? 4 : ct == 5123 || ct == 5122 ? 2 : 1;
    const size_t stride = view.value("byteStride", size * n);
    const size_t start = bin + view.value("byteOffset", size_t{0}) + acc.value("byteOffset", size_t{0});
    const bool normalized = acc.value("normalized", false);
    const size_t count = acc["count"];
    for (size_t i = 0; i < count; ++i)
      for (int c = 0; c < n; ++c) {
        const size_t at = start + i * stride + c * size;
        if (at + size > bin + bin_len) return std::vector<double>{};
        double x = 0;
        const char* p = bytes.data() + at;
        if (ct == 5126) {
          float t;
          std::memcpy(&t, p, 4);
          x = t;
        } else if (ct == 5125) {
          uint32_t t;
          std::memcpy(&t, p, 4);
          x = t;
        } else if (ct == 5123) {
          uint16_t t;
          std::memcpy(&t, p, 2);
          x = normalized ? t / 65535.0 : t;
        } else if (ct == 5122) {
          int16_t t;
          std::memcpy(&t, p, 2);
          x = normalized ? std::max(t / 32767.0, -1.0) : t;
        } else if (ct == 5121) {
          uint8_t t = static_cast<uint8_t>(*p);
          x = normalized ? t / 255.0 : t;
        } else {
          int8_t t = static_cast<int8_t>(*p);
          x = normalized ? std::max(t / 127.0, -1.0) : t;
        }
        v.push_back(x);
      }
    return v;
  };
  // World transform of every node (parents through `children`).
  const auto& nodes = doc.value("nodes", nlohmann::json::array());
  std::vector<int> parent(nodes.size(), -1);
  for (size_t i = 0; i < nodes.size(); ++i)
    for (const auto& c : nodes[i].value("children", nlohmann::json::array()))
      parent[c.get<int>()] = static_cast<int>(i);
  out = Mesh{};
  for (size_t i = 0; i < nodes.size(); ++i) {
    if (!nodes[i].contains("mesh")) continue;
    Mat4 m = nodeMatrix(nodes[i]);
    for (int p = parent[i]; p >= 0; p = parent[p]) m = multiply(nodeMatrix(nodes[p]), m);
    for (const auto& prim : doc["meshes"][nodes[i]["mesh"].get<int>()]["primitives"]) {
      if (prim.value("mode", 4) != 4 || !prim.contains("indices")) return false;
      int n = 0;
      const auto pos = accessor(prim["attributes"]["POSITION"].get<int>(), n);
      if (n != 3) return false;
      const auto idx = accessor(prim["indices"].get<int>(), n);
      const uint32_t base = static_cast<uint32_t>(out.positions.size());
      for (size_t v = 0; v + 2 < pos.size(); v += 3) {
        Vec3d w;
        for (int r = 0; r < 3; ++r) w[r] = m[r] * pos[v] + m[4 + r] * pos[v + 1] + m[8 + r] * pos[v + 2] + m[12 + r];
        out.positions.push_back(w);
      }
      for (size_t t = 0; t + 2 < idx.size(); t += 3)
        out.triangles.push_back({base + uint32_t(idx[t]), base + uint32_t(idx[t + 1]), base + uint32_t(idx[t + 2])});
    }
  }
  return !out.triangles.empty();
}

CompareRow baseRow(const std::string& scan, const Mesh& mesh, const std::string& family, const std::string& codec) {
  CompareRow r;
  r.scan = scan;
  r.family = family;
  r.codec = codec;
  r.anchor = family != "pm" && family != "prm";
  r.vertices = mesh.positions.size();
  r.triangles = mesh.triangles.size();
  return r;
}

std::string percent(double ratio) { return std::to_string(static_cast<int>(std::lround(ratio * 100))) + "%"; }

}  // namespace

void measureDecoded(const Mesh& original, const Mesh& decoded, const CompareOptions& opt, CompareRow& row) {
  if (!opt.rd) return;
  MeasureSettings ms;
  ms.samples_per_triangle = 1;
  auto r = measureMeshes(original, decoded, ms, opt.device);
  if (!r.isOk()) return;
  row.rms_rel = r->symmetric.rms / r->diagonal;
  row.max_rel = r->symmetric.max / r->diagonal;
}

void runAnchors(const std::string& scan, const Mesh& mesh, const CompareOptions& opt, std::vector<CompareRow>& rows) {
  for (int qp = 8; qp <= 12; ++qp) {
    CompareRow row = baseRow(scan, mesh, "draco qp", "draco -cl 10 -qp " + std::to_string(qp));
    row.bits = qp;
    Mesh decoded;
    row.bytes = dracoRoundTrip(mesh.positions, mesh.triangles, qp, 10, decoded);
    if (!row.bytes) continue;
    measureDecoded(mesh, decoded, opt, row);
    rows.push_back(row);
  }
  // meshoptimizer's simplifier (no error limit: the ratio decides), then Draco.
  std::vector<float> fpos;
  for (const auto& p : mesh.positions) fpos.insert(fpos.end(), {float(p[0]), float(p[1]), float(p[2])});
  std::vector<uint32_t> indices;
  for (const auto& t : mesh.triangles) indices.insert(indices.end(), t.begin(), t.end());
  for (double ratio : {0.5, 0.25, 0.1, 0.05}) {
    std::vector<uint32_t> out(indices.size());
    const size_t target = static_cast<size_t>(ratio * indices.size()) / 3 * 3;
    out.resize(meshopt_simplify(out.data(), indices.data(), indices.size(), fpos.data(), mesh.positions.size(),
                                3 * sizeof(float), target, 1.0f, 0, nullptr));
    std::vector<Vec3d> spos;
    std::vector<Triangle> stris;
    compact(mesh.positions, out, spos, stris);
    for (int qp = 10; qp <= 12; ++qp) {
      CompareRow row = baseRow(scan, mesh, "meshopt + draco",
                               "meshopt " + percent(ratio) + " + draco -cl 10 -qp " + std::to_string(qp));
      row.bits = qp;
      Mesh decoded;
      row.bytes = dracoRoundTrip(spos, stris, qp, 10, decoded);
      if (!row.bytes) continue;
      measureDecoded(mesh, decoded, opt, row);
      rows.push_back(row);
    }
  }
  // gltfpack: the size of `-si R -cc`; the geometry from the same run without compression (its meshopt compression is
  // lossless on the quantized attributes, so both hold the same triangles).
  if (std::system("command -v gltfpack >/dev/null 2>&1") != 0) {
    std::fprintf(stderr, "gltfpack not found (scripts/install-bench-deps.sh): no gltfpack anchors\n");
    return;
  }
  const fs::path dir = fs::temp_directory_path() / ("scanpress-compare-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string obj = (dir / "in.obj").string();
  {
    std::ofstream o(obj);
    char line[128];
    for (const auto& p : mesh.positions) {
      std::snprintf(line, sizeof line, "v %.9g %.9g %.9g\n", p[0], p[1], p[2]);
      o << line;
    }
    for (const auto& t : mesh.triangles) o << "f " << t[0] + 1 << " " << t[1] + 1 << " " << t[2] + 1 << "\n";
  }
  for (double ratio : {0.5, 0.25, 0.1, 0.05}) {
    CompareRow row = baseRow(scan, mesh, "gltfpack", "gltfpack -si " + std::to_string(ratio).substr(0, 4) + " -cc");
    row.bits = 14;  // gltfpack's default position quantization
    const std::string packed = (dir / "packed.glb").string(), plain = (dir / "plain.glb").string();
    const std::string si = std::to_string(ratio);
    if (std::system(("gltfpack -i '" + obj + "' -o '" + packed + "' -si " + si + " -cc >/dev/null 2>&1").c_str()) ||
        std::system(("gltfpack -i '" + obj + "' -o '" + plain + "' -si " + si + " >/dev/null 2>&1").c_str())) {
      std::fprintf(stderr, "gltfpack failed on %s\n", scan.c_str());
      continue;
    }
    Mesh decoded;
    if (!readGlb(plain, decoded)) {
      std::fprintf(stderr, "could not read gltfpack's output for %s\n", scan.c_str());
      continue;
    }
    row.bytes = fs::file_size(packed);
    measureDecoded(mesh, decoded, opt, row);
    rows.push_back(row);
  }
  fs::remove_all(dir);
}

// One lossy codec at several settings: `set` puts setting `x` into the options, `label` names the row.
void runLossySweep(const char* family, std::initializer_list<double> settings, void (*set)(CodecOptions&, double),
                   const char* label, const std::string& scan, const Mesh& mesh, const Grid& grid,
                   const QuantizedMesh& q, const CompareOptions& opt, std::vector<CompareRow>& rows) {
  const CodecInfo* codec = findCodec(family);
  if (!codec) return;
  const TileContext ctx{grid.bits, {}};
  for (double x : settings) {
    CodecOptions options;
    set(options, x);
    auto encoded = encodeMesh(*codec, ctx, q, options);
    if (!encoded.isOk()) {
      std::fprintf(stderr, "%s failed on %s: %s\n", family, scan.c_str(), encoded.status().toString().c_str());
      continue;
    }
    auto decoded = codec->decode(ctx, payloadVersion(*codec, *encoded), encoded->payload, limitsOf(encoded->decoded));
    if (!decoded.isOk()) continue;
    char name[96];
    std::snprintf(name, sizeof name, label, grid.bits, x);
    CompareRow row = baseRow(scan, mesh, family, name);
    row.bits = grid.bits;
    row.bytes = encoded->payload.size();
    Mesh m;
    for (const auto& p : decoded->positions) m.positions.push_back(grid.dequantize(p));
    m.triangles = decoded->triangles;
    measureDecoded(mesh, m, opt, row);
    rows.push_back(row);
  }
}

void runPmSweep(const std::string& scan, const Mesh& mesh, const Grid& grid, const QuantizedMesh& q,
                const CompareOptions& opt, std::vector<CompareRow>& rows) {
  if (!opt.rd) return;
  runLossySweep(
      "pm", {0.5, 1.0, 2.0, 4.0, 8.0}, [](CodecOptions& o, double e) { o.pm.max_error = e; },
      "pm %d bits, error %g cells", scan, mesh, grid, q, opt, rows);
  runLossySweep(
      "prm", {0.003, 0.004, 0.006, 0.008, 0.012}, [](CodecOptions& o, double g) { o.prm.grid = g; },
      "prm %d bits, grid %g", scan, mesh, grid, q, opt, rows);
}

// One family's points against the anchors' envelope; the target ratio (pm: issue 19, prm: issue 21).
void writeFamilyEnvelopeTable(std::ostream& md, const std::vector<CompareRow>& rows, const std::string& family) {
  std::map<std::string, std::vector<const CompareRow*>> by_scan;
  for (const auto& r : rows)
    if (!r.family.empty() && r.rms_rel > 0) by_scan[r.scan].push_back(&r);
  if (by_scan.empty()) return;
  md << "\n### " << family
     << " against the anchors' lower envelope (symmetric RMS in [5e-5, 3e-4] of the diagonal)\n\n"
     << "| scan | " << family << " points in range | median " << family
     << " bpv / envelope bpv | best ratio |\n|---|---:|---:|---:|\n";
  std::vector<double> medians;
  char line[256];
  for (const auto& [scan, pts] : by_scan) {
    // The envelope: anchors by RMS, keeping each that is smaller than every anchor with less error.
    std::vector<std::pair<double, double>> env;
    std::vector<const CompareRow*> anchors;
    for (const auto* r : pts)
      if (r->anchor) anchors.push_back(r);
    std::sort(anchors.begin(), anchors.end(), [](auto* a, auto* b) { return a->rms_rel < b->rms_rel; });
    for (const auto* a : anchors) {
      const double bpv = 8.0 * a->bytes / a->vertices;
      if (env.empty() || bpv < env.back().second) env.push_back({a->rms_rel, bpv});
    }
    std::vector<double> ratios;
    for (const auto* r : pts) {
      if (r->anchor || r->family != family || r->rms_rel < 5e-5 || r->rms_rel > 3e-4) continue;
      for (size_t i = 0; i + 1 < env.size(); ++i) {
        if (r->rms_rel < env[i].first || r->rms_rel > env[i + 1].first) continue;
        const double t = std::log(r->rms_rel / env[i].first) / std::log(env[i + 1].first / env[i].first);
        const double e = env[i].second + t * (env[i + 1].second - env[i].second);
        ratios.push_back(8.0 * r->bytes / r->vertices / e);
        break;
      }
    }
    if (ratios.empty()) continue;
    std::sort(ratios.begin(), ratios.end());
    medians.push_back(ratios[ratios.size() / 2]);
    std::snprintf(line, sizeof line, "| %s | %zu | %.3f | %.3f |\n", scan.c_str(), ratios.size(), medians.back(),
                  ratios.front());
    md << line;
  }
  if (medians.empty()) return;
  std::sort(medians.begin(), medians.end());
  std::snprintf(line, sizeof line, "\nMedian over scans: %.3f (target: at most %.1f)\n", medians[medians.size() / 2],
                family == "prm" ? 0.7 : 0.9);
  md << line;
}

void writeEnvelopeTable(std::ostream& md, const std::vector<CompareRow>& rows) {
  for (const char* family : {"pm", "prm"}) writeFamilyEnvelopeTable(md, rows, family);
}

namespace {

// The anchors' lower envelope of bits per original vertex against the error (`max`: Hausdorff, else RMS), at
// `error`: interpolated in log error between the envelope's points; beyond its least-error point, that point's bpv
// (every anchor with less error is larger). -1 when no anchor reaches `error`.
double envelopeAt(const std::vector<CompareRow>& anchors, bool max, double error) {
  std::vector<std::pair<double, double>> pts;  // (error, bpv)
  for (const auto& a : anchors) {
    const double e = max ? a.max_rel : a.rms_rel;
    if (a.anchor && e > 0 && a.vertices) pts.push_back({e, 8.0 * a.bytes / a.vertices});
  }
  std::sort(pts.begin(), pts.end());
  std::vector<std::pair<double, double>> env;
  for (const auto& p : pts)
    if (env.empty() || p.second < env.back().second) env.push_back(p);
  if (env.empty() || env.front().first > error) return -1;
  for (size_t i = 0; i + 1 < env.size(); ++i)
    if (error >= env[i].first && error < env[i + 1].first) {
      const double t = std::log(error / env[i].first) / std::log(env[i + 1].first / env[i].first);
      return env[i].second + t * (env[i + 1].second - env[i].second);
    }
  return env.back().second;
}

}  // namespace

void runTargets(const std::string& path, const Mesh& mesh, const std::vector<CompareRow>& anchors,
                const CompareOptions& opt, std::vector<TargetRow>& out) {
  const fs::path dir = fs::temp_directory_path() / ("scanpress-targets-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string scan = fs::path(path).filename().string();
  for (const bool max : {false, true})
    for (double e : {5e-5, 1e-4, 2e-4, 5e-4})
      for (const char* codec : {"pm", "edgebreaker"}) {
        TargetRow row;
        row.scan = scan;
        row.codec = codec;
        row.metric = max ? "max" : "rms";
        row.target = e;
        row.vertices = mesh.positions.size();
        row.anchor_bpv = envelopeAt(anchors, max, e);
        EncodeSettings s;
        s.input = path;
        s.output = (dir / "t.spz").string();
        s.codec = codec;
        s.threads = 1;
        s.keep_normals = s.keep_colors = false;  // positions only, as every anchor codes
        s.target.kind = TargetKind::kMaxError;
        s.target.max_error = e;
        s.target.metric = max ? ErrorMetric::kMax : ErrorMetric::kRms;
        const auto t0 = std::chrono::steady_clock::now();
        auto r = encodeFile(s, nullptr, opt.device);
        row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (!r.isOk()) {
          row.failure = r.status().toString();
        } else if (r->target && !r->target->met) {
          row.failure = r->target->status.toString();
        } else {
          row.encoded = true;
          row.bytes = r->bytes;
          row.bits = r->grid.bits;
          ContainerHeader header;
          auto q = decodeContainer(s.output, std::nullopt, &header);
          if (q.isOk()) {
            Mesh decoded;
            for (const auto& p : q->positions) decoded.positions.push_back(header.grid.dequantize(p));
            decoded.triangles = q->triangles;
            MeasureSettings ms;  // scanpress measure's defaults, another seed than the encoder's search
            ms.seed = 12345;
            auto m = measureMeshes(mesh, decoded, ms, opt.device);
            if (m.isOk()) row.achieved = (max ? m->symmetric.max : m->symmetric.rms) / m->diagonal;
          } else {
            row.failure = "decode: " + q.status().toString();
          }
        }
        std::fprintf(stderr, "  %s %s %s %.0e: %s %.3e, %.2f bpv (anchors %.2f), %.1f s\n", scan.c_str(), codec,
                     row.metric.c_str(), e, row.encoded ? "achieved" : "FAILED", row.achieved,
                     8.0 * row.bytes / std::max<uint64_t>(1, row.vertices), row.anchor_bpv, row.seconds);
        out.push_back(row);
      }
  fs::remove_all(dir);
}

void writeTargetsTable(std::ostream& md, const std::vector<TargetRow>& rows) {
  if (rows.empty()) return;
  md << "\n### Error targets: `encode --max-error E --error M`, measured independently (another seed)\n\n"
     << "bpv per original vertex; auto is the smaller of pm and edgebreaker (what `--codec auto` keeps); ratios to "
        "the anchors' lower envelope at E.\n\n"
     << "| scan | metric | target | pm achieved | pm bpv | edgebreaker bpv | anchors' bpv | pm ratio | auto ratio |\n"
     << "|---|---|---:|---:|---:|---:|---:|---:|---:|\n";
  // (scan, metric, target) -> codec -> row
  std::map<std::tuple<std::string, std::string, double>, std::map<std::string, const TargetRow*>> by;
  for (const auto& r : rows) by[{r.scan, r.metric, r.target}][r.codec] = &r;
  auto ok = [](const TargetRow* r) { return r && r->encoded && r->achieved >= 0 && r->achieved <= r->target; };
  auto bpv = [](const TargetRow* r) { return 8.0 * r->bytes / std::max<uint64_t>(1, r->vertices); };
  auto fmt = [](double x, const char* f) {
    char b[32];
    std::snprintf(b, sizeof b, f, x);
    return std::string(b);
  };
  int total = 0, met_pm = 0, met_eb = 0;
  std::map<std::string, std::vector<double>> ratios;  // "pm rms", "auto max", ...
  std::map<std::string, int> within;
  for (const auto& [key, codecs] : by) {
    const auto& [scan, metric, target] = key;
    const TargetRow* pm = codecs.count("pm") ? codecs.at("pm") : nullptr;
    const TargetRow* eb = codecs.count("edgebreaker") ? codecs.at("edgebreaker") : nullptr;
    ++total;
    met_pm += ok(pm), met_eb += ok(eb);
    const double anchor = pm ? pm->anchor_bpv : (eb ? eb->anchor_bpv : -1);
    double auto_bpv = -1;
    for (const TargetRow* r : {pm, eb})
      if (ok(r) && (auto_bpv < 0 || bpv(r) < auto_bpv)) auto_bpv = bpv(r);
    const double pm_ratio = ok(pm) && anchor > 0 ? bpv(pm) / anchor : -1;
    const double auto_ratio = auto_bpv > 0 && anchor > 0 ? auto_bpv / anchor : -1;
    if (pm_ratio > 0) ratios["pm " + metric].push_back(pm_ratio), within["pm " + metric] += pm_ratio <= 1.1;
    if (auto_ratio > 0) ratios["auto " + metric].push_back(auto_ratio), within["auto " + metric] += auto_ratio <= 1.1;
    md << "| " << scan << " | " << metric << " | " << fmt(target, "%.0e") << " | "
       << (pm && pm->encoded ? fmt(pm->achieved, "%.3e") + (ok(pm) ? "" : " MISSED") : "failed") << " | "
       << (ok(pm) ? fmt(bpv(pm), "%.2f") : "-") << " | " << (ok(eb) ? fmt(bpv(eb), "%.2f") : "-") << " | "
       << (anchor > 0 ? fmt(anchor, "%.2f") : "none within E") << " | " << (pm_ratio > 0 ? fmt(pm_ratio, "%.3f") : "-")
       << " | " << (auto_ratio > 0 ? fmt(auto_ratio, "%.3f") : "-") << " |\n";
    for (const TargetRow* r : {pm, eb})
      if (r && !r->encoded) md << "|  | " << r->codec << ": " << r->failure.substr(0, 240) << " | | | | | | | |\n";
  }
  md << "\nMet, measured independently: pm " << met_pm << " of " << total << ", edgebreaker " << met_eb << " of "
     << total << ".\n\n| series | compared | within 10% of the anchors | median ratio |\n|---|---:|---:|---:|\n";
  for (auto& [name, v] : ratios) {
    std::sort(v.begin(), v.end());
    md << "| " << name << " | " << v.size() << " | " << within[name] << " | " << fmt(v[v.size() / 2], "%.3f") << " |\n";
  }
}

}  // namespace scanpress
