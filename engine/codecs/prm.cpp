// Codec `prm` (id 6): piecewise regular meshes, remeshing and coding in one.
//
// Paper: A. Szymczak, J. Rossignac, D. King, "Piecewise Regular Meshes: Construction and Compression"
// (../shared/papers/prm-piecewise-regular-meshes.md). Section 2 (reliefs, resampling, merging) is the `remesh`
// stage (engine/remesh/, engine/stages/remesh_stage.cpp), which this codec runs on the tile at its lattice spacing;
// section 3 (the compressed format) is edgebreaker's engine on that lattice (edgebreaker.cpp, "prm"), which this file
// frames.
//
// Where the coder departs from §3, and why:
//  - §3.1, connectivity: edgebreaker's CLERS coding with the paper's contexts (previous symbol, faces already decoded
//    around the gate's start), as the `edgebreaker` codec codes any mesh.
//  - §3.2, irregular triangles: a bit per face in decode order (regular or not, by whether the face across its gate
//    is none, irregular or regular), and its relief (the same as that face's, else one of six), instead of LERS
//    traversals of the irregular triangles. Both are about one adaptive binary decision per face; ours needs no
//    gate per traversal and costs 0.1-0.2 bit per face on scans.
//  - Regular is a property of the quantized mesh the coder is given, not of the remesher's labels: a face is regular
//    when its three corners are a counterclockwise unit triangle of one relief's lattice on the scan's grid
//    (FORMAT.md). Any mesh can be coded; a remeshed one has most of its faces regular. So the coder is lossless on
//    what it codes, as the paper's is ("no errors other than quantization").
//  - §3.3, geometry: patches are found from the connectivity and the regular faces, as in the paper. A patch is
//    anchored at the first of its points the decoder meets (decoded in full, as edgebreaker decodes any point) with
//    one of six rotations; every later point of it gets its base coordinates from the lattice and only its height is
//    coded. Heights are predicted from the lattice neighbours within two steps already decoded, by the
//    least-squares quadratic through them (measured: 6-9% fewer height bits than the mean of the parallelograms,
//    which with the lines and the neighbours is the fallback), in edgebreaker's decode order, instead of the
//    paper's iterated differences over the three edge families with bridges. Every point is still decoded once, in
//    one pass, and the predictor needs no second pass over the patch.
//  - Remeshing: the `remesh` stage, including the paper's collapse of relief-boundary vertices onto grid vertices
//    after merging (remesh.cpp; without it a quarter of horse's points were off the lattice and cost 16 bits each).
//    The tile is coded both as it is and remeshed, and the smaller coding is kept (beyond the paper: a lattice finer
//    than the tile's own triangles makes it larger, and coded as it is it is exact); so is it when remeshing would
//    break the border contract or exceed the remesher's size limit.
//
// Payload v1 and v2: varint G (the lattice spacing in grid cells, even, 2..2^24), then an edgebreaker payload
// (version 2 layout) coded on that lattice. v2 differs only in carrying scalar channels (the remesh stage resamples
// them: floats interpolated, integers and texture coordinates from the nearest corner).
#include <algorithm>
#include <cmath>
#include <string>

#include "engine/codecs/codec.h"
#include "engine/io/bytes.h"
#include "engine/stages/stage.h"

