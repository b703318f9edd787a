// scanpress-compare: side-by-side comparison of every scanpress codec with Draco (edgebreaker, -cl 7 and -cl 10)
// and meshoptimizer (vertex cache and fetch optimisation, index and vertex codecs; raw and with zstd -19 on top),
// on the same quantized input, in one process; on scans with normals or colors, the bytes they add against Draco's
// (compare_attributes.cpp).
//
// For each scan in a folder and each quantization, the scan is quantized once on scanpress's grid (cubic cells
// over the largest extent, as Draco's -qp). Draco is given the cell centers: its lattice (largest extent of the
// input / (2^bits - 1)) then coincides with the grid, so its output can be checked cell by cell. Every result is
// decoded and compared with the input as the multiset of triangles over quantized positions (orientation kept):
// "lossless" in the table means exactly equal. Times are the median of --runs runs, single-threaded.
//
// Writes JSON (--json) and a Markdown table (--markdown); see bench/RESULTS.md.
#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>
#include <meshoptimizer.h>
#include <zstd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <cstdlib>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/compare.h"
#include "engine/codecs/codec.h"
#include "engine/quantize.h"
#include "jobs/measure.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "spatial/surface_index.h"

namespace scanpress {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

using Row = CompareRow;
using Options = CompareOptions;

// Sorted triangles over positions, each rotated to start at its smallest corner.
std::vector<std::array<Vec3u, 3>> canonical(const std::vector<Vec3u>& pos, const std::vector<Triangle>& tris) {
  std::vector<std::array<Vec3u, 3>> out;
  out.reserve(tris.size());
  for (const auto& t : tris) {
    std::array<Vec3u, 3> c{pos[t[0]], pos[t[1]], pos[t[2]]};
    std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
    out.push_back(c);
  }
  std::sort(out.begin(), out.end());
  return out;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

// Runs encode and decode `runs` times; `encode` returns the byte count, `decode` fills positions/triangles.
template <typename Enc, typename Dec>
void timeCodec(int runs, size_t triangles, Enc&& encode, Dec&& decode, Row& row) {
  std::vector<double> te, td;
  for (int r = 0; r < runs; ++r) {
    auto t0 = Clock::now();
    row.bytes = encode();
    auto t1 = Clock::now();
    decode();
    auto t2 = Clock::now();
    te.push_back(std::chrono::duration<double>(t1 - t0).count());
    td.push_back(std::chrono::duration<double>(t2 - t1).count());
  }
  row.encode_mtri = triangles / median(te) / 1e6;
  row.decode_mtri = triangles / median(td) / 1e6;
}

// Symmetric error of a decoded result (quantized positions, triangles) against the original scan.
void measureRow(const Mesh& original, const Grid& grid, const std::vector<Vec3u>& pos,
                const std::vector<Triangle>& tris, const Options& opt, Row& row) {
  if (!opt.rd) return;
  Mesh decoded;
  for (const auto& p : pos) decoded.positions.push_back(grid.dequantize(p));
  decoded.triangles = tris;
  measureDecoded(original, decoded, opt, row);
}

void runScan(const std::string& path, int bits, int first_bits, const Options& opt, std::vector<Row>& rows,
             std::vector<AttributeRow>& attribute_rows) {
  const int runs = opt.runs;
  auto mesh = readMeshFile(path, nullptr, ReadOptions::asInFile());
  if (!mesh.isOk()) {
    std::fprintf(stderr, "skipping %s: %s\n", path.c_str(), mesh.status().toString().c_str());
    return;
  }
  const Grid grid = *makeGrid(boundingBox(*mesh), bits);
  const QuantizedMesh q = *quantizeMesh(*mesh, grid, {}, nullptr);  // positions only: all peers code them
  const auto want = canonical(q.positions, q.triangles);
  const std::string scan = fs::path(path).filename().string();
  auto base = [&](const std::string& codec) {
    Row r;
    r.scan = scan;
    r.codec = codec;
    r.bits = bits;
    r.vertices = q.positions.size();
    r.triangles = q.triangles.size();
    return r;
  };

  // scanpress codecs.
  for (const auto& codec : allCodecs()) {
    Row row = base(std::string("scanpress ") + std::string(codec.name));
    const TileContext ctx{bits, {}};
    EncodedTile encoded;
    QuantizedMesh out;
    timeCodec(
        runs, q.triangles.size(),
        [&] {
      auto e = encodeMesh(codec, ctx, q);
      if (e.isOk()) encoded = std::move(e).value();
      else std::fprintf(stderr, "%s: %s\n", std::string(codec.name).c_str(), e.status().toString().c_str());
      return encoded.payload.size();
        },
        [&] {
      auto r = codec.decode(ctx, payloadVersion(codec, encoded), encoded.payload, limitsOf(encoded.decoded));
      if (r.isOk()) out = std::move(r).value();
    },
        row);
    row.lossless = canonical(out.positions, out.triangles) == want;
    measureRow(*mesh, grid, out.positions, out.triangles, opt, row);
    rows.push_back(row);
  }

  runPmSweep(scan, *mesh, grid, q, opt, rows);

  // Draco: cell centers in, its own quantization at the same bits.
  draco::Mesh dm;
  dm.set_num_points(static_cast<uint32_t>(q.positions.size()));
  draco::GeometryAttribute ga;
  ga.Init(draco::GeometryAttribute::POSITION, nullptr, 3, draco::DT_FLOAT32, false, 12, 0);
  const int att = dm.AddAttribute(ga, true, static_cast<uint32_t>(q.positions.size()));
  for (size_t i = 0; i < q.positions.size(); ++i) {
    const Vec3d c = grid.dequantize(q.positions[i]);
    const float f[3] = {static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2])};
    dm.attribute(att)->SetAttributeValue(draco::AttributeValueIndex(static_cast<uint32_t>(i)), f);
  }
  for (const auto& t : q.triangles)
    dm.AddFace({draco::PointIndex(t[0]), draco::PointIndex(t[1]), draco::PointIndex(t[2])});
  for (int cl : {7, 10}) {
    Row row = base("draco -cl " + std::to_string(cl));
    draco::EncoderBuffer buffer;
    std::unique_ptr<draco::Mesh> decoded;
    timeCodec(
        runs, q.triangles.size(),
        [&] {
      draco::Encoder enc;
      enc.SetAttributeQuantization(draco::GeometryAttribute::POSITION, bits);
      enc.SetSpeedOptions(10 - cl, 10 - cl);
      enc.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
      buffer.Clear();
      if (!enc.EncodeMeshToBuffer(dm, &buffer).ok()) return size_t(0);
      return buffer.size();
        },
        [&] {
      draco::DecoderBuffer in;
      in.Init(buffer.data(), buffer.size());
      draco::Decoder dec;
      auto r = dec.DecodeMeshFromBuffer(&in);
      if (r.ok()) decoded = std::move(r).value();
    },
        row);
    if (decoded) {
      const draco::PointAttribute* pa = decoded->GetNamedAttribute(draco::GeometryAttribute::POSITION);
      std::vector<Vec3u> pos(decoded->num_points());
      for (uint32_t i = 0; i < decoded->num_points(); ++i) {
        float f[3];
        pa->GetMappedValue(draco::PointIndex(i), f);
        pos[i] = grid.quantize({f[0], f[1], f[2]});
      }
      std::vector<Triangle> tris;
      for (uint32_t f = 0; f < decoded->num_faces(); ++f) {
        const auto& face = decoded->face(draco::FaceIndex(f));
        tris.push_back({face[0].value(), face[1].value(), face[2].value()});
      }
      row.lossless = canonical(pos, tris) == want;
      measureRow(*mesh, grid, pos, tris, opt, row);
    }
    rows.push_back(row);
  }

