"""outcore.create_rays_pinhole against Open3D's RaycastingScene.create_rays_pinhole,
bit for bit, on random cameras of both forms; with --write, also (re)makes
the stored expected rays that the regular test suite checks without Open3D
(tests/data/pinhole/open3d-0.20.npz, tests/python/test_pinhole.py).

Run with the bench venv (Open3D 0.20, scripts/install.sh --bench):

    .venv-bench/bin/python bench/pinhole_open3d.py [--cameras 300] [--write tests/data/pinhole/open3d-0.20.npz]

Exits 1 when any camera differs. The module is loaded from this checkout's
client/python/src (not an installed outcore), so the check is of this code.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def load_pinhole():
    path = os.path.join(ROOT, "client", "python", "src", "outcore", "pinhole.py")
    spec = importlib.util.spec_from_file_location("outcore_pinhole", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def random_fov_camera(rng):
    eye = rng.normal(size=3) * 10 ** rng.uniform(-2, 3)
    return dict(fov_deg=float(rng.uniform(5, 170)), center=eye + rng.normal(size=3) * 10 ** rng.uniform(-2, 2),
                eye=eye, up=rng.normal(size=3), width_px=int(rng.integers(1, 48)), height_px=int(rng.integers(1, 48)))


def random_matrix_camera(rng):
    w, h = int(rng.integers(1, 48)), int(rng.integers(1, 48))
    k = np.array([[rng.uniform(10, 500), rng.uniform(-5, 5), rng.uniform(0, w)],
                  [0, rng.uniform(10, 500), rng.uniform(0, h)], [0, 0, 1]])
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    e = np.eye(4)
    e[:3, :3] = q
    e[:3, 3] = rng.normal(size=3) * 10
    return dict(intrinsic_matrix=k, extrinsic_matrix=e, width_px=w, height_px=h)


def open3d_rays(camera: dict) -> np.ndarray:
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene
    if "fov_deg" in camera:
        return scene.create_rays_pinhole(fov_deg=camera["fov_deg"], center=list(camera["center"]),
                                         eye=list(camera["eye"]), up=list(camera["up"]),
                                         width_px=camera["width_px"], height_px=camera["height_px"]).numpy()
    return scene.create_rays_pinhole(o3d.core.Tensor(camera["intrinsic_matrix"]),
                                     o3d.core.Tensor(camera["extrinsic_matrix"]),
                                     camera["width_px"], camera["height_px"]).numpy()


def bitwise_equal(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a.view(np.uint32), b.view(np.uint32))


# The stored cameras: small, and between them every feature (Open3D's own
# tutorial camera, odd sizes, 1x1, a wide and a narrow field of view, skewed
# K with an off-centre principal point, a rotated extrinsic).
STORED_CAMERAS = [
    dict(fov_deg=60.0, center=[0.5, 0.5, 0.5], eye=[-1.0, -1.0, -1.0], up=[0.0, 0.0, 1.0], width_px=6, height_px=4),
    dict(fov_deg=120.0, center=[0.25, -3.5, 2.0], eye=[7.0, 1.5, -0.75], up=[0.3, 0.9, -0.2], width_px=7,
         height_px=3),
    dict(fov_deg=10.0, center=[0.0, 0.0, 0.0], eye=[0.0, 0.0, 5.0], up=[0.0, 1.0, 0.0], width_px=1, height_px=1),
    dict(fov_deg=90.0, center=[0.0, 0.0, 0.0], eye=[0.0, 0.0, 5.0], up=[0.0, 1.0, 0.0], width_px=4, height_px=2),
    dict(intrinsic_matrix=[[120.0, 1.5, 2.75], [0.0, 95.0, 3.25], [0.0, 0.0, 1.0]],
         extrinsic_matrix=[[0.0, -1.0, 0.0, 0.5], [0.6, 0.0, -0.8, 1.0], [0.8, 0.0, 0.6, -2.0],
                           [0.0, 0.0, 0.0, 1.0]], width_px=6, height_px=5),
    dict(intrinsic_matrix=[[500.0, 0.0, 160.0], [0.0, 500.0, 120.0], [0.0, 0.0, 1.0]],
         extrinsic_matrix=np.eye(4).tolist(), width_px=3, height_px=8),
]


def write_expected(path: str) -> None:
    arrays = {}
    for k, camera in enumerate(STORED_CAMERAS):
        if "fov_deg" in camera:
            arrays[f"fov{k}"] = np.array([camera["fov_deg"], *camera["center"], *camera["eye"], *camera["up"]])
        else:
            arrays[f"intrinsic{k}"] = np.array(camera["intrinsic_matrix"], dtype=np.float64)
            arrays[f"extrinsic{k}"] = np.array(camera["extrinsic_matrix"], dtype=np.float64)
        arrays[f"size{k}"] = np.array([camera["width_px"], camera["height_px"]], dtype=np.int64)
        arrays[f"rays{k}"] = open3d_rays(camera)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    np.savez(path, **arrays)
    print(f"wrote {len(STORED_CAMERAS)} cameras' rays to {path}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cameras", type=int, default=300, help="random cameras of each form")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--write", metavar="NPZ", help="also write the stored cameras' Open3D rays here")
    args = parser.parse_args()
    import open3d as o3d

    pinhole = load_pinhole()
    rng = np.random.default_rng(args.seed)
    failures = 0
    cameras = STORED_CAMERAS + [f(rng) for _ in range(args.cameras) for f in (random_fov_camera, random_matrix_camera)]
    for k, camera in enumerate(cameras):
        expected = open3d_rays(camera)
        got = pinhole.create_rays_pinhole(**camera)
        if not bitwise_equal(got, expected):
            failures += 1
            differ = np.argwhere(got.view(np.uint32) != expected.view(np.uint32)) if got.shape == expected.shape else []
            print(f"camera {k} differs ({len(differ)} values): {camera}", file=sys.stderr)
    print(f"Open3D {o3d.__version__}: {len(cameras) - failures} of {len(cameras)} cameras bitwise equal")
    if args.write:
        write_expected(args.write)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
