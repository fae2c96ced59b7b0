"""`--brick-accel auto` and `outcore calibrate` end to end: calibrate writes
a profile from a store's bricks that `trace` and `serve` read; a server with
auto answers bitwise as one with bvh bricks over gRPC, and GetStats counts
its builds per structure; bad profiles are errors naming the file and line.
"""

from __future__ import annotations

import subprocess

import numpy as np

import outcore
from support import Server, binary, make_rays, run_outcore, trace, trace_stats


def run_failing(*args) -> subprocess.CompletedProcess:
    result = subprocess.run([str(binary()), *map(str, args)], capture_output=True, text=True, timeout=120)
    assert result.returncode != 0, f"outcore {args} should have failed"
    return result


def test_calibrate_writes_a_profile_that_trace_reads(store, bounds, tmp_path):
    profile = tmp_path / "profile.txt"
    result = run_outcore("calibrate", store, "--profile", profile, "--structures", "bvh,grid",
                         "--bricks", 3, "--rays", 256, "-q")
    assert result.returncode == 0, result.stderr
    assert f"profile written to {profile}" in result.stdout
    text = profile.read_text()
    assert text.startswith("# outcore cost profile, version 1\n")
    assert "\nbuild bvh " in text and "\ntrace grid " in text
    assert text.count("\nsample ") == 3
    rays = make_rays(bounds, 4000, seed=31)
    reference = trace(store, rays, tmp_path, False, "--brick-accel", "bvh")
    got = trace(store, rays, tmp_path, False, "--brick-accel", "auto", "--profile", profile)
    assert got.tobytes() == reference.tobytes()
    stats = trace_stats(store, rays, tmp_path, "--brick-accel", "auto", "--profile", profile)
    builds = stats["brick_builds_by_structure"]
    assert sum(builds.values()) == stats["brick_builds"] > 0
    assert set(k for k, v in builds.items() if v) <= {"bvh", "grid"}


def test_profile_errors_name_the_file_and_line(store, bounds, tmp_path):
    rays = make_rays(bounds, 10, seed=1)
    np.save(tmp_path / "rays.npy", rays)
    bad = tmp_path / "bad.txt"
    bad.write_text("# outcore cost profile, version 1\nfeatures constant log2_triangles density_spread "
                   "flatness log2_area_ratio\nbuild bvh -16 0 0 0\n")
    result = run_failing("trace", store, "--rays", tmp_path / "rays.npy", "-o", tmp_path / "h.npy",
                         "--brick-accel", "auto", "--profile", bad)
    assert f"{bad}:3: 'build' needs a structure and 5 numbers" in result.stderr
    result = run_failing("trace", store, "--rays", tmp_path / "rays.npy", "-o", tmp_path / "h.npy",
                         "--brick-accel", "grid", "--profile", bad)
    assert "--profile is the cost profile of --brick-accel auto (got 'grid')" in result.stderr
    result = run_failing("calibrate", store, "--structures", "bvh,octagon", "--profile", tmp_path / "p.txt", "-q")
    assert "unknown brick accel 'octagon'" in result.stderr
    assert not (tmp_path / "p.txt").exists()


def test_an_auto_server_answers_as_bvh_and_counts_builds_per_structure(store, bounds):
    rays = make_rays(bounds, 20000, seed=37)
    answers = {}
    for accel in ("bvh", "auto"):
        server = Server(store, "--brick-accel", accel, "--cache-mb", 2)
        try:
            with outcore.SceneClient(server.address, timeout=60) as client:
                answers[accel] = [client.cast_rays(rays[:500]), client.cast_rays(rays)]
                stats = client.stats()
        finally:
            assert server.stop() == 0
        builds = stats["brick_builds_by_structure"]
        assert isinstance(builds, dict)
        assert sum(builds.values()) == stats["brick_builds"] > 0, builds
        if accel == "bvh":
            assert set(builds) == {"bvh"}
            assert stats["brick_rebuilds"] == 0
    for first, second in zip(answers["bvh"], answers["auto"]):
        for key in ("t_hit", "geometry_ids", "primitive_ids", "primitive_uvs", "primitive_normals"):
            assert first[key].tobytes() == second[key].tobytes(), key
