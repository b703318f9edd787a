// CRC-32C (Castagnoli), software slicing-by-8. Used for every checksum in the container format.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

namespace scanpress {

// Returns the CRC-32C of `data`, continuing from `crc` (pass 0 to start; the result of one call may be passed to
// the next to checksum data in pieces).
uint32_t crc32c(std::span<const uint8_t> data, uint32_t crc = 0);

}  // namespace scanpress
