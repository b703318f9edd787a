// Helpers of the jobs-layer tests: running the scanpress binary, finding the shared scan set.
#pragma once

#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "engine/mesh.h"
#include "jobs/commands.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/pipeline.h"

#include "test_util.h"

namespace scanpress::testing {

// Runs the scanpress binary with `args` (shell words), capturing stdout and stderr; returns its exit code.
// `env`: shell assignments (NAME='value' ...) for the command.
inline int runScanpress(const std::string& args, std::string* out = nullptr, const std::string& env = "") {
  FILE* p = ::popen((env + " '" + SCANPRESS_BIN + "' " + args + " 2>&1").c_str(), "r");
  std::string text;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) text.append(buf, n);
  const int status = ::pclose(p);
  if (out) *out = text;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// runScanpress without extra environment: `run("encode a.ply a.spz", &out)`.
inline int run(const std::string& args, std::string* out = nullptr) { return runScanpress(args, out); }

// The Stanford bunny scan committed in the repo (data/).
inline const std::string kBunny = std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";

// The Khronos glTF validator (npm package gltf-validator, scripts/install-test-tools.sh) on `path`: its summary,
// "errors=E warnings=W infos=I [first messages]", or "SKIP: why" when node or the validator is missing. `work`: a
// directory for the script.
inline std::string validateGltf(const std::string& path, const std::string& work) {
  if (std::system("command -v node >/dev/null 2>&1") != 0) return "SKIP: no node";
  const std::string script = work + "/validate-gltf.js";
  if (FILE* f = std::fopen(script.c_str(), "w")) {
    std::fputs(R"(const fs = require('fs');
let v;
try { v = require('gltf-validator'); } catch (e) { console.log('NO-VALIDATOR'); process.exit(0); }
v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])), {externalResourceFunction: () => Promise.reject('none')})
  .then((r) => console.log('errors=' + r.issues.numErrors + ' warnings=' + r.issues.numWarnings + ' infos=' +
                           r.issues.numInfos + ' ' + JSON.stringify(r.issues.messages.slice(0, 4))))
  .catch((e) => console.log('exception ' + e));
)",
               f);
    std::fclose(f);
  }
  FILE* p =
      ::popen(("NODE_PATH=\"$(npm root -g 2>/dev/null)\" node '" + script + "' '" + path + "' 2>&1").c_str(), "r");
  std::string result;
  for (int c; (c = std::fgetc(p)) != EOF;) result += static_cast<char>(c);
  ::pclose(p);
  if (result.find("NO-VALIDATOR") != std::string::npos)
    return "SKIP: gltf-validator not installed (scripts/install-test-tools.sh)";
  return result;
}

// Base64 (RFC 4648) decoding, for data URIs in written files; stops at the first byte outside the alphabet.
inline std::vector<uint8_t> unbase64(const std::string& s) {
  std::vector<uint8_t> out;
  uint32_t acc = 0;
  int bits = 0;
  for (char c : s) {
    const int v = c >= 'A' && c <= 'Z'   ? c - 'A'
                  : c >= 'a' && c <= 'z' ? c - 'a' + 26
                  : c >= '0' && c <= '9' ? c - '0' + 52
                  : c == '+'             ? 62
                  : c == '/'             ? 63
                                         : -1;
    if (v < 0) break;
    acc = acc << 6 | uint32_t(v);
    bits += 6;
    if (bits >= 8) out.push_back(uint8_t(acc >> (bits -= 8)));
  }
  return out;
}

// A mesh's triangles as corner positions (float, rotated to the smallest corner), sorted: the same surface
// whatever the vertex order, duplication or split into parts.
inline std::vector<std::array<std::array<float, 3>, 3>> positionTriangles(const Mesh& m) {
  std::vector<std::array<std::array<float, 3>, 3>> t;
  for (const auto& tri : m.triangles) {
    std::array<std::array<float, 3>, 3> c;
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) c[k][a] = static_cast<float>(m.positions[tri[k]][a]);
    std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
    t.push_back(c);
  }
  std::sort(t.begin(), t.end());
  return t;
}

// An encode of `input` to `output` with `codec` on two threads: what the file tests start from.
inline EncodeSettings encodeSettings(const std::string& input, const std::string& output, const std::string& codec) {
  EncodeSettings s;
  s.input = input;
  s.output = output;
  s.codec = codec;
  s.threads = 2;
  return s;
}

// A target of RMS error `max_error` (relative to the diagonal) on `s`.
inline void setRmsTarget(EncodeSettings& s, double max_error) {
  s.target.kind = TargetKind::kMaxError;
  s.target.metric = ErrorMetric::kRms;
  s.target.max_error = max_error;
}

// `spz` decoded whole to the mesh file `out` (its extension says the format), and read back as in the file.
inline Result<Mesh> decodeAndReadBack(const std::string& spz, const std::string& out) {
  DecodeSettings d;
  d.input = spz;
  d.output = out;
  SP_RETURN_IF_ERROR(decodeFile(d).status());
  return readMeshFile(out);
}

inline std::string sharedDataDir() {
  if (const char* env = std::getenv("SCANPRESS_DATA")) return env;
  return SCANPRESS_SHARED_DATA;
}

}  // namespace scanpress::testing
