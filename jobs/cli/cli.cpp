// The scanpress command line. Exit codes: 0 ok, 1 usage or config error, 2 bad input data, 3 environment (I/O,
// disk full), 4 internal error; 128 + the signal when SIGINT, SIGTERM or SIGHUP ended it (jobs/cleanup.h).
#include "jobs/cli/cli.h"

#include <signal.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "engine/codecs/codec.h"
#include "engine/quantize.h"
#include "jobs/batch.h"
#include "jobs/cleanup.h"
#include "jobs/commands.h"
#include "jobs/config.h"
#include "jobs/container_file.h"
#include "jobs/file_io.h"
#include "jobs/html_report.h"
#include "jobs/measure.h"
#include "jobs/mesh_io/gltf_writer.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/numbers.h"
#include "jobs/process.h"
#include "jobs/progress.h"
#include "jobs/render.h"
#include "jobs/report.h"
#include "jobs/shard.h"
#include "jobs/stdio.h"
#include "jobs/stream_decode.h"
#include "jobs/synth.h"
#include "spatial/surface_index.h"

namespace scanpress {
namespace {

constexpr const char* kVersion = "0.1.0";

constexpr const char* kMainHelp = R"(scanpress: parallel batch compression for large 3D scans

usage: scanpress <command> [options]

commands:
  run      run a JSON job file: many scans, one container and report each, a batch summary
  encode   compress a mesh file (PLY, OBJ, STL, OFF; optionally .zst) into a .spz container
  decode   decompress a container (or some of its tiles) into PLY, OBJ, STL, OFF (optionally .zst) or glTF
  info     describe a container
  measure  surface distance between two meshes (Metro-style, both directions, Embree)
  render   a PNG picture of a mesh, optionally colored by its distance to the original
  report   report.html of a batch: a sortable table of every scan with thumbnails and error heat maps
  merge    join the parts of `encode --subset i/N` into the whole container
  synth    write a deterministic scan-like mesh of N triangles (for tests and benchmarks)

'scanpress <command> --help' shows a command's options.
exit codes: 0 ok, 1 usage or config error, 2 bad input data, 3 environment (I/O, disk full), 4 internal error;
  130 (Ctrl-C), 143 (SIGTERM), 129 (SIGHUP): interrupted, temporary files removed
)";

constexpr const char* kEncodeHelp = R"(usage: scanpress encode IN OUT.spz [options]

Compresses the mesh IN into the container OUT.spz. The output appears complete or not at all. IN `-` reads the
mesh from stdin (with --format), OUT `-` writes the container to stdout (messages go to stderr). A missing output
folder is created; an OUT named like a mesh, glTF, image or JSON file is refused.

options:
  --codec NAME        tile codec (default edgebreaker; available: %s); auto: with a target, the
                      smaller result of pm and edgebreaker that meets it (else edgebreaker)
  --grid G            prm: the hexagonal lattice spacing of the remeshing, a fraction of the largest extent
                      (default 0.005); with --max-error each tile chooses its own
  --tau T             prm: relief regularisation, 0.001..0.577 (default 0.2)
  --stages LIST       geometry stages every tile runs before the codec, in order: NAME[:KEY=VALUE...][,NAME...]
                      (available: %s); e.g. smooth:iterations=5 (configs/REFERENCE.md, "Stages")
  --bits N            quantization bits, 8..24 (default 16): the largest bounding-box extent is divided into 2^N
                      cubic cells, as Draco's -qp does
  --max-error E       error target, relative to the bounding-box diagonal: the measured error of the decoded scan
                      is at most E (verified by decoding and measuring; the report gives it per tile and overall).
                      Without --bits the fewest bits that meet it are chosen; a codec that simplifies also
                      chooses per tile how far. Exit 2 when it cannot be met
  --error rms|max     the metric of --max-error: symmetric RMS (default) or symmetric max (Hausdorff), as
                      `scanpress measure` reports them
  --max-bytes N       size target: the container at most N bytes, at the least error (exit 2 when even the
                      coarsest setting is larger)
  --bpv R             size target: at most R bits per encoded vertex, at the least error
  --normal-bits N     octahedral bits per normal component, 4..16 (default 12)
  --color-bits N      levels per color channel: 2^N, 1..8 (default 8: exact)
  --uv-bits N         texture coordinates as multiples of 2^-N, 1..24 (a texel of a 2^N texture; default:
                      lossless, bit for bit)
  --no-normals        drop normals
  --lossless-normals  keep normals bit for bit (three float channels nx, ny, nz) instead of octahedral codes;
                      store, kdtree, octree, edgebreaker and pm
  --no-colors         drop colors
  --no-scalars        drop per-vertex scalar properties (a PLY's confidence, intensity, quality, ...; kept
                      losslessly at their type by store, kdtree, octree and edgebreaker, by pm at the vertices
                      it keeps, resampled by prm and the remesh stage; texture coordinates not by the last two)
  --allow-degenerate  keep going when quantization makes more than 0.1%% of the triangles degenerate (they are
                      dropped); without it such a scan fails with exit 2 (raise --bits instead). Implied by
                      --max-error, whose measured error accounts for them
  --strict            fail (exit 2) when the input holds anything the container would not keep
                      (materials, per-face properties, extra PLY elements, texture coordinates under prm or
                      the remesh stage, points pm merges); without it they are dropped with
                      one warning and listed in the report
  --tile-triangles N  target triangles per tile (default 131072; tiles adapt to density around it)
  --threads N         worker threads (default: all cores); the output is the same at any count
  --memory-budget S   bound the memory for tile data, e.g. 512M, 2GiB or 1.5G (units K, M, G, T of 1024;
                      no unit: MiB; 0: no limit); larger scans stream through scratch files
  --scratch-dir DIR   where scratch files go (default: the system temp directory)
  --measure           measure the error of the decoded result (per tile and overall) into the report
  --samples-per-triangle X   measurement sampling density (default 2)
  --report R.json     write a JSON report (counts, bytes, bits per vertex, seconds per stage, tiles, error);
                      `-` for stdout (not with OUT `-`)
  --format F          the format of a mesh on stdin: ply, obj, stl or off, with .zst when compressed (ply.zst)
  --subset i/N        one part of a scan spread over N processes or nodes: the scan is read and tiled as a whole
                      encode does, and only every N-th tile from i is encoded, into a partial container;
                      `scanpress merge` joins the N parts into the whole container, byte for byte
                      (not with a target)
  --quiet             print nothing on success, warnings included (progress shows only on a terminal anyway)
)";

constexpr const char* kRunHelp = R"(usage: scanpress run JOB.json [options]

Runs a job file: every input scan (files, directories, globs) is encoded to its own container and report in the
output directory, and a batch summary is written. A bad file is reported and the others still run. Re-running a
finished job skips outputs that are complete and were made with the same settings. configs/REFERENCE.md lists
every key.

