// The operations behind the CLI: encode a mesh file into a container, decode a container (or some of its
// tiles) into a mesh file, describe a container. Each returns a typed result; the CLI and (later) the batch
// runner turn them into output, reports and exit codes.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "engine/container/container.h"
#include "engine/quantize.h"
#include "jobs/mesh_io/mesh_reader.h"

namespace scanpress {

struct EncodeSettings {
  std::string input;
  std::string output;
  std::string codec = "store";
  int bits = kDefaultGridBits;
  int normal_bits = kDefaultNormalBits;
  bool keep_normals = true;
  bool keep_colors = true;
};

struct StageSeconds {
  double read = 0, quantize = 0, encode = 0, write = 0;
};

struct EncodeResult {
  ReadStats read;
  Grid grid;
  AttributeLayout layout;
  QuantizeStats quantize;
  uint64_t vertices = 0;  // encoded (after dropping)
  uint64_t faces = 0;
  uint64_t bytes = 0;  // container size
  uint32_t tiles = 0;
  StageSeconds seconds;
  std::string codec;
  double bitsPerVertex() const { return vertices ? 8.0 * bytes / vertices : 0.0; }
};

Result<EncodeResult> encodeFile(const EncodeSettings& settings);

struct DecodeSettings {
  std::string input;
  std::string output;
  std::optional<std::vector<uint32_t>> tiles;  // all tiles when empty
};

struct DecodeResult {
  uint64_t vertices = 0, faces = 0;
  uint32_t tiles = 0;
  bool double_positions = false;
};

// Decodes the selected tiles and welds them (in memory).
Result<QuantizedMesh> decodeContainer(const std::string& path, const std::optional<std::vector<uint32_t>>& tiles,
                                      ContainerHeader* header = nullptr);
Result<DecodeResult> decodeFile(const DecodeSettings& settings);

// Whether float positions requantize to the same cells on this grid (otherwise writers use double).
bool floatPositionsSuffice(const QuantizedMesh& mesh, const Grid& grid);

}  // namespace scanpress