namespace scanpress {

namespace {

// Version 2: the layout's scalar channels too (resampled by the remesh stage, coded as edgebreaker codes them); a
// tile without them is written as version 1 (the same bytes), which older builds read.
constexpr uint16_t kPrmScalarsFrom = 2;

// The payload's first field, the lattice spacing; `header`: its length in bytes.
Result<uint32_t> readSpacing(std::span<const uint8_t> payload, size_t& header) {
  ByteReader r(payload, "prm payload");
  uint64_t spacing = 0;
  SP_RETURN_IF_ERROR(r.varint(spacing));
  if (spacing < 2 || spacing % 2 != 0 || spacing > kMaxLatticeSpacing)
    return makeError(ErrorCode::kMalformed, "prm payload: lattice spacing " + std::to_string(spacing) +
                                                " is not an even number in 2.." + std::to_string(kMaxLatticeSpacing));
  header = r.position();
  return uint32_t(spacing);
}

}  // namespace

uint32_t prmSpacing(const PrmOptions& options, int bits) {
  // At most the grid's extent (a coarser lattice has no point in it; the error knob can ask for more).
  const double top = std::min(std::ldexp(1.0, std::clamp(bits, 1, 24)), double(kMaxLatticeSpacing));
  if (options.spacing >= 0) {
    const double even = 2 * std::round(options.spacing / 2);
    return uint32_t(std::clamp(even, 2.0, top));
  }
  return uint32_t(std::clamp(double(remeshSpacing(RemeshStageOptions{.grid = options.grid, .tau = options.tau}, bits)),
                             2.0, top));
}

Status prmEncodeWithStats(const TileContext& ctx, const TileView& tile, const CodecOptions& options,
                          std::vector<uint8_t>& out, CodecStats* stats, TileSummary* summary) {
  StageSpec spec;
  spec.kind = StageKind::kRemesh;
  spec.remesh = RemeshStageOptions{.grid = options.prm.grid, .tau = options.prm.tau};
  SP_RETURN_IF_ERROR(validateStage(spec).withContext("prm"));
  if (std::isnan(options.prm.spacing) || std::isinf(options.prm.spacing))
    return makeError(ErrorCode::kInvalidArgument, "prm: spacing must be a number of grid cells");
  const uint32_t spacing = prmSpacing(options.prm, ctx.bits);
  // Both codings of the tile, as it is and remeshed: the smaller is kept. Kept as it is, the tile is also exact
  // (after quantization), so a remeshing that does not make it smaller (a lattice finer than the tile's own
  // triangles, most often) is never worth its error.
  struct Coding {
    std::vector<uint8_t> bytes;
    CodecStats stats;
    TileSummary summary;
  };
  const auto code = [&](const QuantizedMesh& mesh, Coding& c) -> Status {
    ByteWriter w(c.bytes);
    w.varint(spacing);
    SP_RETURN_IF_ERROR(edgebreakerEncodeOnLattice(ctx, mesh, spacing, c.bytes, stats ? &c.stats : nullptr, &c.summary));
    c.stats.payload_bytes = c.bytes.size();
    return Status::ok();
  };
  Coding kept, remeshed;
  SP_RETURN_IF_ERROR(code(tile.mesh, kept));
  if (options.prm.spacing != 0) {
    auto staged = remeshTile(ctx, tile, options.prm.tau, spacing);
    // The border contract, as runStage checks it for the remesh stage: a tile whose remeshing broke it (it should
    // not) is coded as it is rather than with a crack at its seam. So is one the lattice would make too large.
    if (staged.isOk()) {
      if (checkBorderContract(ctx, tile, staged->view(), false).isOk()) {
        SP_RETURN_IF_ERROR(code(staged->mesh, remeshed));
        if (remeshed.bytes.size() < kept.bytes.size()) std::swap(kept, remeshed);
      }
    } else if (staged.status().code() != ErrorCode::kLimitExceeded) {
      return staged.status();
    }
  }
  out.insert(out.end(), kept.bytes.begin(), kept.bytes.end());
  if (stats) *stats = kept.stats;
  if (summary) *summary = kept.summary;
  return Status::ok();
}

Result<EncodedTile> prmEncode(const TileContext& ctx, const TileView& tile, const CodecOptions& options) {
  EncodedTile e;
  SP_RETURN_IF_ERROR(prmEncodeWithStats(ctx, tile, options, e.payload, nullptr, &e.decoded));
  e.version = ctx.layout.hasScalars() ? kPrmScalarsFrom : 1;
  return e;
}

Result<QuantizedMesh> prmDecode(const TileContext& ctx, uint16_t version, std::span<const uint8_t> payload,
                                const DecodeLimits& limits) {
  if (version < 1 || version > kPrmScalarsFrom)
    return makeError(ErrorCode::kUnknownVersion, "prm payload: unknown version " + std::to_string(version));
  if (ctx.layout.hasScalars() && version < kPrmScalarsFrom)
    return makeError(ErrorCode::kMalformed, "prm payload of version 1 in a container with scalar channels");
  size_t header = 0;
  SP_ASSIGN_OR_RETURN(const uint32_t spacing, readSpacing(payload, header));
  return edgebreakerDecodeOnLattice(ctx, payload.subspan(header), limits, spacing);
}

Result<uint32_t> prmPayloadSpacing(std::span<const uint8_t> payload) {
  size_t header = 0;
  return readSpacing(payload, header);
}

}  // namespace scanpress