options:
  --threads N       override the job's thread count
  --force           redo every input, even complete ones
  --quiet           no progress and no per-file lines
  --shard i/N       run shard i (0-based) of N: a deterministic share of the inputs, balanced by size, with its
                    own summary (SUMMARY.shard-i-of-N.json). Without it, a job array's index is read from
                    SLURM_ARRAY_TASK_ID / SLURM_ARRAY_TASK_COUNT, or JOB_COMPLETION_INDEX with --shard-count N
  --shard-count N   the number of shards when the environment does not say (Kubernetes indexed jobs)
  --merge           join the shards' summaries into the job's summary; names inputs no shard covered
                    (configs/slurm-array.sbatch shows an array and its merge)
exit codes: 0 all ok, 1 invalid job file, else the most severe failure (2 bad data, 3 environment, 4 internal)
)";

constexpr const char* kMeasureHelp = R"(usage: scanpress measure A B [options]

Surface distance between mesh A (the original) and mesh B (e.g. a decoded scan): area-weighted samples on each
surface (stratified, seeded; plus the vertices, for the max only), exact closest-point distances to the other
surface, both directions. Reports mean and RMS (area-weighted averages) and max (Hausdorff) in absolute units
and relative to A's bounding-box diagonal, one-sided (forward A->B, backward B->A) and symmetric (the larger
of the two). Same numbers at any thread count.

options:
  --samples N               about N samples per direction (default: 2 per triangle of A)
  --samples-per-triangle X  sampling density in samples per triangle of A
  --seed S                  sampling seed (default 1)
  --monte-carlo             random samples instead of stratified ones
  --json                    print JSON
  --memory-budget S         bound the memory (default 256M; 0: no limit): meshes whose measurement would need
                            more (about 200 bytes per triangle) are read into scratch files and measured a run of
                            triangles at a time; the numbers are the same, bit for bit
  --scratch-dir DIR         where those scratch files go (default: the system temp directory)
A or B may be a container (.spz): it is measured as `decode` would write it, a tile at a time.
)";

constexpr const char* kRenderHelp = R"(usage: scanpress render MESH OUT.png [options]

Ray-casts MESH (Embree) with a headlight. With --against, the surface is colored by its distance to ORIGINAL,
with a color scale bar labelled in units of ORIGINAL's bounding-box diagonal (d) and in absolute units (the bar
tops at the 99.5th percentile of the visible distances, or at --scale-max). Without --against, a scan with vertex
colors is shaded with them. The camera frames the model to 90% of the view; MESH's file name is drawn on top.

options:
  --against ORIGINAL   color by distance to this mesh
  --view AZ,EL         camera azimuth and elevation in degrees (default 30,20; y is up)
  --size W,H           picture size in pixels (default 800,600)
  --scale-max E        top of the color bar at E diagonals (E > 0), so every picture of a batch shares one scale
  --memory-budget S    bound the memory (default 256M; 0: no limit): meshes whose rendering would need more are
                       read into scratch files and drawn a run of triangles at a time (the same picture, up to
                       pixels on an edge between two triangles)
  --scratch-dir DIR    where those scratch files go (default: the system temp directory)
  --color-by K         for a prm container (MESH.spz coded with --codec prm): color each face by what the coder
                       made of it: `reliefs` (the relief whose lattice it is a unit triangle of; irregular faces
                       white) or `regularity` (regular against irregular). The title gives the regular share,
                       and so does a line on standard output. The container is drawn whole (within
                       --memory-budget, else it fails).
  --shade S            `faces` (default): each triangle by its own plane; `normals`: by MESH's normals
                       interpolated over each triangle (where it has them), to see whether a crease's two sides keep
                       their own normals
MESH or ORIGINAL may be a container (.spz): it is drawn as `decode` would write it, a tile at a time.
)";

constexpr const char* kReportHelp = R"(usage: scanpress report DIR|SUMMARY.json [options]

Writes a page of a batch's results (the summary.json that `run` wrote in DIR, or the summary given): a table of
every scan (input and output size, bits per vertex, ratio, measured error, time, tiles, status) with a thumbnail of
each decoded container and the error heat map the job rendered (/measure/render). Click a column to sort it
(`report.html#sort=-bpv` opens sorted). One self-contained file: it opens in a browser without a server (the heat
maps are linked relative to it). A job writes it itself with /output/html.

options:
  --out FILE.html    where to write it (default: report.html beside the summary)
  --no-thumbnails    no decode and render per scan (fast for large batches)
  --memory-budget S  a scan whose decode would need more is drawn from a coarse vertex-clustered decode (its shape
                     at thumbnail resolution) within the budget (default 256M; 0: no limit)
)";

constexpr const char* kMergeHelp = R"(usage: scanpress merge PART.spz... OUT.spz

Joins the N partial containers of one scan (`encode IN PART_i.spz --subset i/N` for i = 0..N-1, on any machines,
with the same settings) into OUT.spz: the same bytes as `encode IN OUT.spz` in one process. Fails, writing nothing,
when a part is missing, given twice, whole, of another split, or of another scan or grid.
)";

constexpr const char* kSynthHelp = R"(usage: scanpress synth OUT.ply --triangles N [options]

Writes a deterministic scan-like mesh of exactly N triangles (PLY binary little endian), streaming: a base mesh
subdivided and displaced by multi-scale noise.

options:
  --triangles N   number of triangles (required)
  --seed S        noise seed (default 1)
  --from SCAN     base mesh (default: a built-in bumpy icosphere)
  --quiet         print nothing on success
)";

constexpr const char* kDecodeHelp = R"(usage: scanpress decode IN.spz OUT [options]

Decompresses a container into a mesh file, by OUT's extension: .ply (binary little endian), .obj, .stl (binary,
geometry only), .off, each optionally .zst-compressed (.ply.zst), or glTF 2.0 (.glb, .gltf). Positions are cell
centers of the container's grid; they are written as float, or as double when float cannot hold the grid (PLY,
OBJ, OFF; glTF keeps float precision with a node translation). IN `-`
reads the container from stdin, OUT `-` writes the mesh to stdout in the --format given (messages go to stderr).

