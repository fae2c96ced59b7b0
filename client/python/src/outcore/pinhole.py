"""Camera rays: create_rays_pinhole, Open3D's
RaycastingScene.create_rays_pinhole without Open3D.

Both of Open3D's forms, with the same results bit for bit (checked against
Open3D 0.20: tests/python/test_pinhole.py against stored answers,
tests/python/bench_pinhole_open3d.py against Open3D itself):

    create_rays_pinhole(fov_deg, center, eye, up, width_px, height_px)
    create_rays_pinhole(intrinsic_matrix, extrinsic_matrix, width_px, height_px)

What Open3D does, and so this does: rays are a float32 (height_px, width_px,
6) array [ox oy oz dx dy dz], row y, column x for pixel (x, y) with y the
image row from the top. Every origin is the camera centre C = -R^T t of the
extrinsic matrix [R | t] (world to camera). The direction of pixel (x, y) is
(R^T K^-1) (x + 0.5, y + 0.5, 1): through the pixel's centre, NOT normalised
(its camera-space z is 1, so t_hit is the depth along the optical axis, not
the distance). R^T K^-1 is computed in float64 (K^-1 by cofactors, as Eigen
does), rounded once to float32, and each direction is then that float32
matrix times the float32 pixel vector in float32, summed as Open3D 0.20's
build does: m0 (x + 0.5) + (m1 (y + 0.5) + m2).

The fov form builds K and [R | t] first: focal length f = (width_px / 2) /
tan(fov_deg / 2) (fov_deg is the HORIZONTAL field of view), principal point
(width_px / 2, height_px / 2); R's rows are right = normalise(up' x forward),
up' = forward x right, forward = normalise(center - eye) (up' is the image's
+y, which is down the rows), t = -R eye.

Thread-safety: pure functions.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["create_rays_pinhole"]

_FOV_NAMES = ("fov_deg", "center", "eye", "up", "width_px", "height_px")
_MATRIX_NAMES = ("intrinsic_matrix", "extrinsic_matrix", "width_px", "height_px")
_INT32_MAX = 2**31 - 1
# Below this |sin| between up and the viewing direction the camera's right
# axis is not defined (Open3D would return NaN directions).
_PARALLEL_SIN = 1e-9


def create_rays_pinhole(*args, **kwargs) -> np.ndarray:
    """Rays of a pinhole camera, as Open3D's
    RaycastingScene.create_rays_pinhole (either form, positional or keyword):

    create_rays_pinhole(fov_deg, center, eye, up, width_px, height_px):
        fov_deg the horizontal field of view in degrees (0 < fov_deg < 180),
        center the point looked at, eye the camera's position, up a vector
        not parallel to center - eye (each 3 numbers).
    create_rays_pinhole(intrinsic_matrix, extrinsic_matrix, width_px, height_px):
        intrinsic_matrix (3, 3) invertible K, extrinsic_matrix (4, 4)
        world-to-camera [R | t; 0 0 0 1].

    Returns a float32 array of shape (height_px, width_px, 6): origin and
    (unnormalised) direction per pixel; see the module docstring. Bad
    arguments raise ValueError naming the argument.
    """
    values = _bind(args, kwargs)
    width = _pixels(values["width_px"], "width_px")
    height = _pixels(values["height_px"], "height_px")
    if "fov_deg" in values:
        fov = _fov(values["fov_deg"])
        center = _vector(values["center"], "center")
        eye = _vector(values["eye"], "eye")
        up = _vector(values["up"], "up")
        intrinsic, extrinsic = _look_at(fov, center, eye, up, width, height)
    else:
        intrinsic = _matrix(values["intrinsic_matrix"], "intrinsic_matrix", 3)
        extrinsic = _matrix(values["extrinsic_matrix"], "extrinsic_matrix", 4)
    return _rays(intrinsic, extrinsic, width, height)


def _bind(args: tuple, kwargs: dict) -> dict:
    """The arguments by name, in whichever of the two forms they were given."""
    fov_form = (
        len(args) + len(kwargs) == 6
        or any(name in kwargs for name in ("fov_deg", "center", "eye", "up"))
        or (len(args) > 0 and np.ndim(args[0]) == 0 and "intrinsic_matrix" not in kwargs)
    )
    names = _FOV_NAMES if fov_form else _MATRIX_NAMES
    form = "create_rays_pinhole(" + ", ".join(names) + ")"
    if len(args) > len(names):
        raise TypeError(f"{form} takes {len(names)} arguments, got {len(args)} positional ones")
    values = dict(zip(names, args))
    for name, value in kwargs.items():
        if name not in names:
            raise TypeError(f"{form} got an unexpected keyword argument {name!r}")
        if name in values:
            raise TypeError(f"{form} got multiple values for argument {name!r}")
        values[name] = value
    missing = [name for name in names if name not in values]
    if missing:
        raise TypeError(f"{form} is missing argument(s): {', '.join(missing)}")
    return values


def _pixels(value, name: str) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if not 0 < int(value) <= _INT32_MAX:
        raise ValueError(f"{name} must be in 1..{_INT32_MAX}, got {int(value)}")
    return int(value)


def _real_array(value, name: str, shape: tuple[int, ...]) -> np.ndarray:
    try:
        a = np.asarray(value)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} must be an array of numbers of shape {shape}: {e}") from None
    if a.dtype.kind not in "fiu":
        raise ValueError(f"{name} must hold real numbers, got dtype {a.dtype}")
    if a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {a.shape}")
    a = a.astype(np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got {a.tolist()}")
    return a


def _vector(value, name: str) -> np.ndarray:
    return _real_array(value, name, (3,))


def _matrix(value, name: str, n: int) -> np.ndarray:
    return _real_array(value, name, (n, n))


def _fov(value) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ValueError(f"fov_deg must be a real number of degrees, got {value!r}")
    fov = float(value)
    if not 0.0 < fov < 180.0:
        raise ValueError(f"fov_deg must be in (0, 180) degrees, got {fov}")
    return fov


# --- float64 steps in Eigen's order (Open3D's implementation) ---------------


def _dot3(a, b) -> float:
    return (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]


def _norm(v) -> float:
    return math.sqrt(_dot3(v, v))


def _cross(a, b) -> list[float]:
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _matmul(a, b) -> list[list[float]]:
    n, m, p = len(a), len(b), len(b[0])
    out = [[0.0] * p for _ in range(n)]
    for i in range(n):
        for j in range(p):
            s = a[i][0] * b[0][j]
            for k in range(1, m):
                s = s + a[i][k] * b[k][j]
            out[i][j] = s
    return out


def _inverse3(m) -> list[list[float]] | None:
    """Eigen's 3x3 inverse: cofactors, the determinant along column 0, then
    each cofactor times 1/det. None when singular."""

    def cofactor(i: int, j: int) -> float:
        i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
        return m[i1][j1] * m[i2][j2] - m[i1][j2] * m[i2][j1]

    column0 = [cofactor(0, 0), cofactor(1, 0), cofactor(2, 0)]
    det = (column0[0] * m[0][0] + column0[1] * m[1][0]) + column0[2] * m[2][0]
    if det == 0.0 or not math.isfinite(det):
        return None
    inv_det = 1.0 / det
    return [[cofactor(j, i) * inv_det for j in range(3)] for i in range(3)]


def _look_at(fov: float, center, eye, up, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    forward = [float(c) - float(e) for c, e in zip(center, eye)]
    forward_norm = _norm(forward)
    if forward_norm == 0.0:
        raise ValueError(f"eye must differ from center, both are {list(map(float, eye))}")
    up_norm = _norm(up)
    if up_norm == 0.0:
        raise ValueError("up must not be the zero vector")
    row1 = [float(u) / up_norm for u in up]
    row2 = [f / forward_norm for f in forward]
    row0 = _cross(row1, row2)
    sin = _norm(row0)
    if not sin > _PARALLEL_SIN:
        raise ValueError(f"up {list(map(float, up))} is parallel to the viewing direction center - eye {forward}")
    row0 = [r / sin for r in row0]
    row1 = _cross(row2, row0)
    rotation = [row0, row1, row2]
    t = [-v for v in (_dot3(row, [float(e) for e in eye]) for row in rotation)]
    focal = 0.5 * width / math.tan(0.5 * (math.pi / 180) * fov)
    intrinsic = np.array([[focal, 0.0, 0.5 * width], [0.0, focal, 0.5 * height], [0.0, 0.0, 1.0]])
    extrinsic = np.eye(4)
    extrinsic[:3, :3] = rotation
    extrinsic[:3, 3] = t
    return intrinsic, extrinsic


def _rays(intrinsic: np.ndarray, extrinsic: np.ndarray, width: int, height: int) -> np.ndarray:
    inv_k = _inverse3(intrinsic.tolist())
    if inv_k is None or not all(math.isfinite(v) for row in inv_k for v in row):
        raise ValueError(f"intrinsic_matrix must be invertible, got {intrinsic.tolist()}")
    e = extrinsic.tolist()
    rotation_t = [[e[j][i] for j in range(3)] for i in range(3)]  # R^T
    t = [e[0][3], e[1][3], e[2][3]]
    # C = (-R^T) t, summed as Eigen does.
    origin = [(-rotation_t[i][0] * t[0] + -rotation_t[i][1] * t[1]) + -rotation_t[i][2] * t[2] for i in range(3)]
    m = np.array(_matmul(rotation_t, inv_k), dtype=np.float64).astype(np.float32)
    if not np.all(np.isfinite(m)) or not all(math.isfinite(c) for c in origin):
        raise ValueError("extrinsic_matrix and intrinsic_matrix give non-finite rays")

    # Pixel centres: x + 0.5 in float32, exact for any int32 below 2^24.
    xs = np.arange(width, dtype=np.float32) + np.float32(0.5)
    ys = np.arange(height, dtype=np.float32) + np.float32(0.5)
    rays = np.empty((height, width, 6), dtype=np.float32)
    rays[..., 0:3] = np.array(origin, dtype=np.float64).astype(np.float32)
    with np.errstate(over="ignore"):
        for i in range(3):
            # float32 throughout, one rounding per operation, in Open3D
            # 0.20's order: m0 x + (m1 y + m2) (measured: bitwise equal).
            rays[..., 3 + i] = m[i, 0] * xs[None, :] + (m[i, 1] * ys[:, None] + m[i, 2])
    return rays
