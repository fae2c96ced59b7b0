"""outcore.render: a picture of a served scene from a pinhole camera, in
three modes, with the same colour rules as the C++ `outcore render`.

`up` is the world's up: the picture is upright and unmirrored, as a
photograph. Open3D's fov camera runs its rows along `up` (row 0 looks
towards -up, column 0 towards the camera's right), so the rays are
create_rays_pinhole(fov_deg, center, eye, -up, width, height) (Open3D's
camera, outcore/pinhole.py), cast with client.cast_rays, and pixel (row y,
column x) is the ray at [y, x] of those rays; the C++ `outcore render` does
the same.

Colour rules (hits_to_image), all arithmetic in float64, every channel
rounded to nearest with halves away from zero and clamped to 0..255:

- every mode: a pixel whose ray missed is (0, 0, 0);
- "depth": tmin, tmax = min and max of t_hit over the hit pixels;
  v = (t - tmin) / (tmax - tmin), or 0 when tmax == tmin; s = 1 - v (near is
  bright); the colour is s interpolated linearly between 5 stops at s = 0,
  0.25, 0.5, 0.75, 1: (68,1,84), (59,82,139), (33,145,140), (94,201,98),
  (253,231,37) (viridis): with x = 4 s, k = min(floor(x), 3), f = x - k,
  colour = stop[k] + (stop[k+1] - stop[k]) * f;
- "normals": channel c = 255 * (n_c * 0.5 + 0.5), n the hit's unit
  geometric normal (primitive_normals);
- "ids": z = splitmix64(geometry_id) (the standard finaliser, on uint64:
  x += 0x9E3779B97F4A7C15; z = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EB; z ^= z >> 31), then
  r = 64 + (z & 0xff) % 192, g = 64 + ((z >> 8) & 0xff) % 192,
  b = 64 + ((z >> 16) & 0xff) % 192.

Thread-safety: pure functions of their arguments (the client's own rules
for concurrent calls apply).
"""

from __future__ import annotations

import numpy as np

from .client import INVALID_ID
from .pinhole import _pixels, create_rays_pinhole

__all__ = ["render", "hits_to_image", "MODES"]

MODES = ("depth", "normals", "ids")
DEPTH_STOPS = np.array(
    [(68, 1, 84), (59, 82, 139), (33, 145, 140), (94, 201, 98), (253, 231, 37)], dtype=np.float64
)
_U64 = np.uint64


def render(client, *, eye, center, up, fov_deg, width, height, mode: str = "depth") -> np.ndarray:
    """An (height, width, 3) uint8 image of the scene `client` (a
    SceneClient) serves, seen from `eye` looking at `center` with `up`
    upwards and a horizontal field of view of `fov_deg` degrees; `mode` is
    "depth", "normals" or "ids" (colour rules in the module docstring).
    Bad arguments raise ValueError naming them; failed calls OutcoreError.
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    width = _pixels(width, "width")
    height = _pixels(height, "height")
    try:
        down = -np.asarray(up, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"up must be 3 finite numbers, got {up!r}") from None
    rays = create_rays_pinhole(fov_deg, center, eye, down, width, height)
    return hits_to_image(client.cast_rays(rays), mode)


def hits_to_image(result: dict, mode: str = "depth") -> np.ndarray:
    """The image of a cast_rays result of (H, W) rays, by the colour rules of
    `mode` (module docstring): (H, W, 3) uint8."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    hit = np.asarray(result["primitive_ids"]) != INVALID_ID
    image = np.zeros(hit.shape + (3,), dtype=np.uint8)
    if not hit.any():
        return image
    if mode == "depth":
        colour = _depth_colours(np.asarray(result["t_hit"], dtype=np.float64)[hit])
    elif mode == "normals":
        normals = np.asarray(result["primitive_normals"], dtype=np.float64)[hit]
        colour = 255.0 * (normals * 0.5 + 0.5)
    else:
        colour = _id_colours(np.asarray(result["geometry_ids"])[hit])
    image[hit] = np.clip(_round_half_away(colour), 0, 255).astype(np.uint8)
    return image


def _depth_colours(t: np.ndarray) -> np.ndarray:
    tmin, tmax = t.min(), t.max()
    v = (t - tmin) / (tmax - tmin) if tmax > tmin else np.zeros_like(t)
    s = 1.0 - v
    x = 4.0 * s
    k = np.minimum(np.floor(x), 3.0).astype(np.intp)
    f = (x - k)[:, None]
    return DEPTH_STOPS[k] + (DEPTH_STOPS[k + 1] - DEPTH_STOPS[k]) * f


def splitmix64(values) -> np.ndarray:
    """The splitmix64 finaliser of each value (as uint64), wrapping as C's
    uint64_t arithmetic does."""
    x = np.asarray(values).astype(_U64) + _U64(0x9E3779B97F4A7C15)
    z = (x ^ (x >> _U64(30))) * _U64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> _U64(27))) * _U64(0x94D049BB133111EB)
    return z ^ (z >> _U64(31))


def _id_colours(geometry_ids: np.ndarray) -> np.ndarray:
    z = splitmix64(geometry_ids)
    channels = [64 + ((z >> _U64(shift)) & _U64(0xFF)) % _U64(192) for shift in (0, 8, 16)]
    return np.stack(channels, axis=-1).astype(np.float64)


def _round_half_away(c: np.ndarray) -> np.ndarray:
    """Round to nearest, halves away from zero (C's round()); exact, unlike
    floor(c + 0.5), which rounds 0.49999999999999994 up."""
    magnitude = np.abs(c)
    whole = np.floor(magnitude)
    return np.copysign(whole + (magnitude - whole >= 0.5), c)
