#!/usr/bin/env bash
# Checks that every tracked C++ file is formatted as .clang-format says (clang-format 14, Debian 12).
# With --fix, formats them in place instead.
set -euo pipefail
cd "$(dirname "$0")/.."
mode=(--dry-run -Werror)
case "${1:-}" in
  --fix) mode=(-i) ;;
  "") ;;
  *) echo "check_format.sh: unknown option $1 (known: --fix)" >&2; exit 2 ;;
esac
git ls-files -z '*.h' '*.cpp' | xargs -0 clang-format --style=file "${mode[@]}"