options:
  --tiles ID,ID,...   decode only these tiles (welded together)
  --box X0,Y0,Z0,X1,Y1,Z1
                      decode only the tiles whose bounds meet this box, in world units (`info` prints each tile's
                      box); not with --tiles
  --crop              with --box: keep only the triangles wholly inside the box
  --format F          the format of a mesh written to stdout (OUT `-`): ply, obj, stl, off, glb or gltf
  --level L           progressive codecs: every tile at level L, as its codec numbers levels (`info` lists each
                      level and what it means; kdtree, octree: cells of 2^(bits-L) grid cells as vertices at their
                      centers with that level's triangles, L = grid bits is lossless)
  --bytes N           progressive codecs: the finest level whose payloads fit in N bytes (info --json lists
                      the bytes of every level)
  --gltf-compression none|meshopt|draco
                      glTF output: EXT_meshopt_compression or KHR_draco_mesh_compression (lossless on the decoded
                      mesh; at most 16 grid bits, positions are the grid's cells with KHR_mesh_quantization)
  --gltf-nodes one|tiles
                      glTF output: one mesh welded from the tiles (default), or one node per tile, named "tile ID"
  --memory-budget S   bound the decode's memory (default 256M; 0: no limit): a scan whose in-memory decode would
                      need more is decoded a batch of tiles at a time and written through scratch files (same
                      output, byte for byte); glTF output is refused instead. A single tile that needs more than
                      three quarters of the budget is an error naming the budget it needs
  --scratch-dir DIR   where the streaming decode keeps its scratch files (default: the system temp directory)
  --quiet             print nothing on success
)";

constexpr const char* kInfoHelp = R"(usage: scanpress info IN.spz [options]

Describes a container: grid, counts, size, attributes and tiles.

options:
  --json      print JSON: {"grid": {"origin", "cell", "bits"}, "vertices", "faces", "bytes", "tiles": [...]}
  --verify    also read every tile and check its checksums and decoding
  --memory-budget S
              with --verify: refuse a tile whose decode would need more (default 256M; 0: no limit)
)";

int fail(const Status& s) {
  std::fprintf(stderr, "scanpress: error: %s\n", s.toString().c_str());
  return exitCodeFor(s.code());
}

// fail() for a command with `-` files: the spool's paths (jobs/stdio.h) are named <stdin> and <stdout>.
int failStdio(const Status& s, const std::string& spooled_in, const std::string& spooled_out) {
  std::string m = s.message();
  for (const auto& [path, name] : {std::pair{spooled_in, "<stdin>"}, std::pair{spooled_out, "<stdout>"}})
    if (!path.empty())
      for (size_t at; (at = m.find(path)) != std::string::npos;) m.replace(at, path.size(), name);
  return fail(Status(s.code(), m));
}

int usage(const std::string& message, const char* help_hint) {
  std::fprintf(stderr, "scanpress: error: %s\n(see 'scanpress %s --help')\n", message.c_str(), help_hint);
  return 1;
}

bool isHelp(const std::string& a) { return a == "--help" || a == "-h"; }

// Options parsed as `--name value` or flags; positional arguments collected in order.
struct Args {
  std::vector<std::string> positional;
  std::vector<std::pair<std::string, std::string>> options;
  bool has(const std::string& name) const {
    for (const auto& [k, v] : options)
      if (k == name) return true;
    return false;
  }
  const std::string* get(const std::string& name) const {
    const std::string* found = nullptr;
    for (const auto& [k, v] : options)
      if (k == name) found = &v;
    return found;
  }
};

// Parses argv[first..]; `valued` lists options that take a value, `flags` those that do not.
bool parseArgs(int argc, char** argv, int first, const std::vector<std::string>& valued,
               const std::vector<std::string>& flags, Args& out, std::string& error) {
  for (int i = first; i < argc; ++i) {
    std::string a = argv[i];
    if (a.size() > 2 && a.starts_with("--")) {
      std::string value;
      bool inline_value = false;
      if (auto eq = a.find('='); eq != std::string::npos) {
        value = a.substr(eq + 1);
        a = a.substr(0, eq);
        inline_value = true;
      }
      const bool takes_value = std::find(valued.begin(), valued.end(), a) != valued.end();
      const bool is_flag = std::find(flags.begin(), flags.end(), a) != flags.end();
      if (!takes_value && !is_flag) return error = "unknown option '" + a + "'", false;
      if (takes_value && !inline_value) {
        if (i + 1 >= argc) return error = "option '" + a + "' needs a value", false;
        value = argv[++i];
      }
      if (is_flag && inline_value) return error = "option '" + a + "' takes no value", false;
      out.options.emplace_back(a, value);
    } else {
      out.positional.push_back(a);
    }
  }
  return true;
}

// Option `name`, when given, parsed into `out` by `parse` (a parser of jobs/numbers.h); false with `error`
// set otherwise.
template <typename T, typename Parse>
bool option(const Args& args, const char* name, T& out, std::string& error, Parse parse) {
  const std::string* v = args.get(name);
  if (!v) return true;
  auto r = parse(*v);
  if (!r.isOk()) return error = r.status().message(), false;
  out = static_cast<T>(*r);
  return true;
}

template <typename T>
bool integerOption(const Args& args, const char* name, int64_t lo, int64_t hi, T& out, std::string& error) {
  return option(args, name, out, error, [&](const std::string& v) { return parseInteger(v, lo, hi, name); });
}

template <typename T>
bool unsignedOption(const Args& args, const char* name, uint64_t hi, T& out, std::string& error) {
  return option(args, name, out, error, [&](const std::string& v) { return parseUnsigned(v, hi, name); });
}

bool numberOption(const Args& args, const char* name, double lo, double hi, double& out, std::string& error) {
  return option(args, name, out, error, [&](const std::string& v) { return parseNumber(v, lo, hi, name); });
}

// --max-error, --error, --max-bytes, --bpv into s.target; an error message, or "" when they are fine.
std::string targetOptions(const Args& args, EncodeSettings& s) {
  std::vector<std::string> given;
  for (const char* name : {"--max-error", "--max-bytes", "--bpv"})
    if (args.has(name)) given.push_back(name);
  if (given.size() > 1)
    return given[0] + " and " + given[1] + " conflict: give one target (an error bound or a size budget)";
  std::string error;
  EncodeTarget& t = s.target;
  if (!numberOption(args, "--max-error", 1e-12, 1, t.max_error, error) ||
      !unsignedOption(args, "--max-bytes", UINT64_MAX, t.max_bytes, error) ||
      !numberOption(args, "--bpv", 1e-6, 1e6, t.bpv, error))
    return error;
  if (const std::string* m = args.get("--error")) {
    if (*m != "rms" && *m != "max") return "--error: must be rms or max, got '" + *m + "'";
    if (!args.has("--max-error")) return "--error applies to --max-error only";
    t.metric = *m == "max" ? ErrorMetric::kMax : ErrorMetric::kRms;
  }
  if (args.has("--max-bytes") && t.max_bytes == 0) return "--max-bytes: must be at least 1";
  t.kind = args.has("--max-error")   ? TargetKind::kMaxError
           : args.has("--max-bytes") ? TargetKind::kMaxBytes
           : args.has("--bpv")       ? TargetKind::kBitsPerVertex
                                     : TargetKind::kNone;
  t.fixed_bits = args.has("--bits");
  return "";
}

