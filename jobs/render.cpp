#include "jobs/render.h"

#include <png.h>

#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <optional>

#include "engine/geometry.h"
#include "engine/quantize.h"
#include "jobs/file_io.h"
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

// 5x7 glyphs for the scale labels.
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
    case 'e': return "00000000000111010001111111000001110";
    case 'd': return "00001000010110110011100011000101111";
    default: return "00000000000000000000000000000000000";
  }
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

}  // namespace

Result<RenderResult> renderMesh(const Mesh& mesh, const RenderSettings& s, std::shared_ptr<EmbreeDevice> device,
                                const Mesh* against) {
  if (s.width < 16 || s.height < 16 || s.width > 8192 || s.height > 8192)
    return makeError(ErrorCode::kInvalidArgument, "picture size must be within 16..8192 pixels per side");
  if (mesh.triangles.empty())
    return makeError(ErrorCode::kInvalidArgument, "nothing to render: the mesh has no triangles");
  SP_ASSIGN_OR_RETURN(SurfaceIndex scene, SurfaceIndex::build(device, mesh.positions, mesh.triangles));
  std::optional<SurfaceIndex> reference;
  RenderResult out;
  const BoundingBox box = usedBoundingBox(against ? *against : mesh);  // the encoder's and measure's diagonal
  out.diagonal = box.diagonal();
  if (against) {
    SP_ASSIGN_OR_RETURN(SurfaceIndex r, SurfaceIndex::build(device, against->positions, against->triangles));
    reference.emplace(std::move(r));
  }
  // Camera: looking at the box center from (azimuth, elevation), the bounding sphere filling the view.
  const BoundingBox mbox = boundingBox(mesh);
  const Vec3d center = vmul(vadd(mbox.lo, mbox.hi), 0.5);
  const double radius = std::max(mbox.diagonal() / 2, 1e-30);
  const double az = s.azimuth * kPi / 180, el = s.elevation * kPi / 180;
  const Vec3d to_eye{std::cos(el) * std::sin(az), std::sin(el), std::cos(el) * std::cos(az)};
  const double fov = 35 * kPi / 180;
  const double aspect = double(s.width) / s.height;
  const double fit = std::min(1.0, aspect);  // the sphere must fit the narrower side
  const double dist = radius / std::sin(fov / 2 * fit) * 1.05;
  const Vec3d eye = vadd(center, vmul(to_eye, dist));
  const Vec3d forward = vmul(to_eye, -1.0);
  Vec3d up{0, 1, 0};
  if (std::fabs(vdot(up, forward)) > 0.999) up = {0, 0, 1};
  Vec3d right = vcross(forward, up);
  right = vmul(right, 1.0 / vlen(right));
  up = vcross(right, forward);
  const double half_h = std::tan(fov / 2), half_w = half_h * aspect;
  const int bar = against ? std::max(60, s.width / 8) : 0;  // room for the scale bar on the right
  const int view_w = s.width - bar;

  std::vector<double> shade(size_t(s.width) * s.height, -1), error(size_t(s.width) * s.height, -1);
  tbb::parallel_for(0, s.height, [&](int y) {
    uint32_t hint = UINT32_MAX;  // neighbouring pixels see nearby surface points
    for (int x = 0; x < view_w; ++x) {
      const double px = ((x + 0.5) / s.width * 2 - 1) * half_w, py = (1 - (y + 0.5) / s.height * 2) * half_h;
      Vec3d dir = vadd(forward, vadd(vmul(right, px), vmul(up, py)));
      dir = vmul(dir, 1.0 / vlen(dir));
      const auto hit = scene.intersect(eye, dir);
      if (!hit.hit) continue;
      const size_t i = size_t(y) * s.width + x;
      shade[i] = 0.25 + 0.75 * std::fabs(vdot(hit.normal, dir));
      if (reference) {
        const auto c = reference->closest(vadd(eye, vmul(dir, hit.t)), hint);
        error[i] = c.distance;
        hint = c.triangle;
      }
    }
  });
  if (reference) {  // the bar tops at the 99.5th percentile of visible distances, so one outlier cannot wash it out
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
    for (int k = 0; k < 3; ++k)
      img.rgb[3 * i + k] = static_cast<uint8_t>(std::clamp(c[k] * shade[i], 0.0, 1.0) * 255 + 0.5);
  }
  if (reference) {  // the scale bar with labels in units of the diagonal
    const int scale = std::max(1, s.height / 300);
    const int x0 = view_w + bar / 6, x1 = view_w + bar / 3, y0 = s.height / 8, y1 = s.height - s.height / 8;
    for (int y = y0; y <= y1; ++y) {
      const auto c = colormap(double(y1 - y) / (y1 - y0));
      for (int x = x0; x <= x1; ++x)
        for (int k = 0; k < 3; ++k)
          img.rgb[3 * (size_t(y) * s.width + x) + k] = static_cast<uint8_t>(c[k] * 255 + 0.5);
    }
    char label[32];
    std::snprintf(label, sizeof label, "%.1e d", out.diagonal > 0 ? out.scale_max / out.diagonal : 0.0);
    const int label_w = static_cast<int>(std::strlen(label)) * 6 * scale;
    drawText(img, std::max(0, std::min(view_w + 2, s.width - label_w - 2)), y0 - 10 * scale, label, scale);
    drawText(img, view_w + 2, y1 + 3 * scale, "0 d", scale);
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
