"""Fixtures for the Python client's end-to-end tests: a small store packed
with the real `outcore pack` and real `outcore serve` processes on loopback
ports (stopped with SIGTERM, which must exit 0). See support.py for the
binary and model paths.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import outcore
from support import SPHERE, Server, binary, models_dir, run_outcore


@pytest.fixture(scope="session")
def store(tmp_path_factory) -> Path:
    exe = binary()
    if not exe.is_file():
        pytest.fail(f"outcore binary not found at {exe}: build it first or set OUTCORE_BINARY")
    bunny = models_dir() / "stanford-bunny.obj"
    if not bunny.is_file():
        pytest.fail(f"model not found: {bunny} (set OUTCORE_MODELS_DIR)")
    path = tmp_path_factory.mktemp("store") / "scene.oc"
    # Small bricks so even this scene spans several of them.
    run_outcore("pack", SPHERE, bunny, "-o", path, "--brick-tris", 4096, "-q")
    return path


def _serve(store, *args):
    server = Server(store, *args)
    yield server
    code = server.stop()
    assert code == 0, f"outcore serve exited {code} on SIGTERM:\n" + "".join(server.lines)


@pytest.fixture(scope="session")
def server(store):
    """The default server (64 MiB messages)."""
    yield from _serve(store)


@pytest.fixture(scope="session")
def small_server(store):
    """A server with --max-message-mb 1, so batches of > ~32k rays must stream."""
    yield from _serve(store, "--max-message-mb", 1)


@pytest.fixture(scope="session")
def bounds(server):
    with outcore.SceneClient(server.address, timeout=30) as client:
        info = client.scene_info()
    return np.array(info["bounds_lo"]), np.array(info["bounds_hi"])
