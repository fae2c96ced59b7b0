"""What the benchmark drivers share: paths, running a command, packing a
scene into a work directory once, reading a store's triangles back, and
timing Open3D's cast_rays."""
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUTCORE = os.path.join(ROOT, "build", "client", "outcore")
HIT_DTYPE = np.dtype([("t_hit", "<f4"), ("geometry_id", "<u4"), ("primitive_id", "<u4"), ("u", "<f4"),
                      ("v", "<f4"), ("ng", "<f4", (3,))])


def run(cmd):
    """Runs cmd; its stdout, or exits naming the command and its stderr."""
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{r.stderr}")
    return r.stdout


def prepare_store(outcore, work, name, inputs, extra=()):
    """Packs `inputs` into work/NAME.oc unless it is there; writes `outcore
    info --json` to work/NAME.json. Returns (store, info path)."""
    store = os.path.join(work, name + ".oc")
    if not os.path.isdir(store):
        print(f"packing {name}", flush=True)
        run([outcore, "pack", *inputs, "-o", store, "-q", *extra])
    info = os.path.join(work, name + ".json")
    with open(info, "w") as f:
        f.write(run([outcore, "info", store, "--json"]))
    return store, info


def trace_repeated(outcore, store, rays_path, out, runs, cache_mb, extra=()):
    """`outcore trace --repeat runs` (2 threads) with a budget meant to hold the
    scene: the stats of every run (run 1 cold, the rest warm); exits if a warm
    run built a brick (the budget was too small)."""
    stats_path = out + ".stats.json"
    run([outcore, "trace", store, "--rays", rays_path, "-o", out, "--threads", "2", "--repeat", str(runs),
         "--cache-mb", str(cache_mb), "--stats-json", stats_path, *extra])
    with open(stats_path) as f:
        stats = json.load(f)
    stats = stats if isinstance(stats, list) else [stats]
    if any(s["brick_builds"] > 0 for s in stats[1:]):
        sys.exit(f"a warm run of {rays_path} built bricks: raise --cache-mb (now {cache_mb})")
    return stats


def make_rays(info, kind, count, path):
    """bench/make_rays.py: `count` rays of `kind` (incoherent, camera) for the scene of `info`."""
    run([sys.executable, os.path.join(ROOT, "bench", "make_rays.py"), info, kind, str(count), path])
    return np.load(path)


def read_store_triangles(store):
    """Triangles and ids in brick-file order, from the self-describing brick headers."""
    data = np.fromfile(os.path.join(store, "bricks.dat"), dtype=np.uint8)
    tris, ids, offset = [], [], 0
    while offset + 32 <= data.size:
        header = data[offset:offset + 32]
        if bytes(header[:7]) != b"OCBRICK":
            offset += 4096
            continue
        count = int(header[12:16].view("<u4")[0])
        body = offset + 32
        tris.append(data[body:body + count * 36].view("<f4").reshape(count, 9))
        ids.append(data[body + count * 36:body + count * 44].view("<u4").reshape(count, 2))
        offset = (body + count * 44 + 4095) // 4096 * 4096
    return np.concatenate(tris), np.concatenate(ids)


def open3d_scene(tris):
    """An Open3D RaycastingScene of the (N, 9) triangles, unindexed."""
    import open3d as o3d
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(tris.reshape(-1, 3))),
                        o3d.core.Tensor(np.arange(tris.shape[0] * 3, dtype=np.uint32).reshape(-1, 3)))
    return scene


def open3d_timed_cast(scene, rays, runs):
    """cast_rays(nthreads=2) `runs` times after a one-ray call (Open3D builds
    its BVH on the first call); returns (median seconds, last result)."""
    import open3d as o3d
    rays_t = o3d.core.Tensor(rays)
    scene.cast_rays(rays_t[:1], nthreads=2)
    times, result = [], None
    for _ in range(runs):
        t0 = time.perf_counter()
        result = scene.cast_rays(rays_t, nthreads=2)
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result
