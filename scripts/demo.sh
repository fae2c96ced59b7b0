#!/usr/bin/env bash
# The README's main-job command: installs what is missing, builds, packs the
# built-in procedural scene (a city of 2,000 icospheres on a fractal terrain,
# about 10.4 M triangles) into a scene store, describes it, starts `outcore
# serve` on a loopback port under a 256 MiB cache budget (a fraction of the
# scene's built size), queries 1 M camera rays from the C++ CLI and from the
# Python client, prints a few hits and the cache figures, renders a depth
# picture of the city through the server (`outcore render --server`, written
# to demo-city.png in the work directory), stops the server (SIGTERM), and
# checks that in-process `outcore trace` answers identically.
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
echo "== outcore serve (loopback, --cache-mb 256)"
log="$work/serve.log"
"$bin" serve "$scene" --listen 127.0.0.1:0 --cache-mb 256 >"$log" 2>&1 &
server_pid=$!
trap 'kill -TERM "$server_pid" 2>/dev/null || true' EXIT
address=""
for _ in $(seq 1 600); do
  address=$(sed -n 's/.*listening on \([0-9.]*:[0-9]*\).*/\1/p' "$log" | head -n 1)
  [ -n "$address" ] && break
  kill -0 "$server_pid" 2>/dev/null || { cat "$log"; echo "outcore serve exited early" >&2; exit 1; }
  sleep 0.1
done
[ -n "$address" ] || { cat "$log"; echo "outcore serve did not start" >&2; exit 1; }
echo "serving $scene on $address"
echo
echo "== outcore query (1 M camera rays, C++ client: one gRPC call, rays and hits through shared memory on this host)"
"$bin" query --server "$address" --rays "$work/camera.npy" -o "$work/hits.npy" --stats
echo
echo "== outcore.SceneClient (the same rays from Python)"
.venv/bin/python - "$address" "$work/camera.npy" "$work/hits.npy" <<'PY'
import sys
import time
import numpy as np
import outcore

address, rays_path, cli_hits_path = sys.argv[1:]
rays = np.load(rays_path)
with outcore.SceneClient(address, timeout=600) as scene:
    t0 = time.perf_counter()
    ans = scene.cast_rays(rays)
    seconds = time.perf_counter() - t0
    shared = scene.last_call_shared
    occluded = scene.test_occlusions(rays[::10])  # every 10th pixel
    stats = scene.stats()
hit = np.flatnonzero(np.isfinite(ans["t_hit"]))
print(f"cast_rays: {rays.shape[0]} rays in {seconds:.2f} s ({rays.shape[0] / seconds / 1e6:.2f} M rays/s, "
      f"{'through shared memory' if shared else 'over gRPC bytes'}), "
      f"{hit.size} hit; test_occlusions on every 10th ray: {int(occluded.sum())} of {occluded.size} occluded")
for i in hit[:: max(1, hit.size // 5)][:5]:
    print(f"ray {i}: t={ans['t_hit'][i]:.4f} geometry {ans['geometry_ids'][i]} primitive {ans['primitive_ids'][i]} "
          f"uv={np.round(ans['primitive_uvs'][i], 3)} ng={np.round(ans['primitive_normals'][i], 3)}")
cli = np.load(cli_hits_path)
same = (np.array_equal(cli["primitive_id"], ans["primitive_ids"]) and
        np.array_equal(cli["t_hit"].view(np.uint32), ans["t_hit"].view(np.uint32)))
print("Python answers equal the CLI's bitwise:", same)
print("server cache figures: " + ", ".join(
    f"{k}={stats[k]}" for k in ("brick_builds", "cache_hits", "cache_misses", "evictions",
                                "resident_bytes", "peak_resident_bytes", "cache_budget_bytes",
                                "eviction_policy")))
if not same:
    sys.exit("the Python and CLI answers differ")
PY
echo
echo "== outcore render --server (a depth picture of the city, rays made and coloured here, traced by the server)"
# The camera: low over a part of the city where the icospheres stand above
# the terrain (elsewhere the terrain's hills hide most of them), looking
# along the ground; --up is the world's up (y).
"$bin" render --server "$address" --eye=-60,22,-50 --center=-125,0,-135 --up=0,1,0 --fov 60 \
  --size 1280x720 --mode depth -o "$work/demo-city.png"
echo "depth picture of the city: $work/demo-city.png"
echo
echo "== stopping the server (SIGTERM: drains, exits 0)"
kill -TERM "$server_pid"
wait "$server_pid"
trap - EXIT
tail -n 3 "$log"
echo
echo "== outcore trace (in process, the same rays; answers must equal the server's)"
"$bin" trace "$scene" --rays "$work/camera.npy" -o "$work/hits_trace.npy" --cache-mb 256 --stats
cmp "$work/hits.npy" "$work/hits_trace.npy" && echo "trace and query answers are bitwise identical"
