#!/usr/bin/env bash
# Checks that every tracked C++ source and header is formatted as .clang-format says (clang-format 14, Debian
# 12's; installed when missing). Lists the differences and exits non-zero when a file differs.
# Reformat: git ls-files '*.cpp' '*.h' | xargs clang-format -i
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/lib.sh
command -v clang-format >/dev/null || install_missing_packages clang-format
if ! git ls-files -z '*.cpp' '*.h' | xargs -0 clang-format --dry-run -Werror; then
  echo "check-format: files differ from .clang-format (reformat: git ls-files '*.cpp' '*.h' | xargs clang-format -i)" >&2
  exit 1
fi
echo "check-format: $(git ls-files '*.cpp' '*.h' | wc -l) files match .clang-format"
