#!/usr/bin/env bash
# The README's main-job command: installs what is missing, builds, packs the
# built-in procedural scene (a city of 2,000 icospheres on a fractal terrain,
# about 10.4 M triangles) into a scene store, describes it, and traces 1 M
# camera rays against it in process under a 256 MiB cache budget (a fraction of
# the scene's built size), printing a few hits and the cache figures.
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
"$bin" info "$scene" --json > "$work/city.json"
.venv/bin/python bench/make_rays.py "$work/city.json" camera 1000000 "$work/camera.npy"
echo
echo "== outcore trace (1 M camera rays, --cache-mb 256, cold then warm)"
"$bin" trace "$scene" --rays "$work/camera.npy" -o "$work/hits.npy" --cache-mb 256 --repeat 2 --stats
echo
echo "== a few hits ($work/hits.npy)"
.venv/bin/python - "$work/hits.npy" <<'PY'
import sys
import numpy as np
hits = np.load(sys.argv[1])
hit = np.flatnonzero(hits["primitive_id"] != 0xFFFFFFFF)
print(f"{hit.size} of {hits.size} rays hit")
for i in hit[:: max(1, hit.size // 5)][:5]:
    h = hits[i]
    print(f"ray {i}: t={h['t_hit']:.4f} geometry {h['geometry_id']} primitive {h['primitive_id']} "
          f"u={h['u']:.3f} v={h['v']:.3f} ng={np.round(h['ng'], 3)}")
PY
