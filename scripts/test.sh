#!/usr/bin/env bash
# The README's test command: installs what is missing, builds, and runs every
# test — the unit and integration suite (ctest) and the Python client's tests
# (pytest, tests/python) on the optimised build, then the C++ suite once more
# under AddressSanitizer + UndefinedBehaviorSanitizer.
# Set OUTCORE_SKIP_ASAN=1 to skip the sanitizer pass locally.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
start=$(date +%s)
# A fresh CI machine builds everything once: no debug information for the
# optimised build (the sanitizer build keeps it for its reports).
if [ "${CI:-}" = true ]; then export OUTCORE_RELEASE_BUILD_TYPE="${OUTCORE_RELEASE_BUILD_TYPE:-Release}"; fi

echo "== build (release)"
bash scripts/build.sh release
echo "== tests (release)"
ctest --test-dir build --output-on-failure -j "$(nproc)" --timeout 900
echo "== tests (python client)"
OUTCORE_BINARY=build/client/outcore .venv/bin/python -m pytest tests/python -q -p no:cacheprovider

if [ "${OUTCORE_SKIP_ASAN:-0}" != 1 ]; then
  echo "== build (asan+ubsan)"
  bash scripts/build.sh asan
  echo "== tests (asan+ubsan)"
  ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    ctest --test-dir build-asan --output-on-failure -j "$(nproc)" --timeout 1800
fi
echo "== all tests passed in $(( $(date +%s) - start )) s"
