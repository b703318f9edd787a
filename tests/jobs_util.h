// Helpers of the jobs-layer tests: running the scanpress binary, finding the shared scan set.
#pragma once

#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <string>

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

inline std::string sharedDataDir() {
  if (const char* env = std::getenv("SCANPRESS_DATA")) return env;
  return SCANPRESS_SHARED_DATA;
}

}  // namespace scanpress::testing