// --memory-budget: 0 or at least 16M.
bool budgetOption(const Args& args, uint64_t& budget, std::string& error) {
  if (!option(args, "--memory-budget", budget, error,
              [](const std::string& v) { return parseSize(v, "--memory-budget"); }))
    return false;
  if (budget != 0 && budget < (16u << 20)) {
    error = "--memory-budget: must be 0 or at least 16M, got '" + *args.get("--memory-budget") + "'";
    return false;
  }
  return true;
}

int runEncode(int argc, char** argv) {
  Args args;
  std::string error;
  if (!parseArgs(argc, argv, 2, {"--codec",      "--stages",        "--bits",        "--normal-bits",
                                 "--color-bits", "--uv-bits",       "--report",      "--tile-triangles",
                                 "--threads",    "--memory-budget", "--scratch-dir", "--samples-per-triangle",
                                 "--format",     "--max-error",     "--error",       "--max-bytes",
                                 "--bpv",        "--subset",        "--grid",        "--tau"},
                 {"--no-normals", "--lossless-normals", "--no-colors", "--no-scalars", "--allow-degenerate",
                  "--strict", "--measure", "--quiet", "--help"},
                 args, error))
    return usage(error, "encode");
  if (args.has("--help")) {
    std::printf(kEncodeHelp, codecNames().c_str(), stageNames().c_str());
    return 0;
  }
  if (args.positional.size() != 2) return usage("encode needs IN and OUT", "encode");
  EncodeSettings s;
  s.input = args.positional[0];
  s.output = args.positional[1];
  if (const auto* c = args.get("--codec")) s.codec = *c;
  if (!knownCodecName(s.codec))
    return usage("unknown codec '" + s.codec + "' (available: " + codecNames() + ", auto)", "encode");
  if (const auto* st = args.get("--stages")) {
    auto stages = parseStagesOption(*st, "--stages");
    if (!stages.isOk()) return usage(stages.status().message(), "encode");
    s.stages = std::move(stages).value();
  }
  if (!integerOption(args, "--bits", kMinGridBits, kMaxGridBits, s.bits, error) ||
      !integerOption(args, "--normal-bits", 4, 16, s.normal_bits, error) ||
      !integerOption(args, "--color-bits", 1, 8, s.color_bits, error) ||
      !integerOption(args, "--uv-bits", 1, kMaxScalarBits, s.uv_bits, error))
    return usage(error, "encode");
  if (std::string target_error = targetOptions(args, s); !target_error.empty()) return usage(target_error, "encode");
  for (const char* name : {"--grid", "--tau"})
    if (args.has(name) && s.codec != "prm") return usage(std::string(name) + " applies to --codec prm only", "encode");
  if (!numberOption(args, "--grid", 1e-6, 1, s.codec_options.prm.grid, error) ||
      !numberOption(args, "--tau", 1e-3, 0.577, s.codec_options.prm.tau, error))
    return usage(error, "encode");
  s.keep_normals = !args.has("--no-normals");
  s.lossless_normals = args.has("--lossless-normals");
  s.keep_colors = !args.has("--no-colors");
  s.keep_scalars = !args.has("--no-scalars");
  s.allow_degenerate = args.has("--allow-degenerate");
  s.strict = args.has("--strict");
  if (!integerOption(args, "--tile-triangles", kMinTileTriangles, kMaxTileTriangles, s.tile_triangles, error) ||
      !integerOption(args, "--threads", 0, 4096, s.threads, error) || !budgetOption(args, s.memory_budget, error))
    return usage(error, "encode");
  if (const auto* d = args.get("--scratch-dir")) s.scratch_dir = *d;
  if (const auto* sub = args.get("--subset")) {
    auto share = parseShard(*sub, "--subset");
    if (!share.isOk()) return usage(share.status().message(), "encode");
    if (share->count < 2 || share->count > 65535) return usage("--subset i/N: N must be 2..65535", "encode");
    if (s.target.active())
      return usage("--subset does not go with a target: a target is met by the whole scan", "encode");
    s.subset_index = static_cast<uint16_t>(share->index);
    s.subset_count = static_cast<uint16_t>(share->count);
  }
  s.measure.enabled = args.has("--measure");
  if (!numberOption(args, "--samples-per-triangle", 1e-6, 1e6, s.measure.samples_per_triangle, error))
    return usage(error, "encode");
  // `-`: stdin and stdout (jobs/stdio.h); messages then go to stderr only.
  const auto* report = args.get("--report");
  const bool in_stdin = isStdio(s.input), out_stdout = isStdio(s.output), report_stdout = report && isStdio(*report);
  if (out_stdout && report_stdout) return usage("OUT and --report cannot both be - (stdout)", "encode");
  const std::string in_name = in_stdin ? "<stdin>" : s.input, out_name = out_stdout ? "<stdout>" : s.output;
  FILE* say = out_stdout || report_stdout ? stderr : stdout;
  const auto* format = args.get("--format");
  if (in_stdin && !format)
    return usage("a mesh on stdin (IN = -) needs --format ply|obj|stl|off (compressed: ply.zst, ...)", "encode");
  if (format && !in_stdin) return usage("--format is for a mesh on stdin (IN = -)", "encode");
  if (format && formatFromName("x." + *format) == MeshFormat::kUnknown)
    return usage("--format: must be ply, obj, stl or off, optionally with .zst, got '" + *format + "'", "encode");
  if (!out_stdout) {
    // Replacing the input is refused first (exit 1 either way); then a name that claims another format.
    if (Status ok = checkOutputPath(s.output, {s.input}); !ok.isOk()) return fail(ok);
    if (Status ok = checkContainerName(s.output); !ok.isOk()) return usage(ok.message(), "encode");
  }
  if (report && !report_stdout) {
    // The report must not replace the input nor the container it describes.
    Status ok = checkOutputPath(*report, {s.input, s.output}, "report");
    if (!ok.isOk()) return fail(ok);
  }
  std::optional<StdioSpool> spool;
  if (in_stdin || out_stdout) {
    auto created = StdioSpool::create(s.scratch_dir);
    if (!created.isOk()) return fail(created.status());
    spool.emplace(std::move(created).value());
    if (in_stdin) {
      auto copied = spool->readStdin("stdin." + *format);
      if (!copied.isOk()) return fail(copied.status());
      s.input = *copied;
    }
    if (out_stdout) s.output = spool->path("stdout.spz");
  }
  TerminalProgress progress(args.has("--quiet"));
  if (progress.enabled()) progress.file(0, 1, in_name);
  auto result = encodeFile(s, progress.enabled() ? &progress : nullptr);
  progress.clear();
  const std::string spooled_in = in_stdin ? s.input : "", spooled_out = out_stdout ? s.output : "";
  if (!result.isOk()) return failStdio(result.status(), spooled_in, spooled_out);
  if (!args.has("--quiet") && !result->read.dropped.empty())
    std::fprintf(stderr, "scanpress: warning: dropped %s (not kept by scanpress; --strict fails instead)\n",
                 describeDropped(result->read.dropped).c_str());
  if (report) {
    const std::string text = encodeReportJson(s, *result, settingsFingerprint(s));
    if (report_stdout) {
      if (std::fwrite(text.data(), 1, text.size(), stdout) != text.size() || std::fflush(stdout) != 0)
        return fail(makeError(ErrorCode::kIo, "<stdout>: cannot write the report"));
    } else {
      Status w = writeFileAtomically(*report, std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
      if (!w.isOk()) return fail(w);
    }
  }
  if (result->target && !args.has("--quiet")) {
    const TargetReport& t = *result->target;
    std::fprintf(say, "target %s: %s; %d bits%s, %zu attempt(s)", targetKindName(t.target.kind),
                 t.met ? "met" : "NOT met", t.bits, t.target.fixed_bits ? " (fixed)" : " (chosen)", t.attempts.size());
    if (t.target.kind == TargetKind::kMaxError)
      std::fprintf(say, ", %s error %.3e d (target %.3e d)", errorMetricName(t.target.metric), t.error,
                   t.target.max_error);
    if (t.knob_cells >= 0) std::fprintf(say, ", knob %.3g cells", t.knob_cells);
    std::fprintf(say, "\n");
  }
  if (result->target && !result->target->status.isOk())
    return failStdio(result->target->status, spooled_in, spooled_out);
  if (out_stdout)
    if (Status w = spool->writeStdout("stdout.spz"); !w.isOk()) return failStdio(w, spooled_in, spooled_out);
  if (!args.has("--quiet") && result->measured) {
    const ErrorStats sym = symmetricOf(statsOf(result->forward), statsOf(result->backward));
    const double d = result->diagonal > 0 ? result->diagonal : 1;
    std::fprintf(say, "error (symmetric): mean %.3e d, rms %.3e d, max %.3e d (d = %.6g)\n", sym.mean / d, sym.rms / d,
                 sym.max / d, result->diagonal);
  }
  if (!args.has("--quiet"))
    std::fprintf(say, "%s -> %s: %llu vertices, %llu faces, %llu bytes, %.3f bpv (%s, %d bits, %zu tiles)\n",
                 in_name.c_str(), out_name.c_str(), static_cast<unsigned long long>(result->vertices),
                 static_cast<unsigned long long>(result->faces), static_cast<unsigned long long>(result->bytes),
                 result->bitsPerVertex(), result->codec.c_str(), result->grid.bits, result->tiles.size());
  if (result->failed_tiles > 0) {
    for (const auto& t : result->tiles)
      if (!t.status.isOk()) std::fprintf(stderr, "scanpress: error: tile %u: %s\n", t.id, t.status.toString().c_str());
    return 2;
  }
  return 0;
}

int runDecode(int argc, char** argv) {
  Args args;
  std::string error;
  if (!parseArgs(argc, argv, 2,
                 {"--tiles", "--level", "--bytes", "--box", "--format", "--gltf-compression", "--gltf-nodes",
                  "--memory-budget", "--scratch-dir"},
                 {"--quiet", "--crop", "--help"}, args, error))
    return usage(error, "decode");
  if (args.has("--help")) return std::fputs(kDecodeHelp, stdout), 0;
  if (args.positional.size() != 2) return usage("decode needs IN.spz and OUT", "decode");
  DecodeSettings s;
  s.input = args.positional[0];
  s.output = args.positional[1];
  if (const auto* t = args.get("--tiles")) {
    auto ids = parseIntegerList(*t, 0, UINT32_MAX, 0, "--tiles");
    if (!ids.isOk()) return usage(ids.status().message(), "decode");
    s.tiles.emplace(ids->begin(), ids->end());
  }
  if (const auto* b = args.get("--box")) {
    auto v = parseNumberList(*b, -std::numeric_limits<double>::max(), std::numeric_limits<double>::max(), 6, "--box");
    if (!v.isOk()) return usage(v.status().message(), "decode");
    s.box.emplace();
    std::copy(v->begin(), v->end(), s.box->begin());
  }
  s.crop = args.has("--crop");
  if (const auto* c = args.get("--gltf-compression")) {
    auto parsed = parseGltfCompression(*c);
    if (!parsed.isOk()) return usage("--gltf-compression: " + parsed.status().message(), "decode");
    s.gltf_compression = *parsed;
  }
  if (const auto* n = args.get("--gltf-nodes")) {
    if (*n != "one" && *n != "tiles") return usage("--gltf-nodes: must be one or tiles, got '" + *n + "'", "decode");
    s.gltf_tile_nodes = *n == "tiles";
  }
  if (!unsignedOption(args, "--level", UINT32_MAX, s.level, error) ||
      !unsignedOption(args, "--bytes", UINT64_MAX, s.bytes, error) || !budgetOption(args, s.memory_budget, error))
    return usage(error, "decode");
  if (const auto* d = args.get("--scratch-dir")) s.scratch_dir = *d;
  // `-`: stdin and stdout (jobs/stdio.h); messages then go to stderr.
  const bool in_stdin = isStdio(s.input), out_stdout = isStdio(s.output);
  const std::string in_name = in_stdin ? "<stdin>" : s.input, out_name = out_stdout ? "<stdout>" : s.output;
  const auto* format = args.get("--format");
  if (out_stdout && !format)
    return usage("a mesh on stdout (OUT = -) needs --format ply|obj|stl|off|glb|gltf", "decode");
  if (format && !out_stdout) return usage("--format is for a mesh on stdout (OUT = -)", "decode");
  if (format && *format != "ply" && *format != "obj" && *format != "stl" && *format != "off" && *format != "glb" &&
      *format != "gltf")
    return usage("--format: must be ply, obj, stl, off, glb or gltf, got '" + *format + "'", "decode");
  std::optional<StdioSpool> spool;
  if (in_stdin || out_stdout) {
    auto created = StdioSpool::create();
    if (!created.isOk()) return fail(created.status());
    spool.emplace(std::move(created).value());
    if (in_stdin) {
      auto copied = spool->readStdin("stdin.spz");
      if (!copied.isOk()) return fail(copied.status());
      s.input = *copied;
    }
    if (out_stdout) s.output = spool->path("stdout." + *format);
  }
  auto result = decodeFile(s);
  const std::string spooled_in = in_stdin ? s.input : "", spooled_out = out_stdout ? s.output : "";
  if (!result.isOk()) return failStdio(result.status(), spooled_in, spooled_out);
  if (out_stdout)
    if (Status w = spool->writeStdout("stdout." + *format); !w.isOk()) return failStdio(w, spooled_in, spooled_out);
  FILE* say = out_stdout ? stderr : stdout;
  if (result->subset_count)  // never a silent part-for-whole, --quiet or not
    std::fprintf(stderr,
                 "scanpress: warning: %s is part %u of %u (encode --subset): it holds only the tiles t with "
                 "t %% %u == %u; scanpress merge joins the parts\n",
                 in_name.c_str(), unsigned(result->subset_index), unsigned(result->subset_count),
                 unsigned(result->subset_count), unsigned(result->subset_index));
  if (!args.has("--quiet"))
    std::fprintf(say, "%s -> %s: %llu vertices, %llu faces from %u tile(s)%s%s\n", in_name.c_str(), out_name.c_str(),
                 static_cast<unsigned long long>(result->vertices), static_cast<unsigned long long>(result->faces),
                 result->tiles, result->double_positions ? " (double positions)" : "",
                 result->streamed ? ", streamed under the memory budget" : "");
  if (!args.has("--quiet") && result->level)
    std::fprintf(say, "level %u: %llu payload bytes\n", *result->level,
                 static_cast<unsigned long long>(result->level_bytes));
  if (!result->dropped.empty())  // never silent, --quiet or not
    std::fprintf(stderr, "scanpress: warning: %s holds %s, which %s cannot: not written (decode to .ply keeps them)\n",
                 in_name.c_str(), describeDropped(result->dropped).c_str(), out_name.c_str());
  return 0;
}

int runInfo(int argc, char** argv) {
  Args args;
  std::string error;
  if (!parseArgs(argc, argv, 2, {"--memory-budget"}, {"--json", "--verify", "--help"}, args, error))
    return usage(error, "info");
  if (args.has("--help")) return std::fputs(kInfoHelp, stdout), 0;
  if (args.positional.size() != 1) return usage("info needs IN.spz", "info");
  uint64_t budget = kDefaultDecodeBudget;
  if (!budgetOption(args, budget, error)) return usage(error, "info");
  auto file = ContainerFile::open(args.positional[0]);
  if (!file.isOk()) return fail(file.status());
  if (args.has("--verify"))
    for (const auto& t : file->tiles()) {  // one tile at a time
      const uint64_t need = tileDecodeBytes(t, size_t(file->header().layout.scalarStride()));
      if (budget != 0 && need > budget)
        return fail(makeError(ErrorCode::kLimitExceeded,
                              file->path() + ": tile " + std::to_string(t.tile_id) + " needs about " +
                                  humanBytes(need) + " to decode, over the memory budget of " + humanBytes(budget) +
                                  ": give --memory-budget " + std::to_string((need >> 20) + 1) + "M or more"));
      auto m = file->decodeTile(t);
      if (!m.isOk()) return fail(m.status());
    }
  const std::string text = args.has("--json") ? containerInfoJson(*file) : containerInfoText(*file);
  std::fputs(text.c_str(), stdout);
  return 0;
}

int runJobCommand(int argc, char** argv) {
  Args args;
  std::string error;
  if (!parseArgs(argc, argv, 2, {"--threads", "--shard", "--shard-count"}, {"--force", "--quiet", "--merge", "--help"},
                 args, error))
    return usage(error, "run");
  if (args.has("--help")) return std::fputs(kRunHelp, stdout), 0;
  if (args.positional.size() != 1) return usage("run needs one JOB.json", "run");
  RunOptions options;
  options.force = args.has("--force");
  options.quiet = args.has("--quiet");
  if (!integerOption(args, "--threads", 0, 4096, options.threads, error)) return usage(error, "run");
  if (!args.has("--threads")) options.threads = -1;
  if (const auto* sh = args.get("--shard")) {
    if (args.has("--shard-count")) return usage("--shard and --shard-count: give one of them", "run");
    auto shard = parseShard(*sh, "--shard");
    if (!shard.isOk()) return usage(shard.status().message(), "run");
    options.shard = *shard;
  } else if (!args.has("--merge")) {
    std::optional<uint32_t> count;
    if (const auto* c = args.get("--shard-count")) {
      auto n = parseInteger(*c, 1, 65536, "--shard-count");
      if (!n.isOk()) return usage(n.status().message(), "run");
      count = static_cast<uint32_t>(*n);
    }
    auto shard = shardFromEnvironment(count);
    if (!shard.isOk()) return usage(shard.status().message(), "run");
    options.shard = *shard;
  }
  auto job = loadJobConfig(args.positional[0]);
  if (!job.isOk()) return fail(job.status());
  if (args.has("--merge")) {
    if (args.has("--shard") || args.has("--shard-count")) return usage("--merge runs no shard", "run");
    auto merged = mergeJobShards(*job);
    if (!merged.isOk()) return fail(merged.status());
    for (const auto& in : merged->missing)
      std::fprintf(stderr, "scanpress: error: %s: in no shard's summary (was the job or its inputs changed?)\n",
                   in.c_str());
    if (!options.quiet)
      std::printf("merged %llu files into %s\n", static_cast<unsigned long long>(merged->files),
                  (job->output_directory + "/" + job->summary_name).c_str());
    return merged->exit_code;
  }
  if (options.shard && !options.quiet) std::printf("shard %u of %u\n", options.shard->index, options.shard->count);
  auto batch = runJob(*job, options);
  if (!batch.isOk()) return fail(batch.status());
  return batch->exitCode();
}

int runMeasure(int argc, char** argv) {
  Args args;
  std::string error;
  if (!parseArgs(argc, argv, 2, {"--samples", "--samples-per-triangle", "--seed", "--memory-budget", "--scratch-dir"},
                 {"--json", "--monte-carlo", "--help"}, args, error))
    return usage(error, "measure");
  if (args.has("--help")) return std::fputs(kMeasureHelp, stdout), 0;
  if (args.positional.size() != 2) return usage("measure needs two meshes A and B", "measure");
  MeasureSettings s;
  if (!unsignedOption(args, "--samples", kMaxMeasureSamples, s.samples, error) ||
      !numberOption(args, "--samples-per-triangle", 1e-6, 1e6, s.samples_per_triangle, error) ||
      !unsignedOption(args, "--seed", UINT64_MAX, s.seed, error))
    return usage(error, "measure");
  s.stratified = !args.has("--monte-carlo");
  uint64_t budget = kDefaultDecodeBudget;
  if (!budgetOption(args, budget, error)) return usage(error, "measure");
  const std::string scratch = args.get("--scratch-dir") ? *args.get("--scratch-dir") : std::string();
  auto device = EmbreeDevice::create();
  if (!device.isOk()) return fail(device.status());
  Result<MeasureResult> r = makeError(ErrorCode::kInternal, "not measured");
  if (needsChunks(args.positional, budget)) {
    auto a = openSurface(args.positional[0], budget, scratch);
    if (!a.isOk()) return fail(a.status());
    auto b = openSurface(args.positional[1], budget, scratch);
    if (!b.isOk()) return fail(b.status());
    r = measureChunked(*a, *b, s, surfaceCacheBytes(budget), *device);
  } else {
    auto a = readSurfaceFile(args.positional[0]);
    if (!a.isOk()) return fail(a.status());
    auto b = readSurfaceFile(args.positional[1]);
    if (!b.isOk()) return fail(b.status());
    r = measureMeshes(*a, *b, s, *device);
  }
  if (!r.isOk()) return fail(r.status());
  if (args.has("--json")) {
    std::fputs(measureJson(*r).c_str(), stdout);
  } else {
    const double d = r->diagonal > 0 ? r->diagonal : 1;
    std::printf("bounding-box diagonal of A: %.9g\n", r->diagonal);
    for (auto [name, e] : {std::pair<const char*, ErrorStats>{"forward (A->B)", r->forward},
                           {"backward (B->A)", r->backward},
                           {"symmetric", r->symmetric}})
      std::printf("%-16s mean %.6g (%.3e d)  rms %.6g (%.3e d)  max %.6g (%.3e d)  [%llu samples]\n", name, e.mean,
                  e.mean / d, e.rms, e.rms / d, e.max, e.max / d, static_cast<unsigned long long>(e.samples));
  }
  return 0;
}

int runRender(int argc, char** argv) {
  Args args;
  std::string error;
  if (!parseArgs(argc, argv, 2,
                 {"--against", "--view", "--size", "--scale-max", "--memory-budget", "--scratch-dir", "--color-by",
                  "--shade"},
                 {"--help"}, args, error))
    return usage(error, "render");
  if (args.has("--help")) return std::fputs(kRenderHelp, stdout), 0;
  if (args.positional.size() != 2) return usage("render needs MESH and OUT.png", "render");
  if (const std::string ext = lowerExtension(args.positional[1]); ext != ".png")
    return usage("render writes PNG: OUT must end in .png, got '" + args.positional[1] + "'", "render");
  RenderSettings s;
  if (const auto* v = args.get("--view")) {
    auto view = parseNumberList(*v, -360, 360, 2, "--view");
    if (!view.isOk()) return usage(view.status().message(), "render");
    s.azimuth = (*view)[0];
    s.elevation = (*view)[1];
  }
  if (const auto* v = args.get("--size")) {
    auto size = parseIntegerList(*v, 16, 8192, 2, "--size");
    if (!size.isOk()) return usage(size.status().message(), "render");
    s.width = static_cast<int>((*size)[0]);
    s.height = static_cast<int>((*size)[1]);
  }
  if (const auto* v = args.get("--scale-max")) {
    if (!args.has("--against")) return usage("--scale-max needs --against (it scales the distance colors)", "render");
    auto e = parseNumber(*v, 0, 1e6, "--scale-max");
    if (!e.isOk()) return usage(e.status().message(), "render");
    if (!(*e > 0)) return usage("--scale-max must be positive, got '" + *v + "'", "render");
    s.scale_max_relative = *e;
  }
  if (const auto* v = args.get("--shade")) {
    if (*v != "faces" && *v != "normals") return usage("--shade is `faces` or `normals`, got '" + *v + "'", "render");
    s.vertex_normals = *v == "normals";
  }
  s.title = std::filesystem::path(args.positional[0]).filename().string();
  std::vector<std::string> inputs = {args.positional[0]};
  if (const auto* a = args.get("--against")) inputs.push_back(*a);
  uint64_t budget = kDefaultDecodeBudget;
  if (!budgetOption(args, budget, error)) return usage(error, "render");
  const std::string scratch = args.get("--scratch-dir") ? *args.get("--scratch-dir") : std::string();
  if (Status ok = checkOutputPath(args.positional[1], inputs); !ok.isOk()) return fail(ok);
  auto device = EmbreeDevice::create();
  if (!device.isOk()) return fail(device.status());
  Result<RenderResult> r = makeError(ErrorCode::kInternal, "not rendered");
  if (const auto* by = args.get("--color-by")) {
    if (*by != "reliefs" && *by != "regularity")
      return usage("--color-by is `reliefs` or `regularity`, got '" + *by + "'", "render");
    if (args.has("--against")) return usage("--color-by and --against both color the surface: give one", "render");
    if (!isContainerPath(inputs[0])) return usage("--color-by needs a prm container (.spz) as MESH", "render");
    auto picture =
        latticePicture(inputs[0], *by == "reliefs" ? LatticeColoring::kReliefs : LatticeColoring::kRegularity, budget);
    if (!picture.isOk()) return fail(picture.status());
    const double percent = picture->faces ? 100.0 * double(picture->regular_faces) / double(picture->faces) : 0.0;
    char share[64];
    std::snprintf(share, sizeof share, "  %.1f%% REGULAR", percent);
    s.title += share;
    s.legend = std::move(picture->legend);
    s.face_colors = std::move(picture->face_colors);
    r = renderMesh(picture->mesh, s, *device);
    if (r.isOk())
      std::printf("%s: %llu faces, %llu regular (%.1f%%)\n", inputs[0].c_str(),
                  static_cast<unsigned long long>(picture->faces),
                  static_cast<unsigned long long>(picture->regular_faces), percent);
  } else if (needsChunks(inputs, budget)) {
    auto mesh = openSurface(inputs[0], budget, scratch);
    if (!mesh.isOk()) return fail(mesh.status());
    std::optional<ChunkedSurface> original;
    if (inputs.size() > 1) {
      auto m = openSurface(inputs[1], budget, scratch);
      if (!m.isOk()) return fail(m.status());
      original.emplace(std::move(m).value());
    }
    r = renderSurface(*mesh, s, *device, original ? &*original : nullptr, surfaceCacheBytes(budget));
  } else {
    auto mesh = readSurfaceFile(inputs[0]);
    if (!mesh.isOk()) return fail(mesh.status());
    std::optional<Mesh> original;
    if (inputs.size() > 1) {
      auto m = readSurfaceFile(inputs[1]);
      if (!m.isOk()) return fail(m.status());
      original = std::move(m).value();
    }
    r = renderMesh(*mesh, s, *device, original ? &*original : nullptr);
  }
  if (!r.isOk()) return fail(r.status());
  Status w = writePng(args.positional[1], r->image);
  if (!w.isOk()) return fail(w);
  return 0;
}

int runMerge(int argc, char** argv) {
  Args args;
  std::string error;
  if (!parseArgs(argc, argv, 2, {}, {"--help", "--quiet"}, args, error)) return usage(error, "merge");
  if (args.has("--help")) return std::fputs(kMergeHelp, stdout), 0;
  if (args.positional.size() < 2) return usage("merge needs the parts and OUT.spz", "merge");
  const std::vector<std::string> parts(args.positional.begin(), args.positional.end() - 1);
  auto merged = mergeContainers(parts, args.positional.back());
  if (!merged.isOk()) return fail(merged.status());
  if (!args.has("--quiet"))
    std::printf("%zu parts -> %s: %u tiles, %llu bytes\n", parts.size(), args.positional.back().c_str(), merged->tiles,
                static_cast<unsigned long long>(merged->bytes));
  return 0;
}

int runReport(int argc, char** argv) {
  Args args;
  std::string error;
  if (!parseArgs(argc, argv, 2, {"--out", "--memory-budget"}, {"--help", "--no-thumbnails"}, args, error))
    return usage(error, "report");
  if (args.has("--help")) return std::fputs(kReportHelp, stdout), 0;
  if (args.positional.size() != 1) return usage("report needs DIR or SUMMARY.json", "report");
  const std::string summary = summaryPathOf(args.positional[0]);
  std::string out = (std::filesystem::path(summary).parent_path() / "report.html").string();
  if (const auto* o = args.get("--out")) out = *o;
  const std::string ext = lowerExtension(out);
  if (ext != ".html" && ext != ".htm")
    return usage("report writes HTML: --out must end in .html, got '" + out + "'", "report");
  if (Status ok = checkOutputPath(out, {summary}); !ok.isOk()) return fail(ok);
  HtmlReportOptions options;
  options.thumbnails = !args.has("--no-thumbnails");
  if (!budgetOption(args, options.memory_budget, error)) return usage(error, "report");
  if (Status ok = writeHtmlReport(summary, out, options); !ok.isOk()) return fail(ok);
  std::fprintf(stderr, "%s -> %s\n", summary.c_str(), out.c_str());
  return 0;
}

int runSynth(int argc, char** argv) {
  Args args;
  std::string error;
  if (!parseArgs(argc, argv, 2, {"--triangles", "--seed", "--from"}, {"--quiet", "--help"}, args, error))
    return usage(error, "synth");
  if (args.has("--help")) return std::fputs(kSynthHelp, stdout), 0;
  if (args.positional.size() != 1 || !args.has("--triangles"))
    return usage("synth needs OUT.ply and --triangles N", "synth");
  SynthSettings s;
  s.output = args.positional[0];
  if (!unsignedOption(args, "--triangles", UINT64_MAX, s.triangles, error) ||
      !unsignedOption(args, "--seed", UINT64_MAX, s.seed, error))
    return usage(error, "synth");
  if (const auto* f = args.get("--from")) s.from = *f;
  auto r = synthesize(s);
  if (!r.isOk()) return fail(r.status());
  if (!args.has("--quiet"))
    std::printf("%s: %llu vertices, %llu triangles (%llu base triangles, %u segments per edge)\n", s.output.c_str(),
                static_cast<unsigned long long>(r->vertices), static_cast<unsigned long long>(r->triangles),
                static_cast<unsigned long long>(r->base_triangles), r->segments);
  return 0;
}

int run(int argc, char** argv) {
  if (argc < 2) return std::fputs(kMainHelp, stderr), 1;
  const std::string cmd = argv[1];
  if (isHelp(cmd) || cmd == "help") {
    if (argc >= 3) {
      const std::string sub = argv[2];
      if (sub == "encode") return std::printf(kEncodeHelp, codecNames().c_str(), stageNames().c_str()), 0;
      if (sub == "decode") return std::fputs(kDecodeHelp, stdout), 0;
      if (sub == "info") return std::fputs(kInfoHelp, stdout), 0;
      if (sub == "run") return std::fputs(kRunHelp, stdout), 0;
      if (sub == "synth") return std::fputs(kSynthHelp, stdout), 0;
      if (sub == "measure") return std::fputs(kMeasureHelp, stdout), 0;
      if (sub == "render") return std::fputs(kRenderHelp, stdout), 0;
      if (sub == "report") return std::fputs(kReportHelp, stdout), 0;
      if (sub == "merge") return std::fputs(kMergeHelp, stdout), 0;
    }
    return std::fputs(kMainHelp, stdout), 0;
  }
  if (cmd == "--version") return std::printf("scanpress %s\n", kVersion), 0;
  if (cmd == "encode") return runEncode(argc, argv);
  if (cmd == "decode") return runDecode(argc, argv);
  if (cmd == "info") return runInfo(argc, argv);
  if (cmd == "run") return runJobCommand(argc, argv);
  if (cmd == "synth") return runSynth(argc, argv);
  if (cmd == "measure") return runMeasure(argc, argv);
  if (cmd == "render") return runRender(argc, argv);
  if (cmd == "report") return runReport(argc, argv);
  if (cmd == "merge") return runMerge(argc, argv);
  std::fprintf(stderr, "scanpress: error: unknown command '%s'\n\n%s", cmd.c_str(), kMainHelp);
  return 1;
}

}  // namespace
}  // namespace scanpress