  // meshoptimizer: positions as 4 x uint16 (bits <= 16), vertex cache + fetch order, index and vertex codecs.
  if (bits <= 16) {
    std::vector<uint32_t> idx;
    for (const auto& t : q.triangles) idx.insert(idx.end(), t.begin(), t.end());
    std::vector<std::array<uint16_t, 4>> verts(q.positions.size());
    for (size_t i = 0; i < verts.size(); ++i)
      verts[i] = {uint16_t(q.positions[i][0]), uint16_t(q.positions[i][1]), uint16_t(q.positions[i][2]), 0};
    for (bool zstd : {false, true}) {
      Row row = base(zstd ? "meshopt + zstd-19" : "meshopt");
      std::vector<uint8_t> ib, vb, packed;
      std::vector<uint32_t> out_idx(idx.size());
      std::vector<std::array<uint16_t, 4>> out_verts(verts.size());
      size_t vcount = verts.size();
      timeCodec(
          runs, q.triangles.size(),
          [&] {
        std::vector<uint32_t> opt(idx.size());
        meshopt_optimizeVertexCache(opt.data(), idx.data(), idx.size(), verts.size());
        std::vector<std::array<uint16_t, 4>> ordered(verts.size());
        vcount = meshopt_optimizeVertexFetch(ordered.data(), opt.data(), opt.size(), verts.data(), verts.size(), 8);
        ib.resize(meshopt_encodeIndexBufferBound(opt.size(), vcount));
        ib.resize(meshopt_encodeIndexBuffer(ib.data(), ib.size(), opt.data(), opt.size()));
        vb.resize(meshopt_encodeVertexBufferBound(vcount, 8));
        vb.resize(meshopt_encodeVertexBuffer(vb.data(), vb.size(), ordered.data(), vcount, 8));
        if (!zstd) return ib.size() + vb.size();
        std::vector<uint8_t> both(ib);
        both.insert(both.end(), vb.begin(), vb.end());
        packed.resize(ZSTD_compressBound(both.size()));
        packed.resize(ZSTD_compress(packed.data(), packed.size(), both.data(), both.size(), 19));
        return packed.size();
          },
          [&] {
        if (zstd) {
          std::vector<uint8_t> both(ib.size() + vb.size());
          ZSTD_decompress(both.data(), both.size(), packed.data(), packed.size());
        }
        meshopt_decodeIndexBuffer(out_idx.data(), out_idx.size(), 4, ib.data(), ib.size());
        out_verts.resize(vcount);
        meshopt_decodeVertexBuffer(out_verts.data(), vcount, 8, vb.data(), vb.size());
      },
          row);
      std::vector<Vec3u> pos(vcount);
      for (size_t i = 0; i < vcount; ++i) pos[i] = {out_verts[i][0], out_verts[i][1], out_verts[i][2]};
      std::vector<Triangle> tris(out_idx.size() / 3);
      for (size_t t = 0; t < tris.size(); ++t) tris[t] = {out_idx[3 * t], out_idx[3 * t + 1], out_idx[3 * t + 2]};
      row.lossless = canonical(pos, tris) == want;
      measureRow(*mesh, grid, pos, tris, opt, row);
      rows.push_back(row);
    }
  }
  if (opt.rd && bits == first_bits) runAnchors(scan, *mesh, opt, rows);
  runAttributes(scan, *mesh, bits, attribute_rows);
  runTexcoords(scan, path, *mesh, bits, attribute_rows);
}

}  // namespace
}  // namespace scanpress

