#!/usr/bin/env python3
"""Writes benchmark rays for a scene store as float32 (N,6) .npy files.

incoherent: origins uniform on a sphere around the scene's box (radius 1.5x the
            box's half diagonal), aimed at uniform random points of the box.
camera:     a pinhole camera on that sphere looking at the box centre, one ray
            per pixel of a square image, row-major.

Usage: make_rays.py SCENE_INFO_JSON KIND N OUT.npy [--seed S]
(SCENE_INFO_JSON is `outcore info SCENE --json` output, for the bounds.)
"""
import argparse
import json

import numpy as np


def scene_box(info_path):
    with open(info_path) as f:
        info = json.load(f)
    return np.array(info["bounds"]["min"], np.float64), np.array(info["bounds"]["max"], np.float64)


def incoherent(lo, hi, n, rng):
    center, radius = (lo + hi) / 2, 1.5 * np.linalg.norm(hi - lo) / 2
    d = rng.normal(size=(n, 3))
    origins = center + radius * d / np.linalg.norm(d, axis=1, keepdims=True)
    targets = lo + rng.random((n, 3)) * (hi - lo)
    return np.hstack([origins, targets - origins]).astype(np.float32)


def camera(lo, hi, n, rng):
    side = int(round(np.sqrt(n)))
    center, radius = (lo + hi) / 2, 1.5 * np.linalg.norm(hi - lo) / 2
    eye = center + radius * np.array([0.6, 0.5, 0.62]) / np.linalg.norm([0.6, 0.5, 0.62])
    forward = (center - eye) / np.linalg.norm(center - eye)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    half = np.tan(np.radians(25.0))
    s = (np.arange(side) + 0.5) / side * 2 - 1
    x, y = np.meshgrid(s * half, -s * half)
    dirs = forward + x[..., None] * right + y[..., None] * up
    dirs = dirs.reshape(-1, 3)
    origins = np.broadcast_to(eye, dirs.shape)
    return np.hstack([origins, dirs]).astype(np.float32)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("info")
    ap.add_argument("kind", choices=["incoherent", "camera"])
    ap.add_argument("n", type=int)
    ap.add_argument("out")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    lo, hi = scene_box(a.info)
    rng = np.random.default_rng(a.seed)
    rays = (incoherent if a.kind == "incoherent" else camera)(lo, hi, a.n, rng)
    np.save(a.out, rays)


if __name__ == "__main__":
    main()
