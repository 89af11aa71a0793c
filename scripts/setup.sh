#!/usr/bin/env bash
# Installs the Debian packages rcbench builds and runs with (only those missing), then builds the
# rcbench executable alone (Release) into build/: the test suite and the micro-benchmarks are left
# to the README's test command, which builds everything in the same build/.
#   --deps-only    stop after the packages
#   --test-tools   also install what CI's checks use: chromium (the report rendering test), clang with
#                  its sanitizer and libFuzzer runtime (the sanitizer build), Ninja (CI's builds),
#                  clang-format, and libclang's Python bindings (scripts/check_function_length.py)
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(cmake make g++ git pkg-config libgtest-dev nlohmann-json3-dev libcli11-dev libtbb-dev zlib1g-dev liblzma-dev libsqlite3-dev libceres-dev libeigen3-dev gnuplot-nox libnlopt-cxx-dev libembree-dev libbullet-dev libassimp-dev libzip-dev libode-dev jq)

deps_only=0
for arg in "$@"; do
  case "$arg" in
    --deps-only) deps_only=1 ;;
    --test-tools) packages+=(chromium clang libclang-rt-14-dev ninja-build clang-format python3-clang-14) ;;
    *) echo "setup.sh: unknown option $arg (known: --deps-only, --test-tools)" >&2; exit 2 ;;
  esac
done

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  echo "setup: installing ${missing[*]}"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
if [ "$deps_only" = 1 ]; then exit 0; fi

cmake -S . -B build -DCMAKE_BUILD_TYPE=Release
cmake --build build -j"$(nproc)" --target rcbench