int main(int argc, char** argv) {
  using namespace scanpress;
  std::string data = SCANPRESS_SHARED_DATA, json_path = "compare.json", md_path = "compare.md", plot_dir;
  std::vector<int> bits = {12, 14};
  std::string only;  // comma-separated name prefixes (igea,horse): only those scans
  bool targets = false;
  Options opt;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string { return i + 1 < argc ? argv[++i] : ""; };
    if (a == "--data") data = next();
    else if (a == "--json") json_path = next();
    else if (a == "--markdown") md_path = next();
    else if (a == "--runs") opt.runs = std::max(1, std::atoi(next().c_str()));
    else if (a == "--rd") opt.rd = true;
    else if (a == "--targets") opt.rd = targets = true;
    else if (a == "--plots") plot_dir = next();
    else if (a == "--scans") only = next();
    else if (a == "--bits") {
      bits.clear();
      std::string list = next();
      for (size_t p = 0; p < list.size();) {
        const size_t c = std::min(list.find(',', p), list.size());
        bits.push_back(std::atoi(list.substr(p, c - p).c_str()));
        p = c + 1;
      }
    } else {
      std::fprintf(
          stderr,
          "usage: scanpress-compare [--data DIR] [--bits 12,14] [--runs 5] [--json F] [--markdown F]\n"
          "                         [--scans igea,horse] [--rd [--plots DIR]] [--targets]\n"
          "  --rd: rate-distortion: the error of every result, the lossy anchors (Draco -qp 8..12, meshoptimizer's\n"
          "        simplifier + Draco, gltfpack -si R -cc), pm's points against their envelope, bpv-error plots\n"
          "  --targets: --rd, and pm's error targets (--max-error 5e-5..5e-4, rms and max) measured independently\n"
          "        against the anchors' best size within each target\n");
      return 1;
    }
  }
  std::vector<std::string> scans;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(data, ec))
    if (e.is_regular_file() && formatFromName(e.path().filename().string()) != MeshFormat::kUnknown)
      if (only.empty() || [&] {
            const std::string name = e.path().filename().string();
            for (size_t p = 0; p <= only.size();) {
              const size_t c = std::min(only.find(',', p), only.size());
              if (c > p && name.rfind(only.substr(p, c - p), 0) == 0) return true;
              p = c + 1;
            }
            return false;
          }())
        scans.push_back(e.path().string());
  std::sort(scans.begin(), scans.end());
  if (scans.empty()) {
    std::fprintf(stderr, "no scans in %s\n", data.c_str());
    return 1;
  }
  if (opt.rd) {
    auto device = EmbreeDevice::create();
    if (!device.isOk()) return std::fprintf(stderr, "%s\n", device.status().toString().c_str()), 1;
    opt.device = *device;
  }
  std::vector<Row> rows;
  std::vector<TargetRow> target_rows;
  std::vector<AttributeRow> attribute_rows;
  for (const auto& s : scans) {
    for (int b : bits) {
      std::fprintf(stderr, "%s at %d bits\n", fs::path(s).filename().c_str(), b);
      runScan(s, b, bits.front(), opt, rows, attribute_rows);
    }
    if (!targets) continue;
    auto mesh = readMeshFile(s, nullptr, ReadOptions::asInFile());
    if (!mesh.isOk()) continue;
    std::vector<Row> anchors;
    for (const auto& r : rows)
      if (r.anchor && r.scan == fs::path(s).filename().string()) anchors.push_back(r);
    runTargets(s, *mesh, anchors, opt, target_rows);
  }
  nlohmann::json j = nlohmann::json::array();
  for (const auto& r : rows)
    j.push_back({{"scan", r.scan},
                 {"codec", r.codec},
                 {"family", r.family},
                 {"bits", r.bits},
                 {"vertices", r.vertices},
                 {"triangles", r.triangles},
                 {"bytes", r.bytes},
                 {"bpv", 8.0 * r.bytes / r.vertices},
                 {"encode_mtri_s", r.encode_mtri},
                 {"decode_mtri_s", r.decode_mtri},
                 {"lossless", r.lossless},
                 {"symmetric_rms_relative", r.rms_rel},
                 {"symmetric_max_relative", r.max_rel}});
  for (const auto& r : attribute_rows)  // the attribute table's rows: "attributes" names the configuration
    j.push_back({{"scan", r.scan},
                 {"codec", r.codec},
                 {"attributes", r.config},
                 {"bits", r.bits},
                 {"vertices", r.vertices},
                 {"bytes", r.bytes},
                 {"geometry_bytes", r.geometry_bytes},
                 {"attribute_bpv", 8.0 * (double(r.bytes) - double(r.geometry_bytes)) / double(r.vertices)},
                 {"exact", r.exact},
                 {"max_normal_angle_deg", r.max_angle_deg},
                 {"colors_exact", r.colors_exact}});
  std::ofstream(json_path) << j.dump(2) << "\n";
  std::ofstream md(md_path);
  md << "| scan | bits | codec | bytes | bpv | encode Mtri/s | decode Mtri/s | lossless |\n|---|---:|---|---:|---:|---:|---:|---|\n";
  char line[512];
  for (const auto& r : rows) {
    std::snprintf(line, sizeof line, "| %s | %d | %s | %llu | %.2f | %.2f | %.2f | %s |\n", r.scan.c_str(), r.bits,
                  r.codec.c_str(), static_cast<unsigned long long>(r.bytes), 8.0 * r.bytes / r.vertices, r.encode_mtri,
                  r.decode_mtri, r.lossless ? "yes" : "NO");
    md << line;
  }
  // Median bpv per codec and bits, over the scans.
  md << "\n| codec | bits | median bpv | median encode Mtri/s | median decode Mtri/s | all lossless |\n|---|---:|---:|---:|---:|---|\n";
  std::map<std::pair<std::string, int>, std::vector<const Row*>> by;
  for (const auto& r : rows)
    if (r.family.empty()) by[{r.codec, r.bits}].push_back(&r);
  for (const auto& [key, v] : by) {
    std::vector<double> bpv, enc, dec;
    bool all = true;
    for (const Row* r : v)
      bpv.push_back(8.0 * r->bytes / r->vertices), enc.push_back(r->encode_mtri), dec.push_back(r->decode_mtri),
          all &= r->lossless;
    std::snprintf(line, sizeof line, "| %s | %d | %.2f | %.2f | %.2f | %s |\n", key.first.c_str(), key.second,
                  median(bpv), median(enc), median(dec), all ? "yes" : "NO");
    md << line;
  }
  writeAttributeTable(md, attribute_rows);
  if (opt.rd) {  // RD columns, and one bpv-vs-error plot per scan (gnuplot, when installed)
    md << "\n| scan | codec | bits | bpv | symmetric RMS / diagonal | symmetric max / diagonal |\n|---|---|---:|---:|---:|---:|\n";
    for (const auto& r : rows) {
      std::snprintf(line, sizeof line, "| %s | %s | %d | %.2f | %.3e | %.3e |\n", r.scan.c_str(), r.codec.c_str(),
                    r.bits, 8.0 * r.bytes / r.vertices, r.rms_rel, r.max_rel);
      md << line;
    }
    writeEnvelopeTable(md, rows);
    writeTargetsTable(md, target_rows);
    if (!plot_dir.empty()) {
      // Per scan, bits per original vertex against the symmetric RMS and against the symmetric max (Hausdorff).
      fs::create_directories(plot_dir);
      std::map<std::string, std::map<std::string, std::vector<const Row*>>> series;
      for (const auto& r : rows) series[r.scan][r.family.empty() ? r.codec : r.family].push_back(&r);
      const std::string script = plot_dir + "/rd.gp";
      std::ofstream gp(script);
      for (const auto& [scan, codecs] : series)
        for (const bool hausdorff : {false, true}) {
          const std::string what = hausdorff ? "max" : "rms";
          gp << "set terminal pngcairo size 900,600\nset output '" << plot_dir << "/" << scan << ".rd-" << what
             << ".png'\nset title 'Rate-distortion: " << scan << "'\nset logscale xy\nset xlabel 'symmetric "
             << (hausdorff ? "Hausdorff" : "RMS") << " error / bounding-box diagonal'\nset ylabel 'bits per original "
             << "vertex'\nset key outside right\nset grid\nplot ";
          bool first = true;
          for (const auto& [codec, pts] : codecs) {
            // Far above every other series (store, raw meshoptimizer): they would flatten the plot.
            if (codec == "scanpress store" || codec == "meshopt") continue;
            std::vector<const Row*> sorted(pts);
            std::sort(sorted.begin(), sorted.end(), [&](auto* a, auto* b) {
              return (hausdorff ? a->max_rel : a->rms_rel) < (hausdorff ? b->max_rel : b->rms_rel);
            });
            const std::string dat = plot_dir + "/" + scan + "." + what + "." +
                                    std::to_string(std::hash<std::string>()(codec)) + ".dat";
            std::ofstream d(dat);
            for (const Row* r : sorted)
              if ((hausdorff ? r->max_rel : r->rms_rel) > 0)
                d << (hausdorff ? r->max_rel : r->rms_rel) << " " << 8.0 * r->bytes / r->vertices << "\n";
            gp << (first ? "" : ", ") << "'" << dat << "' with "
               << (codec == "meshopt + draco" ? "points" : "linespoints") << " title '" << codec << "'";
            first = false;
          }
          gp << "\n";
        }
      gp.close();
      if (std::system(("command -v gnuplot >/dev/null && gnuplot '" + script + "'").c_str()) != 0)
        std::fprintf(stderr, "gnuplot not found (scripts/install-bench-deps.sh): wrote %s only\n", script.c_str());
    }
  }
  std::fprintf(stderr, "wrote %s and %s\n", json_path.c_str(), md_path.c_str());
  return 0;
}
