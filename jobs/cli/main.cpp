// The scanpress command line. Exit codes: 0 ok, 1 usage or config error, 2 bad input data, 3 environment (I/O,
// disk full), 4 internal error.
#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

#include "engine/codecs/codec.h"
#include "jobs/commands.h"
#include "jobs/container_file.h"
#include "jobs/file_io.h"
#include "jobs/report.h"

namespace scanpress {
namespace {

constexpr const char* kVersion = "0.1.0";

constexpr const char* kMainHelp = R"(scanpress: parallel batch compression for large 3D scans

usage: scanpress <command> [options]

commands:
  encode   compress a mesh file (PLY, OBJ, STL, OFF; optionally .zst) into a .spz container
  decode   decompress a container (or some of its tiles) into a PLY or OBJ file
  info     describe a container

'scanpress <command> --help' shows a command's options.
exit codes: 0 ok, 1 usage or config error, 2 bad input data, 3 environment (I/O, disk full), 4 internal error
)";

constexpr const char* kEncodeHelp = R"(usage: scanpress encode IN OUT.spz [options]

Compresses the mesh IN into the container OUT.spz. The output appears complete or not at all.

options:
  --codec NAME        tile codec (default store; available: %s)
  --bits N            quantization bits, 8..24 (default 16): the largest bounding-box extent is divided into 2^N
                      cubic cells, as Draco's -qp does
  --normal-bits N     octahedral bits per normal component, 4..16 (default 12)
  --no-normals        drop normals
  --no-colors         drop colors
  --report R.json     write a JSON report (counts, bytes, bits per vertex, seconds per stage, dropped elements)
  --quiet             print nothing on success
)";

constexpr const char* kDecodeHelp = R"(usage: scanpress decode IN.spz OUT.(ply|obj) [options]

Decompresses a container into a mesh file (PLY binary little endian or OBJ, by extension). Positions are cell
centers of the container's grid; they are written as float, or as double when float cannot hold the grid.

options:
  --tiles ID,ID,...   decode only these tiles (welded together)
  --quiet             print nothing on success
)";

constexpr const char* kInfoHelp = R"(usage: scanpress info IN.spz [options]

Describes a container: grid, counts, size, attributes and tiles.

options:
  --json      print JSON: {"grid": {"origin", "cell", "bits"}, "vertices", "faces", "bytes", "tiles": [...]}
  --verify    also read every tile and check its checksums and decoding
)";

struct UsageError {
  std::string message;
};

