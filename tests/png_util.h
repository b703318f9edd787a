// PNG decoding for tests that check pictures (libpng's simplified API, independent of our encoder's code path).
#pragma once

#include <png.h>

#include <cstdint>
#include <cstring>
#include <vector>

#include "jobs/render.h"

namespace scanpress::testing {

// RGB pixels of a PNG; an empty image when the bytes are not one.
inline Image decodePng(const std::vector<uint8_t>& bytes) {
  png_image img;
  std::memset(&img, 0, sizeof img);
  img.version = PNG_IMAGE_VERSION;
  Image out;
  if (!png_image_begin_read_from_memory(&img, bytes.data(), bytes.size())) return out;
  img.format = PNG_FORMAT_RGB;
  out.width = static_cast<int>(img.width);
  out.height = static_cast<int>(img.height);
  out.rgb.resize(PNG_IMAGE_SIZE(img));
  if (!png_image_finish_read(&img, nullptr, out.rgb.data(), 0, nullptr)) out = Image();
  return out;
}

}  // namespace scanpress::testing
