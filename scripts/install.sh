#!/usr/bin/env bash
# Installs exactly what is missing for building, testing and benchmarking Outcore
# on Debian 12: apt packages (all C++ dependencies) and a Python venv in .venv.
# Idempotent: a second run installs nothing and takes a second or two.
# With --bench it also makes .venv-bench with Open3D and matplotlib.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PACKAGES=(
  build-essential cmake ninja-build pkg-config clang-format
  libembree-dev libopenvdb-dev libcereal-dev libxxhash-dev
  libboost-dev  # OpenVDB's headers include Boost; libopenvdb-dev does not pull it in
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler grpc-proto
  libspdlog-dev libtbb-dev libcli11-dev
  libcpp-httplib-dev  # the server's metrics endpoint
  openssl  # the TLS tests make their certificates with it
  libgtest-dev libgmock-dev libbenchmark-dev zlib1g-dev
  python3-venv python3-dev
)

missing=()
for p in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "[install] apt packages missing: ${missing[*]}"
  SUDO=""
  [ "$(id -u)" = 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

PY_REQS=scripts/requirements.txt
if [ ! -x .venv/bin/python ]; then
  echo "[install] creating .venv"
  python3 -m venv .venv
fi
stamp=.venv/.requirements.sha
want=$(sha256sum "$PY_REQS" | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  echo "[install] pip install -r $PY_REQS"
  .venv/bin/pip install -q --upgrade pip >/dev/null
  .venv/bin/pip install -q -r "$PY_REQS"
  echo "$want" > "$stamp"
fi
# The Python client (client/python; stubs generated from proto/ at build time),
# reinstalled only when its sources or the proto changed.
client_stamp=.venv/.outcore-client.sha
client_want=$(find client/python/pyproject.toml client/python/setup.py client/python/src \
    proto/outcore/v1/scene_query.proto -type f ! -name '*_pb2*' ! -path '*/__pycache__/*' \
    ! -path '*.egg-info/*' | LC_ALL=C sort | xargs sha256sum | sha256sum | cut -d' ' -f1)
if [ "$(cat "$client_stamp" 2>/dev/null)" != "$client_want" ] || ! .venv/bin/python -c 'import outcore' 2>/dev/null; then
  echo "[install] pip install ./client/python"
  .venv/bin/pip install -q ./client/python
  echo "$client_want" > "$client_stamp"
fi
# Benchmarks compare against Open3D (large), kept out of the test venv.
if [ "${1:-}" = "--bench" ]; then
  missing=()
  for p in libusb-1.0-0 libgl1 libgomp1; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if ((${#missing[@]})); then
    SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  fi
  [ -x .venv-bench/bin/python ] || python3 -m venv .venv-bench
  bench_stamp=.venv-bench/.requirements.sha
  bench_want=$(sha256sum scripts/requirements-bench.txt | cut -d' ' -f1)
  if [ "$(cat "$bench_stamp" 2>/dev/null)" != "$bench_want" ]; then
    .venv-bench/bin/pip install -q -r scripts/requirements-bench.txt
    echo "$bench_want" > "$bench_stamp"
  fi
  # The remote benchmark drives the Python client from this venv too.
  if [ "$(cat .venv-bench/.outcore-client.sha 2>/dev/null)" != "$client_want" ]; then
    .venv-bench/bin/pip install -q ./client/python
    echo "$client_want" > .venv-bench/.outcore-client.sha
  fi
fi
echo "[install] ok"
