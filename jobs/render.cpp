#include "jobs/render.h"

#include <png.h>

#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <optional>
#include <utility>

#include "engine/geometry.h"
#include "engine/quantize.h"
#include "engine/codecs/codec.h"
#include "jobs/container_file.h"
#include "jobs/file_io.h"
#include "jobs/measure.h"
#include "spatial/surface_index.h"

namespace scanpress {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A perceptual blue -> cyan -> green -> yellow -> red ramp (piecewise linear through the "turbo" control points).
std::array<double, 3> colormap(double t) {
  static const double kStops[][3] = {{0.19, 0.07, 0.23}, {0.16, 0.47, 0.93}, {0.10, 0.84, 0.80}, {0.40, 0.99, 0.38},
                                     {0.85, 0.91, 0.21}, {0.99, 0.55, 0.15}, {0.80, 0.17, 0.03}, {0.48, 0.02, 0.01}};
  constexpr int n = 8;
  t = std::clamp(t, 0.0, 1.0) * (n - 1);
  const int i = std::min(n - 2, static_cast<int>(t));
  const double f = t - i;
  return {kStops[i][0] + (kStops[i + 1][0] - kStops[i][0]) * f, kStops[i][1] + (kStops[i + 1][1] - kStops[i][1]) * f,
          kStops[i][2] + (kStops[i + 1][2] - kStops[i][2]) * f};
}

// 5x7 glyphs for the scale labels and titles (titles are drawn in capitals; 'e' and 'd' are the labels' own).
const char* glyph(char c) {
  switch (c) {
    case '0': return "01110100011001110101110011000101110";
    case '1': return "00100011000010000100001000010001110";
    case '2': return "01110100010000100010001000100011111";
    case '3': return "11111000100010000010000011000101110";
    case '4': return "00010001100101010010111110001000010";
    case '5': return "11111100001111000001000011000101110";
    case '6': return "00110010001000011110100011000101110";
    case '7': return "11111000010001000100010000100001000";
    case '8': return "01110100011000101110100011000101110";
    case '9': return "01110100011000101111000010001001100";
    case '.': return "00000000000000000000000000110001100";
    case '-': return "00000000000000011111000000000000000";
    case '+': return "00000001000010011111001000010000000";
    case '_': return "00000000000000000000000000000011111";
    case '=': return "00000000001111100000111110000000000";
    case '(': return "00010001000100001000010000010000010";
    case ')': return "01000001000001000010000100010001000";
    case '%': return "11000110010001000100010001001100011";
    case 'e': return "00000000000111010001111111000001110";
    case 'd': return "00001000010110110011100011000101111";
    case 'A': return "01110100011000111111100011000110001";
    case 'B': return "11110100011000111110100011000111110";
    case 'C': return "01110100011000010000100001000101110";
    case 'D': return "11100100101000110001100011001011100";
    case 'E': return "11111100001000011110100001000011111";
    case 'F': return "11111100001000011110100001000010000";
    case 'G': return "01110100011000010111100011000101111";
    case 'H': return "10001100011000111111100011000110001";
    case 'I': return "01110001000010000100001000010001110";
    case 'J': return "00111000100001000010000101001001100";
    case 'K': return "10001100101010011000101001001010001";
    case 'L': return "10000100001000010000100001000011111";
    case 'M': return "10001110111010110101100011000110001";
    case 'N': return "10001100011100110101100111000110001";
    case 'O': return "01110100011000110001100011000101110";
    case 'P': return "11110100011000111110100001000010000";
    case 'Q': return "01110100011000110001101011001001101";
    case 'R': return "11110100011000111110101001001010001";
    case 'S': return "01111100001000001110000010000111110";
    case 'T': return "11111001000010000100001000010000100";
    case 'U': return "10001100011000110001100011000101110";
    case 'V': return "10001100011000110001100010101000100";
    case 'W': return "10001100011000110101101011010101010";
    case 'X': return "10001100010101000100010101000110001";
    case 'Y': return "10001100011000101010001000010000100";
    case 'Z': return "11111000010001000100010001000011111";
    default: return "00000000000000000000000000000000000";
  }
}

std::string capitals(std::string text) {
  for (char& c : text) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return text;
}

void drawText(Image& img, int x, int y, const std::string& text, int scale) {
  for (char c : text) {
    const char* g = glyph(c);
    for (int gy = 0; gy < 7; ++gy)
      for (int gx = 0; gx < 5; ++gx)
        if (g[gy * 5 + gx] == '1')
          for (int sy = 0; sy < scale; ++sy)
            for (int sx = 0; sx < scale; ++sx) {
              const int px = x + gx * scale + sx, py = y + gy * scale + sy;
              if (px < 0 || py < 0 || px >= img.width || py >= img.height) continue;
              uint8_t* p = &img.rgb[3 * (size_t(py) * img.width + px)];
              p[0] = p[1] = p[2] = 20;
            }
    x += 6 * scale;
  }
}

// The vertex colors at `p` on triangle `t`, interpolated barycentrically (as fractions of 255).
// The barycentric weights of point p (on triangle t, clamped to it).
std::array<double, 3> barycentric(const Mesh& mesh, uint32_t t, const Vec3d& p) {
  const auto& tri = mesh.triangles[t];
  const Vec3d a = mesh.positions[tri[0]], e1 = vsub(mesh.positions[tri[1]], a), e2 = vsub(mesh.positions[tri[2]], a);
  const Vec3d d = vsub(p, a);
  const double d11 = vdot(e1, e1), d12 = vdot(e1, e2), d22 = vdot(e2, e2), d1 = vdot(d, e1), d2 = vdot(d, e2);
  const double den = d11 * d22 - d12 * d12;
  double u = 0, v = 0;
  if (den > 0) {
    u = std::clamp((d22 * d1 - d12 * d2) / den, 0.0, 1.0);
    v = std::clamp((d11 * d2 - d12 * d1) / den, 0.0, 1.0 - u);
  }
  return {1 - u - v, u, v};
}

std::array<double, 3> vertexColor(const Mesh& mesh, uint32_t t, const Vec3d& p) {
  const auto& tri = mesh.triangles[t];
  const auto w = barycentric(mesh, t, p);
  std::array<double, 3> c{0, 0, 0};
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 3; ++j) c[k] += w[j] * mesh.colors[tri[j]][k] / 255.0;
  return c;
}