int fail(const Status& s) {
  std::fprintf(stderr, "scanpress: error: %s\n", s.toString().c_str());
  return exitCodeFor(s.code());
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

bool parseIntOption(const Args& args, const std::string& name, int lo, int hi, int& value, std::string& error) {
  const std::string* v = args.get(name);
  if (!v) return true;
  char* end = nullptr;
  errno = 0;
  const long x = std::strtol(v->c_str(), &end, 10);
  if (v->empty() || *end != '\0' || errno != 0 || x < lo || x > hi)
    return error = name + " must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got '" +
                   *v + "'",
           false;
  value = static_cast<int>(x);
  return true;
}

std::string codecList() {
  std::string s;
  for (const auto& c : allCodecs()) s += (s.empty() ? "" : ", ") + std::string(c.name);
  return s;
}

int runEncode(int argc, char** argv) {
  Args args;
  std::string error;
  if (!parseArgs(argc, argv, 2, {"--codec", "--bits", "--normal-bits", "--report"},
                 {"--no-normals", "--no-colors", "--quiet", "--help"}, args, error))
    return usage(error, "encode");
  if (args.has("--help")) {
    std::printf(kEncodeHelp, codecList().c_str());
    return 0;
  }
  if (args.positional.size() != 2) return usage("encode needs IN and OUT", "encode");
  EncodeSettings s;
  s.input = args.positional[0];
  s.output = args.positional[1];
  if (const auto* c = args.get("--codec")) s.codec = *c;
  if (!findCodec(s.codec)) return usage("unknown codec '" + s.codec + "' (available: " + codecList() + ")", "encode");
  if (!parseIntOption(args, "--bits", kMinGridBits, kMaxGridBits, s.bits, error) ||
      !parseIntOption(args, "--normal-bits", 4, 16, s.normal_bits, error))
    return usage(error, "encode");
  s.keep_normals = !args.has("--no-normals");
  s.keep_colors = !args.has("--no-colors");
  auto result = encodeFile(s);
  if (!result.isOk()) return fail(result.status());
  if (const auto* report = args.get("--report")) {
    const std::string text = encodeReportJson(s, *result);
    Status w = writeFileAtomically(*report, std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
    if (!w.isOk()) return fail(w);
  }
  if (!args.has("--quiet"))
    std::printf("%s -> %s: %llu vertices, %llu faces, %llu bytes, %.3f bpv (%s, %d bits)\n", s.input.c_str(),
                s.output.c_str(), static_cast<unsigned long long>(result->vertices),
                static_cast<unsigned long long>(result->faces), static_cast<unsigned long long>(result->bytes),
                result->bitsPerVertex(), result->codec.c_str(), s.bits);
  return 0;
}

bool parseTileList(const std::string& text, std::vector<uint32_t>& out, std::string& error) {
  size_t i = 0;
  while (i <= text.size()) {
    const size_t comma = std::min(text.find(',', i), text.size());
    const std::string part = text.substr(i, comma - i);
    char* end = nullptr;
    errno = 0;
    const unsigned long long v = std::strtoull(part.c_str(), &end, 10);
    if (part.empty() || *end != '\0' || errno != 0 || v > UINT32_MAX || part[0] == '-')
      return error = "--tiles expects tile ids separated by commas, got '" + text + "'", false;
    out.push_back(static_cast<uint32_t>(v));
    i = comma + 1;
  }
  return true;
}

int runDecode(int argc, char** argv) {
  Args args;
  std::string error;
  if (!parseArgs(argc, argv, 2, {"--tiles"}, {"--quiet", "--help"}, args, error)) return usage(error, "decode");
  if (args.has("--help")) return std::fputs(kDecodeHelp, stdout), 0;
  if (args.positional.size() != 2) return usage("decode needs IN.spz and OUT", "decode");
  DecodeSettings s;
  s.input = args.positional[0];
  s.output = args.positional[1];
  if (const auto* t = args.get("--tiles")) {
    std::vector<uint32_t> ids;
    if (!parseTileList(*t, ids, error)) return usage(error, "decode");
    s.tiles = std::move(ids);
  }
  auto result = decodeFile(s);
  if (!result.isOk()) return fail(result.status());
  if (!args.has("--quiet"))
    std::printf("%s -> %s: %llu vertices, %llu faces from %u tile(s)%s\n", s.input.c_str(), s.output.c_str(),
                static_cast<unsigned long long>(result->vertices), static_cast<unsigned long long>(result->faces),
                result->tiles, result->double_positions ? " (double positions)" : "");
  return 0;
}

int runInfo(int argc, char** argv) {
  Args args;
  std::string error;
  if (!parseArgs(argc, argv, 2, {}, {"--json", "--verify", "--help"}, args, error)) return usage(error, "info");
  if (args.has("--help")) return std::fputs(kInfoHelp, stdout), 0;
  if (args.positional.size() != 1) return usage("info needs IN.spz", "info");
  auto file = ContainerFile::open(args.positional[0]);
  if (!file.isOk()) return fail(file.status());
  if (args.has("--verify"))
    for (const auto& t : file->tiles()) {
      auto m = file->decodeTile(t);
      if (!m.isOk()) return fail(m.status());
    }
  const std::string text = args.has("--json") ? containerInfoJson(*file) : containerInfoText(*file);
  std::fputs(text.c_str(), stdout);
  return 0;
}

int run(int argc, char** argv) {
  if (argc < 2) return std::fputs(kMainHelp, stderr), 1;
  const std::string cmd = argv[1];
  if (isHelp(cmd) || cmd == "help") {
    if (argc >= 3) {
      const std::string sub = argv[2];
      if (sub == "encode") return std::printf(kEncodeHelp, codecList().c_str()), 0;
      if (sub == "decode") return std::fputs(kDecodeHelp, stdout), 0;
      if (sub == "info") return std::fputs(kInfoHelp, stdout), 0;
    }
    return std::fputs(kMainHelp, stdout), 0;
  }
  if (cmd == "--version") return std::printf("scanpress %s\n", kVersion), 0;
  if (cmd == "encode") return runEncode(argc, argv);
  if (cmd == "decode") return runDecode(argc, argv);
  if (cmd == "info") return runInfo(argc, argv);
  std::fprintf(stderr, "scanpress: error: unknown command '%s'\n\n%s", cmd.c_str(), kMainHelp);
  return 1;
}

}  // namespace
}  // namespace scanpress

int main(int argc, char** argv) {
  try {
    return scanpress::run(argc, argv);
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "scanpress: error: out of memory\n");
    return 3;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scanpress: error: internal error: %s\n", e.what());
    return 4;
  }
}
