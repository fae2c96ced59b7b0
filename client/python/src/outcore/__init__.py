"""Outcore's Python client: ray queries against `outcore serve` over gRPC,
with Open3D RaycastingScene-style results.

    import numpy as np, outcore
    with outcore.SceneClient("127.0.0.1:50051") as scene:
        ans = scene.cast_rays(rays)          # rays: (..., 6) or (..., 8) float32
        ans["t_hit"], ans["primitive_ids"]   # Open3D's keys; misses: inf, INVALID_ID
        hit = scene.test_occlusions(rays)    # (...,) bool
        o = outcore.spawn_origins(rays, ans) # (..., 3) origins for secondary rays

    rays = outcore.create_rays_pinhole(60, center, eye, up, 640, 480)  # Open3D's camera rays
    outcore.pack(vertices, triangles, "scene.oc")                       # a store from arrays
    image = outcore.render(scene, eye=eye, center=center, up=up, fov_deg=60, width=640, height=480)
    outcore.write_png("depth.png", image)

See docs/PYTHON.md in the repository.
"""

from .client import INVALID_ID, SceneClient
from .errors import OutcoreError
from .pack import PackError, pack
from .pinhole import create_rays_pinhole
from .png import write_png
from .render import render
from .spawn import spawn_origins

__all__ = [
    "SceneClient",
    "OutcoreError",
    "INVALID_ID",
    "spawn_origins",
    "create_rays_pinhole",
    "pack",
    "PackError",
    "render",
    "write_png",
]
__version__ = "0.1.0"
