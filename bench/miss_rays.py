"""Rays of known fate on the sparse scene (bench/sparse_scene.py), for the
cost of a ray by what it meets; float32 (N,6) like bench/make_rays.py:

outside:  origins uniform on the sphere of make_rays.py (radius 1.5x the
          box's half diagonal), aimed at uniform points of the box scaled 3x
          about its centre; only rays whose line misses the scene's box grown
          by 2 % of its size on each side are kept (float64): none enters it.
between:  rays along a random axis from outside the box through the gaps
          between the copies (both other coordinates in the middle 60 % of a
          gap, directions tilted by at most 0.05 off the axis, which keeps
          them in their gap): each enters the scene's box but no copy's box,
          so no brick's.
hit:      origins as `outside`, aimed at the centroid of a random triangle:
          all but a handful hit something.
"""
import numpy as np


def _sphere_points(center, radius, n, rng):
    d = rng.normal(size=(n, 3))
    return center + radius * d / np.linalg.norm(d, axis=1, keepdims=True)


def _line_touches_box(origins, directions, lo, hi):
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = 1.0 / directions
        t0, t1 = (lo - origins) * inverse, (hi - origins) * inverse
    near = np.nanmax(np.minimum(t0, t1), axis=1)
    far = np.nanmin(np.maximum(t0, t1), axis=1)
    return (near <= far) & (far >= 0)


def outside_rays(lo, hi, n, rng):
    center, radius = (lo + hi) / 2, 1.5 * np.linalg.norm(hi - lo) / 2
    margin = 0.02 * (hi - lo)
    kept, count = [], 0
    while count < n:
        origins = _sphere_points(center, radius, n, rng)
        targets = center + (rng.random((n, 3)) * 2 - 1) * 1.5 * (hi - lo)
        miss = ~_line_touches_box(origins, targets - origins, lo - margin, hi + margin)
        kept.append(np.hstack([origins[miss], (targets - origins)[miss]]))
        count += int(miss.sum())
    return np.concatenate(kept)[:n].astype(np.float32)


def between_rays(lo, hi, copy_lo, copy_hi, step, grid, n, rng):
    axis = rng.integers(0, 3, n)
    origins, directions = np.empty((n, 3)), np.zeros((n, 3))
    for a in range(3):
        rows = axis == a
        m = int(rows.sum())
        for b in range(3):
            if b == a:
                origins[rows, b] = lo[b] - 0.1 * (hi[b] - lo[b])
                directions[rows, b] = 1.0
                continue
            gap_lo = copy_hi[b] + rng.integers(0, grid - 1, m) * step
            gap = step - (copy_hi[b] - copy_lo[b])
            origins[rows, b] = gap_lo + gap * (0.2 + 0.6 * rng.random(m))
            directions[rows, b] = (rng.random(m) * 2 - 1) * 0.05
    return np.hstack([origins, directions]).astype(np.float32)


def hit_rays(lo, hi, triangles, n, rng):
    center, radius = (lo + hi) / 2, 1.5 * np.linalg.norm(hi - lo) / 2
    origins = _sphere_points(center, radius, n, rng)
    targets = triangles[rng.integers(0, len(triangles), n)].reshape(n, 3, 3).astype(np.float64).mean(axis=1)
    return np.hstack([origins, targets - origins]).astype(np.float32)
