// Pictures of meshes: Embree ray casting with a headlight, optionally colored by the distance to another mesh
// (the original), with a color scale bar labelled in units of the original's bounding-box diagonal and in absolute
// units; otherwise by the scan's vertex colors when it has them. PNG output (libpng), written all-or-nothing.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "engine/mesh.h"
#include "engine/status.h"
#include "jobs/chunked_surface.h"

namespace scanpress {

class EmbreeDevice;

struct LegendEntry {
  std::string label;  // drawn in capitals
  std::array<uint8_t, 3> rgb;
};

struct RenderSettings {
  int width = 800, height = 600;
  double azimuth = 30, elevation = 20;  // degrees; y is up
  // Top of the color bar in units of the reference's diagonal; 0: the 99.5th percentile of the visible distances.
  // A fixed value gives every picture of a batch the same scale.
  double scale_max_relative = 0;
  std::string title;                // drawn in a band at the top (e.g. the file name); none when empty
  std::vector<LegendEntry> legend;  // swatches with labels along the bottom (what the colors mean); none when empty
  // One color per triangle of a mesh drawn whole (one chunk) without a reference; none when empty.
  std::vector<std::array<uint8_t, 3>> face_colors;
  // Shade with the mesh's normals interpolated over each triangle (where it has them: a crease's wedges show
  // whether their sides' normals stay apart), instead of each triangle's own plane.
  bool vertex_normals = false;
};

struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;  // row-major, 3 bytes per pixel
};

struct RenderResult {
  Image image;
  double scale_max = 0;  // distance at the top of the color bar (absolute units), when colored
  double diagonal = 0;   // of the reference mesh
};

// Renders `mesh`; with `against`, colors each visible point by its distance to `against`.
Result<RenderResult> renderMesh(const Mesh& mesh, const RenderSettings& settings, std::shared_ptr<EmbreeDevice> device,
                                const Mesh* against = nullptr);

// renderMesh a chunk at a time: the mesh's chunks are ray cast one after the other (a pixel keeps the nearest hit)
// and the visible points' distances found over the reference's chunks through a cache of `cache_bytes`. Hits
// and distances are computed in double from each triangle's corners, so the picture is the whole mesh's, up to a
// pixel whose ray meets two triangles at the same distance (an edge).
Result<RenderResult> renderSurface(const ChunkedSurface& mesh, const RenderSettings& settings,
                                   std::shared_ptr<EmbreeDevice> device, const ChunkedSurface* against,
                                   uint64_t cache_bytes);

// A prm container's surface with every face colored by what prm's coder made of it (the paper's Fig. 1 and 10):
// by the relief whose lattice it is a unit triangle of, irregular faces white (kReliefs), or regular against
// irregular (kRegularity): `face_colors` for RenderSettings, and `legend` says what the colors are. Regularity is
// read from the decoded positions on each tile's lattice, as the coder reads it (a face the mesh repeats counts each
// time; the coder codes the repeat as a copy). The picture is drawn whole: kLimitExceeded when that would need
// more than `memory_budget` bytes (0: no limit).
enum class LatticeColoring { kReliefs, kRegularity };
struct LatticePicture {
  Mesh mesh;  // the tiles' meshes side by side (not welded)
  std::vector<std::array<uint8_t, 3>> face_colors;
  std::vector<LegendEntry> legend;
  uint64_t faces = 0, regular_faces = 0;
};
Result<LatticePicture> latticePicture(const std::string& container_path, LatticeColoring how,
                                      uint64_t memory_budget = 0);

Result<std::vector<uint8_t>> encodePng(const Image& image);
Status writePng(const std::string& path, const Image& image);

}  // namespace scanpress
