"""outcore.create_rays_pinhole: bit for bit Open3D 0.20's rays (stored
answers, tests/data/pinhole/README.md; bench/pinhole_open3d.py checks Open3D
itself), its layout and pixel centres, and ValueError naming the argument
for every bad one. No server needed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import outcore

EXPECTED = Path(__file__).resolve().parents[1] / "data" / "pinhole" / "open3d-0.20.npz"


def stored_cameras():
    data = np.load(EXPECTED)
    k = 0
    while f"rays{k}" in data:
        width, height = (int(v) for v in data[f"size{k}"])
        if f"fov{k}" in data:
            p = data[f"fov{k}"]
            args = (float(p[0]), p[1:4], p[4:7], p[7:10], width, height)
            kwargs = dict(fov_deg=args[0], center=args[1], eye=args[2], up=args[3], width_px=width, height_px=height)
        else:
            args = (data[f"intrinsic{k}"], data[f"extrinsic{k}"], width, height)
            kwargs = dict(intrinsic_matrix=args[0], extrinsic_matrix=args[1], width_px=width, height_px=height)
        yield k, args, kwargs, data[f"rays{k}"]
        k += 1


def bitwise_equal(a, b) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a.view(np.uint32), b.view(np.uint32))


def test_rays_are_bitwise_open3ds_for_the_stored_cameras_in_both_forms():
    cameras = list(stored_cameras())
    assert len(cameras) == 6
    assert {"fov_deg" in kw for _, _, kw, _ in cameras} == {True, False}
    for k, args, kwargs, expected in cameras:
        assert bitwise_equal(outcore.create_rays_pinhole(*args), expected), f"camera {k}, positional"
        assert bitwise_equal(outcore.create_rays_pinhole(**kwargs), expected), f"camera {k}, keywords"
        # Lists work as well as arrays.
        listed = [a.tolist() if isinstance(a, np.ndarray) else a for a in args]
        assert bitwise_equal(outcore.create_rays_pinhole(*listed), expected), f"camera {k}, lists"


def test_pixel_x_y_is_row_y_column_x_through_the_pixel_centre_and_not_normalised():
    f, cx, cy = 10.0, 2.0, 1.5
    intrinsic = [[f, 0, cx], [0, f, cy], [0, 0, 1]]
    extrinsic = np.eye(4)
    extrinsic[:3, 3] = [1.0, -2.0, 3.0]  # world -> camera translation t: the camera is at -t
    rays = outcore.create_rays_pinhole(intrinsic, extrinsic, 5, 3)
    assert rays.shape == (3, 5, 6) and rays.dtype == np.float32
    assert np.all(rays[..., :3] == np.float32([-1.0, 2.0, -3.0]))
    for y in range(3):
        for x in range(5):
            expected = [(x + 0.5 - cx) / f, (y + 0.5 - cy) / f, 1.0]
            np.testing.assert_allclose(rays[y, x, 3:], expected, rtol=1e-6, atol=1e-7)
    # z stays 1: depth along the axis, not unit length (Open3D's convention).
    assert np.all(rays[..., 5] == 1.0)
    assert not np.allclose(np.linalg.norm(rays[..., 3:], axis=-1), 1.0)


def test_the_fov_form_looks_from_eye_at_center_with_open3ds_orientation():
    # Open3D 0.20 (tests/data/pinhole, camera 3): seen from +z towards the
    # origin with up +y, row 0 looks down (-y) and column 0 towards +x; the
    # centre of the image is the viewing direction.
    rays = outcore.create_rays_pinhole(90, [0, 0, 0], [0, 0, 5], [0, 1, 0], 4, 2)
    assert np.all(rays[..., :3] == np.float32([0, 0, 5]))
    assert rays[0, 0, 3] > 0 and rays[0, 0, 4] < 0
    assert rays[1, 3, 3] < 0 and rays[1, 3, 4] > 0
    assert np.all(rays[..., 5] == -1.0)
    np.testing.assert_allclose(rays[..., 3:].mean(axis=(0, 1)), [0, 0, -1], atol=1e-7)
    # The horizontal field of view: the outer pixel centres at 90 degrees.
    np.testing.assert_allclose(abs(rays[0, 0, 3]), 0.75, rtol=1e-6)


GOOD_FOV = dict(fov_deg=60, center=[0, 0, 0], eye=[0, 0, 5], up=[0, 1, 0], width_px=4, height_px=3)
GOOD_MATRIX = dict(intrinsic_matrix=np.diag([10.0, 10.0, 1.0]), extrinsic_matrix=np.eye(4), width_px=4, height_px=3)


@pytest.mark.parametrize(
    "form, argument, value",
    [
        ("fov", "width_px", 0),
        ("fov", "width_px", -3),
        ("fov", "height_px", 2.5),
        ("fov", "height_px", 4.0),
        ("fov", "width_px", True),
        ("fov", "width_px", "4"),
        ("matrix", "height_px", 0),
        ("matrix", "width_px", 2**31),
        ("fov", "fov_deg", 0),
        ("fov", "fov_deg", 180),
        ("fov", "fov_deg", float("nan")),
        ("fov", "fov_deg", "60"),
        ("fov", "center", [0, 0]),
        ("fov", "center", [0, 0, np.inf]),
        ("fov", "eye", [[0, 0, 5]]),
        ("fov", "eye", [0, 0, np.nan]),
        ("fov", "eye", [0, 0, 0]),  # == center
        ("fov", "up", [0, 0, 1]),  # parallel to the view
        ("fov", "up", [0, 0, -3]),  # antiparallel
        ("fov", "up", [0, 0, 0]),
        ("fov", "up", ["a", "b", "c"]),
        ("matrix", "intrinsic_matrix", np.eye(4)),
        ("matrix", "intrinsic_matrix", np.zeros((3, 3))),  # singular
        ("matrix", "intrinsic_matrix", [[1, 0, 0], [0, np.nan, 0], [0, 0, 1]]),
        ("matrix", "extrinsic_matrix", np.eye(3)),
        ("matrix", "extrinsic_matrix", np.full((4, 4), np.inf)),
        ("matrix", "extrinsic_matrix", np.eye(4, dtype=bool)),
    ],
)
def test_bad_arguments_raise_value_error_naming_them(form, argument, value):
    kwargs = dict(GOOD_FOV if form == "fov" else GOOD_MATRIX)
    outcore.create_rays_pinhole(**kwargs)  # the good camera works
    kwargs[argument] = value
    with pytest.raises(ValueError, match=argument):
        outcore.create_rays_pinhole(**kwargs)


def test_numpy_integers_are_sizes_and_mixed_or_missing_arguments_are_type_errors():
    assert outcore.create_rays_pinhole(60, [0, 0, 0], [0, 0, 5], [0, 1, 0], np.int64(2), np.uint8(3)).shape == (3, 2, 6)
    with pytest.raises(TypeError, match="height_px"):
        outcore.create_rays_pinhole(60, [0, 0, 0], [0, 0, 5], [0, 1, 0], 4)
    with pytest.raises(TypeError, match="fov_deg"):
        outcore.create_rays_pinhole(np.eye(3), np.eye(4), 4, 3, fov_deg=60)
