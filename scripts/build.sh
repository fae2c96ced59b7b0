#!/usr/bin/env bash
# Configures and builds Outcore. Usage: scripts/build.sh [release|asan]
# release -> build/, asan -> build-asan/ (AddressSanitizer + UBSan, Debug);
# OUTCORE_BUILD_DIR overrides the directory (parallel work trees of one checkout);
# OUTCORE_RELEASE_BUILD_TYPE the release build's CMake type (default
# RelWithDebInfo, for profiling; CI, which builds once from scratch, uses
# Release: the same -O3 code without debug information, faster to build).
# Both kinds compile in unity batches (CMakeLists.txt, OUTCORE_UNITY_BUILD):
# half the fresh build time; OUTCORE_UNITY_BUILD=0 compiles file by file (an
# edit then rebuilds one file, not its batch).
set -euo pipefail
cd "$(dirname "$0")/.."
kind=${1:-release}
jobs=$(nproc)
case "$kind" in
  release) dir=build; flags=(-DCMAKE_BUILD_TYPE="${OUTCORE_RELEASE_BUILD_TYPE:-RelWithDebInfo}" -DOUTCORE_WERROR=ON) ;;
  # -g1: line tables, all a sanitizer report needs, at a fraction of -g's build time.
  asan) dir=build-asan; flags=(-DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG=-g1 -DOUTCORE_SANITIZE=ON -DOUTCORE_WERROR=ON) ;;
  *) echo "usage: $0 [release|asan]" >&2; exit 2 ;;
esac
dir=${OUTCORE_BUILD_DIR:-$dir}
flags+=(-DOUTCORE_UNITY_BUILD="$([ "${OUTCORE_UNITY_BUILD:-1}" = 0 ] && echo OFF || echo ON)")
cmake -S . -B "$dir" -G Ninja "${flags[@]}" >/dev/null
ninja -C "$dir" -j "$jobs"