// With SCANPRESS_PEAK_RSS_FILE set, the process writes its peak resident set (bytes) to that file on the way out:
// for tests that bound a command's memory (a parent's wait4 also counts the parent's own resident set).
static int finish(int code) {
  if (const char* path = std::getenv("SCANPRESS_PEAK_RSS_FILE"))
    if (std::FILE* f = std::fopen(path, "w")) {
      std::fprintf(f, "%llu\n", static_cast<unsigned long long>(scanpress::peakRss()));
      std::fclose(f);
    }
  return code;
}

int scanpress::cliMain(int argc, char** argv) {
  scanpress::tuneAllocator();  // before the first large allocation (jobs/process.h)
  // A file-size limit (ulimit -f) must fail the write with EFBIG (exit 3, temporaries removed), not kill the
  // process with SIGXFSZ; and SIGINT/SIGTERM/SIGHUP remove the temporaries before exiting (jobs/cleanup.h).
  // Both before any thread starts, so that every thread inherits them.
  ::signal(SIGXFSZ, SIG_IGN);
  scanpress::installInterruptCleanup();
  // A closed stdout (`scanpress decode X - --format ply | head`) is a write error that cleans up and exits 3, not a
  // SIGPIPE that would end the process before its temporaries are removed.
  ::signal(SIGPIPE, SIG_IGN);
  try {
    return finish(scanpress::run(argc, argv));
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "scanpress: error: out of memory\n");
    return 3;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scanpress: error: internal error: %s\n", e.what());
    return 4;
  }
}