// The mesh's normal at p, interpolated over triangle t (not normalized; zero where the corners' cancel).
Vec3d vertexNormal(const Mesh& mesh, uint32_t t, const Vec3d& p) {
  const auto& tri = mesh.triangles[t];
  const auto w = barycentric(mesh, t, p);
  Vec3d n{0, 0, 0};
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 3; ++j) n[k] += w[j] * mesh.normals[tri[j]][k];
  return n;
}

}  // namespace

Result<RenderResult> renderMesh(const Mesh& mesh, const RenderSettings& s, std::shared_ptr<EmbreeDevice> device,
                                const Mesh* against) {
  const ChunkedSurface whole = ChunkedSurface::whole(mesh);
  std::optional<ChunkedSurface> reference;
  if (against) reference.emplace(ChunkedSurface::whole(*against));
  return renderSurface(whole, s, std::move(device), against ? &*reference : nullptr, UINT64_MAX);
}

Result<RenderResult> renderSurface(const ChunkedSurface& mesh, const RenderSettings& s,
                                   std::shared_ptr<EmbreeDevice> device, const ChunkedSurface* against,
                                   uint64_t cache_bytes) {
  if (s.width < 16 || s.height < 16 || s.width > 8192 || s.height > 8192)
    return makeError(ErrorCode::kInvalidArgument, "picture size must be within 16..8192 pixels per side");
  if (mesh.triangles() == 0)
    return makeError(ErrorCode::kInvalidArgument, "nothing to render: the mesh has no triangles");
  const bool reference = against != nullptr;
  RenderResult out;
  out.diagonal = (against ? *against : mesh).usedBox().diagonal();  // the encoder's and measure's diagonal
  // Layout: a title band on top, the scale bar on the right, the model in the rest.
  const int text_scale = std::max(1, s.height / 300);
  const int title_h = s.title.empty() ? 0 : 11 * text_scale;
  // The legend: swatch and label after swatch and label, wrapped into rows at the picture's width.
  std::vector<std::array<int, 2>> legend_at;  // x, row
  for (int x = 2 * text_scale, row = 0; const LegendEntry& e : s.legend) {
    const int w = (9 + 6 * static_cast<int>(e.label.size())) * text_scale;  // swatch, gap, label
    if (!legend_at.empty() && x + w > s.width) x = 2 * text_scale, ++row;
    legend_at.push_back({x, row});
    x += w + 8 * text_scale;
  }
  const int legend_h = legend_at.empty() ? 0 : (legend_at.back()[1] + 1) * 12 * text_scale;
  const int bar = against ? std::max(60, s.width / 8) : 0;
  const int view_w = s.width - bar, view_h = s.height - title_h - legend_h;
  if (view_w < 8 || view_h < 8) return makeError(ErrorCode::kInvalidArgument, "picture too small for its labels");
  // Camera: from (azimuth, elevation), framing the model's vertices to kFill of the view's smaller extent. The
  // look-at point centers their projection along the view plane; the distance is the smallest at which every vertex
  // projects inside the filled frame (exact under perspective, per vertex), so elongated scans fill the view too
  // rather than their bounding sphere. Minima and maxima over the chunks: the same as over the whole mesh.
  constexpr double kFill = 0.9;
  const double az = s.azimuth * kPi / 180, el = s.elevation * kPi / 180;
  const Vec3d to_eye{std::cos(el) * std::sin(az), std::sin(el), std::cos(el) * std::cos(az)};
  const Vec3d forward = vmul(to_eye, -1.0);
  Vec3d up{0, 1, 0};
  if (std::fabs(vdot(up, forward)) > 0.999) up = {0, 0, 1};
  Vec3d right = vcross(forward, up);
  right = vmul(right, 1.0 / vlen(right));
  up = vcross(right, forward);
  const double fov = 35 * kPi / 180;
  const double aspect = double(view_w) / view_h;
  const double half_h = std::tan(fov / 2), half_w = half_h * aspect;
  const BoundingBox& mbox = mesh.box();
  const Vec3d mesh_center = vmul(vadd(mbox.lo, mbox.hi), 0.5);
  Vec3d center = mesh_center;
  // Each used vertex of chunk i, given to `f`.
  std::vector<uint8_t> used;
  auto forUsed = [&](auto&& f) -> Status {
    for (size_t i = 0; i < mesh.chunks(); ++i) {
      if (mesh.info(i).triangles == 0) continue;
      SP_ASSIGN_OR_RETURN(auto m, mesh.load(i));
      used.assign(m->positions.size(), 0);
      for (const auto& t : m->triangles)
        for (uint32_t v : t)
          if (v < used.size()) used[v] = 1;
      for (size_t v = 0; v < used.size(); ++v)
        if (used[v]) f(m->positions[v]);
    }
    return Status::ok();
  };
  double a_lo = HUGE_VAL, a_hi = -HUGE_VAL, b_lo = HUGE_VAL, b_hi = -HUGE_VAL;
  SP_RETURN_IF_ERROR(forUsed([&](const Vec3d& p) {
    const Vec3d d = vsub(p, center);
    a_lo = std::min(a_lo, vdot(d, right)), a_hi = std::max(a_hi, vdot(d, right));
    b_lo = std::min(b_lo, vdot(d, up)), b_hi = std::max(b_hi, vdot(d, up));
  }));
  center = vadd(center, vadd(vmul(right, (a_lo + a_hi) / 2), vmul(up, (b_lo + b_hi) / 2)));
  double dist = 0;
  SP_RETURN_IF_ERROR(forUsed([&](const Vec3d& p) {
    const Vec3d d = vsub(p, center);
    dist = std::max(dist, vdot(d, to_eye) + std::max(std::fabs(vdot(d, right)) / (kFill * half_w),
                                                     std::fabs(vdot(d, up)) / (kFill * half_h)));
  }));
  std::vector<uint8_t>().swap(used);
  dist = std::max(dist, std::max(mbox.diagonal(), 1e-30) * 1e-3);  // a point-like or degenerate model
  const Vec3d eye = vadd(center, vmul(to_eye, dist));
  // Rays, chunk by chunk: a pixel keeps the nearest hit (the earlier chunk on a tie), its shade, the vertex color
  // there (when no reference colors it and the chunk has colors) and the point.
  const size_t pixels = size_t(s.width) * s.height;
  std::vector<double> shade(pixels, -1), error(pixels, -1), depth(pixels, HUGE_VAL);
  std::vector<std::array<double, 3>> albedo;
  std::vector<Vec3d> hit_point(reference ? pixels : 0);
  bool vertex_colors = false;
  const bool face_colors = !s.face_colors.empty();
  if (face_colors && (reference || mesh.chunks() != 1 || s.face_colors.size() != mesh.triangles()))
    return makeError(ErrorCode::kInvalidArgument,
                     "face colors are for a mesh drawn whole, one per triangle, without a reference");
  if (face_colors) albedo.assign(pixels, {0.85, 0.85, 0.85});
  for (size_t i = 0; i < mesh.chunks(); ++i) {
    if (mesh.info(i).triangles == 0) continue;
    SP_ASSIGN_OR_RETURN(auto m, mesh.load(i));
    // Every chunk around the mesh's centre: a corner two chunks share rounds alike in both, so no ray slips
    // between them at their seam.
    SP_ASSIGN_OR_RETURN(SurfaceIndex scene, SurfaceIndex::build(device, m->positions, m->triangles, &mesh_center));
    const bool colors = !reference && !m->colors.empty() && m->colors.size() == m->positions.size();
    const bool normals = s.vertex_normals && !m->normals.empty() && m->normals.size() == m->positions.size();
    if (colors && albedo.empty()) albedo.assign(pixels, {0.85, 0.85, 0.85});
    vertex_colors |= colors;
    tbb::parallel_for(title_h, title_h + view_h, [&](int y) {
      for (int x = 0; x < view_w; ++x) {
        const double px = ((x + 0.5) / view_w * 2 - 1) * half_w, py = (1 - (y - title_h + 0.5) / view_h * 2) * half_h;
        Vec3d dir = vadd(forward, vadd(vmul(right, px), vmul(up, py)));
        dir = vmul(dir, 1.0 / vlen(dir));
        const auto hit = scene.intersect(eye, dir);
        const size_t k = size_t(y) * s.width + x;
        if (!hit.hit || !(hit.t < depth[k])) continue;
        depth[k] = hit.t;
        const Vec3d point = vadd(eye, vmul(dir, hit.t));
        Vec3d n = hit.normal;
        if (normals) {
          const Vec3d v = vertexNormal(*m, hit.triangle, point);
          if (const double l = vlen(v); l > 0) n = vmul(v, 1 / l);
        }
        shade[k] = 0.25 + 0.75 * std::fabs(vdot(n, dir));
        if (face_colors) {
          const auto& c = s.face_colors[hit.triangle];
          albedo[k] = {c[0] / 255.0, c[1] / 255.0, c[2] / 255.0};
        } else if (colors) {
          albedo[k] = vertexColor(*m, hit.triangle, point);
        } else if (!albedo.empty()) albedo[k] = {0.85, 0.85, 0.85};
        if (reference) hit_point[k] = point;
      }
    });
  }
  std::vector<double>().swap(depth);
  if (reference) {  // each visible point's distance to the reference
    std::vector<size_t> where;
    std::vector<Vec3d> points;
    for (size_t k = 0; k < pixels; ++k)
      if (shade[k] >= 0) where.push_back(k), points.push_back(hit_point[k]);
    std::vector<Vec3d>().swap(hit_point);
    std::vector<double> d2;
    ChunkIndexCache cache(*against, device, cache_bytes);
    SP_RETURN_IF_ERROR(nearestSquared(*against, cache, points, d2));
    for (size_t n = 0; n < where.size(); ++n) error[where[n]] = std::sqrt(d2[n]);
  }
  if (reference && s.scale_max_relative > 0) {
    out.scale_max = s.scale_max_relative * out.diagonal;
  } else if (reference) {  // the bar tops at the 99.5th percentile of visible distances, so one outlier cannot
                           // wash it out
    std::vector<double> visible;
    for (double e : error)
      if (e >= 0) visible.push_back(e);
    if (!visible.empty()) {
      const size_t k = std::min(visible.size() - 1, static_cast<size_t>(visible.size() * 0.995));
      std::nth_element(visible.begin(), visible.begin() + k, visible.end());
      out.scale_max = visible[k];
    }
    if (!(out.scale_max > 0)) out.scale_max = out.diagonal > 0 ? out.diagonal * 1e-9 : 1e-30;
  }
  Image& img = out.image;
  img.width = s.width;
  img.height = s.height;
  img.rgb.assign(size_t(s.width) * s.height * 3, 245);
  for (size_t i = 0; i < shade.size(); ++i) {
    if (shade[i] < 0) continue;
    std::array<double, 3> c{0.85, 0.85, 0.85};
    if (reference) c = colormap(error[i] / out.scale_max);
    else if (vertex_colors || face_colors) c = albedo[i];
    for (int k = 0; k < 3; ++k)
      img.rgb[3 * i + k] = static_cast<uint8_t>(std::clamp(c[k] * shade[i], 0.0, 1.0) * 255 + 0.5);
  }
  if (reference) {  // the scale bar, its top labelled in units of the diagonal and in the scan's own units
    const int scale = text_scale, line = 10 * scale;
    const int x0 = view_w + bar / 6, x1 = view_w + bar / 3;
    const int y0 = title_h + 2 * line + 4 * scale, y1 = std::max(y0 + 1, s.height - legend_h - line - 2 * scale);
    for (int y = y0; y <= y1 && y < s.height; ++y) {
      const auto c = colormap(double(y1 - y) / (y1 - y0));
      for (int x = x0; x <= x1; ++x)
        for (int k = 0; k < 3; ++k)
          img.rgb[3 * (size_t(y) * s.width + x) + k] = static_cast<uint8_t>(c[k] * 255 + 0.5);
    }
    char relative[32], absolute[32];
    std::snprintf(relative, sizeof relative, "%.1e d", out.diagonal > 0 ? out.scale_max / out.diagonal : 0.0);
    std::snprintf(absolute, sizeof absolute, "%.2e", out.scale_max);
    for (auto [text, y] : {std::pair<const char*, int>{relative, y0 - 2 * line}, {absolute, y0 - line}}) {
      const int w = static_cast<int>(std::strlen(text)) * 6 * scale;
      drawText(img, std::max(0, std::min(view_w + 2, s.width - w - 2)), y, text, scale);
    }
    drawText(img, view_w + 2, y1 + 3 * scale, "0", scale);
  }
  for (size_t i = 0; i < s.legend.size(); ++i) {  // the bottom band
    const int scale = text_scale, x = legend_at[i][0], y = s.height - legend_h + (12 * legend_at[i][1] + 2) * scale;
    for (int py = y; py < y + 7 * scale && py < s.height; ++py)
      for (int px = x; px < x + 7 * scale && px < s.width; ++px)
        for (int k = 0; k < 3; ++k) img.rgb[3 * (size_t(py) * s.width + px) + k] = s.legend[i].rgb[size_t(k)];
    drawText(img, x + 9 * scale, y, capitals(s.legend[i].label), scale);
  }
  if (!s.title.empty()) {
    drawText(img, 2 * text_scale, 2 * text_scale, capitals(s.title), text_scale);
  }
  return out;
}

