// Fuzz target: a container decoded by every codec's decoder. The first input byte is a mode: bit 0 set means
// "recompute every checksum after the mutation" (so that mutations reach the decoders' logic instead of
// failing a CRC); the rest is the container. Every tile is decoded whole and at every level, within the
// index's limits.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "container_decode.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const bool repair = (data[0] & 1) != 0;
  std::vector<uint8_t> file(data + 1, data + size);
  if (repair) scanpress::fuzzing::repairChecksums(file);
  scanpress::fuzzing::DecodeCounts counts;
  (void)scanpress::fuzzing::decodeEverything(file, counts);
  return 0;
}
