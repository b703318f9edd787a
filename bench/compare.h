// What scanpress-compare's parts share (bench/compare.cpp: lossless comparison; bench/compare_rd.cpp: the lossy
// rate-distortion anchors and the pm sweep).
#pragma once

#include <memory>
#include <ostream>
#include <string>
#include <vector>

#include "engine/mesh.h"
#include "engine/quantize.h"
#include "spatial/surface_index.h"

namespace scanpress {

struct CompareRow {
  std::string scan, codec;
  std::string family;   // rate-distortion series: "draco qp", "meshopt + draco", "gltfpack", "pm"; empty otherwise
  bool anchor = false;  // a peer's point of the rate-distortion comparison (pm is measured against their envelope)
  int bits = 0;
  uint64_t vertices = 0, triangles = 0, bytes = 0;  // vertices and triangles of the original (bpv per original vertex)
  double encode_mtri = 0, decode_mtri = 0;
  bool lossless = false;
  double rms_rel = -1, max_rel = -1;  // symmetric error relative to the diagonal (--rd)
};

struct CompareOptions {
  int runs = 5;
  bool rd = false;
  std::shared_ptr<EmbreeDevice> device;
};

// Symmetric error of `decoded` against `original` (relative to the original's diagonal) into the row (--rd only).
void measureDecoded(const Mesh& original, const Mesh& decoded, const CompareOptions& opt, CompareRow& row);

// Lossy anchors on one scan (once per scan, independent of --bits): Draco -cl 10 at -qp 8..12; meshoptimizer's
// simplifier to 50/25/10/5% of the triangles followed by Draco -cl 10 at -qp 10..12; gltfpack -si R -cc (the size
// of its .glb; when gltfpack is installed).
void runAnchors(const std::string& scan, const Mesh& mesh, const CompareOptions& opt, std::vector<CompareRow>& rows);

// pm at several error bounds and prm at several lattice spacings, on the scan quantized at `bits`, as one tile.
void runPmSweep(const std::string& scan, const Mesh& mesh, const Grid& grid, const QuantizedMesh& q,
                const CompareOptions& opt, std::vector<CompareRow>& rows);

// The rate-distortion tables of issues 19 (pm) and 21 (prm): per scan, the codec's bits per original vertex against
// the lower envelope of the anchors (interpolated in log RMS) at symmetric RMS between 5e-5 and 3e-4 of the
// diagonal; the median ratio.
void writeEnvelopeTable(std::ostream& md, const std::vector<CompareRow>& rows);

// One error target of issue 19 (`--targets`): scanpress encode --codec pm --max-error E --error metric on a scan,
// measured independently afterwards, against the smallest size the anchors reach within E.
struct TargetRow {
  std::string scan, codec;
  std::string metric;  // "rms" or "max"
  double target = 0;   // relative to the diagonal
  uint64_t vertices = 0, bytes = 0;
  int bits = 0;
  bool encoded = false;  // the encoder reported the target met (else `failure` says why)
  std::string failure;
  double achieved = -1;    // independent measurement (scanpress measure's defaults, another seed), relative
  double anchor_bpv = -1;  // the anchors' lower envelope at the target (interpolated in log error); -1: none reaches
  double seconds = 0;
};

// Runs the targets 5e-5, 1e-4, 2e-4, 5e-4 (rms and max) on `path` with pm and with edgebreaker (whose better result
// is what --codec auto keeps) and appends their rows; `anchors` are the scan's anchor rows (runAnchors).
void runTargets(const std::string& path, const Mesh& mesh, const std::vector<CompareRow>& anchors,
                const CompareOptions& opt, std::vector<TargetRow>& out);
void writeTargetsTable(std::ostream& md, const std::vector<TargetRow>& rows);

// Attributes (bench/compare_attributes.cpp): one coder on a scan at one configuration (normals at 10 or 12
// octahedral bits, 8-bit colors, or both), with the bytes of the same coder on the geometry alone.
struct AttributeRow {
  std::string scan, config, codec;
  int bits = 0;
  uint64_t vertices = 0, bytes = 0, geometry_bytes = 0;
  bool exact = false;         // scanpress: every (position, normal code, color) came back
  double max_angle_deg = -1;  // Draco: the largest angle between a decoded normal and the input's
  bool colors_exact = true;   // Draco: every color came back
  double max_uv_error = -1;   // Draco: the largest difference between a decoded texture coordinate and the input's
  int uv_qt = 0;              // Draco: its -qt (the nearest step to scanpress's 2^-bits over the coordinates' range)
};
// Scans without normals or colors add no rows.
void runAttributes(const std::string& scan, const Mesh& mesh, int bits, std::vector<AttributeRow>& rows);
// Texture coordinates: a scan whose file gives corners texture coordinates, read again with its wedges, at 10, 12 and
// 14 bits (scanpress --uv-bits, Draco -qt). `as_in_file`: the scan as runScan read it (its geometry alone). Scans
// without texture coordinates add no rows.
void runTexcoords(const std::string& scan, const std::string& path, const Mesh& as_in_file, int bits,
                  std::vector<AttributeRow>& rows);
void writeAttributeTable(std::ostream& md, const std::vector<AttributeRow>& rows);

}  // namespace scanpress
