"""Helpers for the Python client's end-to-end tests: the real `outcore`
binary (pack, serve, trace as the reference) and test rays.

The binary is $OUTCORE_BINARY (default build/client/outcore; relative paths
are taken from the repository root); models come from the repository's own
tests/data/models ($OUTCORE_MODELS_DIR overrides).
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import threading
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
# The test scene's first input: beside the bunny (about 0.16 across, near the
# origin), not around it, so rays hit both.
SPHERE = "gen:sphere?level=3&radius=0.08&cx=0.2&cy=0.1"
_LISTENING = re.compile(r"listening on (\S+):(\d+)")


def binary() -> Path:
    path = Path(os.environ.get("OUTCORE_BINARY", "build/client/outcore"))
    return path if path.is_absolute() else REPO / path


def models_dir() -> Path:
    return Path(os.environ.get("OUTCORE_MODELS_DIR", REPO / "tests" / "data" / "models"))


def run_outcore(*args, timeout=120) -> subprocess.CompletedProcess:
    result = subprocess.run([str(binary()), *map(str, args)], capture_output=True, text=True, timeout=timeout)
    if result.returncode != 0:
        raise AssertionError(f"outcore {' '.join(map(str, args))} exited {result.returncode}:\n"
                             f"{result.stdout}\n{result.stderr}")
    return result


class Server:
    """One `outcore serve` process on 127.0.0.1 (unless extra_args has its
    own --listen), port chosen by the OS."""

    def __init__(self, store: Path, *extra_args):
        self.lines: list[str] = []
        self._ready = threading.Event()
        self.address: str | None = None
        listen = [] if "--listen" in map(str, extra_args) else ["--listen", "127.0.0.1:0"]
        self.process = subprocess.Popen(
            [str(binary()), "serve", str(store), *listen, *map(str, extra_args)],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )
        # Keep draining the output (logs) so the server never blocks on a full pipe.
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        if not self._ready.wait(60) or self.address is None:
            self.process.kill()
            self.process.wait()
            raise AssertionError("outcore serve did not report its port:\n" + "".join(self.lines))

    def _read(self):
        for line in self.process.stdout:
            self.lines.append(line)
            match = _LISTENING.search(line)
            if match and self.address is None:
                self.address = f"{match.group(1)}:{match.group(2)}"
                self._ready.set()
        self._ready.set()  # exited before listening

    def stop(self) -> int:
        """SIGTERM, then the exit code (the server drains and exits 0)."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        try:
            code = self.process.wait(60)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            raise AssertionError("outcore serve did not exit within 60 s of SIGTERM:\n" + "".join(self.lines))
        self._reader.join(10)
        return code


def make_rays(bounds, n: int, seed: int, columns: int = 6) -> np.ndarray:
    """(n, columns) float32 rays from a sphere around the scene towards points
    in a box 30% larger than its bounds (so a mix of hits and misses), with
    directions of varied length (t is in units of it)."""
    lo, hi = bounds
    rng = np.random.default_rng(seed)
    center, extent = (lo + hi) / 2, (hi - lo)
    radius = np.linalg.norm(extent)
    unit = rng.standard_normal((n, 3))
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    origins = center + radius * unit
    targets = center + (rng.random((n, 3)) - 0.5) * extent * 1.3
    directions = (targets - origins) * rng.uniform(0.2, 3.0, (n, 1))
    rays = np.concatenate([origins, directions], axis=1)
    if columns == 8:
        tnear = rng.uniform(0.0, 0.5, n)
        tfar = np.where(rng.random(n) < 0.5, np.inf, rng.uniform(0.5, 2.0, n))
        rays = np.concatenate([rays, tnear[:, None], tfar[:, None]], axis=1)
    return np.ascontiguousarray(rays, dtype=np.float32)


def trace(store: Path, rays: np.ndarray, tmp_path: Path, any_hit: bool = False, *extra) -> np.ndarray:
    """The reference: `outcore trace` in-process on the same store (extra:
    more of its options)."""
    rays_path, out_path = tmp_path / "rays.npy", tmp_path / "hits.npy"
    np.save(rays_path, rays)
    run_outcore("trace", store, "--rays", rays_path, "-o", out_path, *(["--any-hit"] if any_hit else []),
                *extra)
    return np.load(out_path)


def trace_stats(store: Path, rays: np.ndarray, tmp_path: Path, *extra) -> dict:
    """The engine's figures (`outcore trace --stats-json`) for closest hits of
    `rays` on the store, with a fresh cache."""
    stats_path = tmp_path / "trace-stats.json"
    trace(store, rays, tmp_path, False, "--stats-json", stats_path, *extra)
    return json.loads(stats_path.read_text())