Result<LatticePicture> latticePicture(const std::string& path, LatticeColoring how, uint64_t memory_budget) {
  // Relief colors as the paper's pictures: six distinct hues, irregular faces white.
  static constexpr std::array<uint8_t, 3> kRelief[6] = {{222, 84, 72},  {240, 170, 60}, {96, 186, 96},
                                                        {70, 168, 180}, {86, 112, 222}, {178, 102, 214}};
  static constexpr std::array<uint8_t, 3> kIrregularWhite{236, 236, 236}, kRegular{110, 170, 235},
      kIrregular{240, 120, 60};
  static const char* const kReliefName[6] = {"+x", "-x", "+y", "-y", "+z", "-z"};
  SP_ASSIGN_OR_RETURN(ContainerFile file, ContainerFile::open(path));
  const ContainerHeader& header = file.header();
  // The picture is drawn whole: the mesh, its face colors and the ray-casting index.
  uint64_t faces = 0, vertices = 0;
  for (const TileEntry& e : file.tiles()) faces += e.faces, vertices += e.vertices;
  if (memory_budget != 0 && faces * kInMemoryBytesPerTriangle > memory_budget)
    return makeError(ErrorCode::kLimitExceeded,
                     path + ": its " + std::to_string(faces) + " faces are pictured whole, which needs about " +
                         std::to_string(faces * kInMemoryBytesPerTriangle >> 20) + " MiB, over the memory budget of " +
                         std::to_string(memory_budget >> 20) + " MiB (--memory-budget)");
  if (vertices > UINT32_MAX)
    return makeError(ErrorCode::kLimitExceeded, path + ": more than 2^32 vertices cannot be pictured in one mesh");
  LatticePicture out;
  out.mesh.positions.reserve(vertices);
  out.mesh.triangles.reserve(faces);
  out.face_colors.reserve(faces);
  std::vector<uint8_t> chunk;
  for (const TileEntry& e : file.tiles()) {
    const std::string where = path + ": tile " + std::to_string(e.tile_id);
    if (e.codec != CodecId::kPrm)
      return makeError(ErrorCode::kInvalidArgument, where + " is coded with " + codecName(e.codec) +
                                                        "; reliefs and regularity are pictured for prm containers");
    if (e.faces == 0) continue;
    SP_ASSIGN_OR_RETURN(auto payload, file.readPayload(e, chunk));
    const auto spacing = prmPayloadSpacing(payload);
    if (!spacing.isOk()) return spacing.status().withContext(where);
    SP_ASSIGN_OR_RETURN(QuantizedMesh q, decodeTilePayload(header, e, payload, path));
    const std::vector<int8_t> relief = latticeFaceReliefs(q, *spacing);
    const uint32_t base = uint32_t(out.mesh.positions.size());
    for (const Vec3u& p : q.positions) out.mesh.positions.push_back(header.grid.dequantize(p));
    for (size_t f = 0; f < q.triangles.size(); ++f) {
      const int r = relief[f];
      out.face_colors.push_back(how == LatticeColoring::kReliefs ? (r >= 0 ? kRelief[r] : kIrregularWhite)
                                : r >= 0                         ? kRegular
                                                                 : kIrregular);
      out.mesh.triangles.push_back({base + q.triangles[f][0], base + q.triangles[f][1], base + q.triangles[f][2]});
      out.regular_faces += r >= 0;
    }
    out.faces += q.triangles.size();
  }
  if (how == LatticeColoring::kReliefs) {
    for (int r = 0; r < 6; ++r) out.legend.push_back({kReliefName[r], kRelief[r]});
    out.legend.push_back({"irregular", kIrregularWhite});
  } else {
    out.legend = {{"regular", kRegular}, {"irregular", kIrregular}};
  }
  return out;
}

Result<std::vector<uint8_t>> encodePng(const Image& image) {
  std::vector<uint8_t> out;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  if (!png) return makeError(ErrorCode::kIo, "cannot create a PNG writer");
  png_infop info = png_create_info_struct(png);
  if (!info || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return makeError(ErrorCode::kInternal, "PNG encoding failed");
  }
  png_set_write_fn(
      png, &out,
      [](png_structp p, png_bytep data, png_size_t n) {
    auto* v = static_cast<std::vector<uint8_t>*>(png_get_io_ptr(p));
    v->insert(v->end(), data, data + n);
      },
      nullptr);
  png_set_IHDR(png, info, static_cast<png_uint_32>(image.width), static_cast<png_uint_32>(image.height), 8,
               PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (int y = 0; y < image.height; ++y)
    png_write_row(png, const_cast<png_bytep>(image.rgb.data() + size_t(y) * image.width * 3));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return out;
}

Status writePng(const std::string& path, const Image& image) {
  SP_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, encodePng(image));
  return writeFileAtomically(path, bytes);
}

}  // namespace scanpress
