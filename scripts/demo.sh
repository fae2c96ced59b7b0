#!/usr/bin/env bash
# The README's main-job command: installs what is missing, builds, packs the
# built-in procedural scene (a city of 2,000 icospheres on a fractal terrain,
# about 10.6 M triangles) into a scene store and describes it.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
bash scripts/build.sh release >/dev/null
bin=build/client/outcore
work=${OUTCORE_DEMO_DIR:-build/demo}
mkdir -p "$work"
scene="$work/city.oc"
echo "== outcore pack (built-in procedural scene)"
"$bin" pack 'gen:city?of=(gen:sphere?level=4)&copies=2000' 'gen:terrain?n=256&size=600&height=20' \
  -o "$scene" --brick-tris 32768 --mem-mb 512 --force
echo
echo "== outcore info"
"$bin" info "$scene"
