"""outcore.render and write_png: a small scene packed from arrays and served
by the real `outcore serve`, rendered in each mode: misses are black, the
nearest surface is the brightest depth stop and the farthest the darkest,
an axis-aligned face has the colour of its normal, each geometry the
colour of its id; the colour rules on synthetic hits (rounding halves away
from zero, the stops, splitmix64); write_png's file decodes back to the
image."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

import outcore
from outcore.render import hits_to_image, splitmix64
from support import Server, binary

STOPS = [(68, 1, 84), (59, 82, 139), (33, 145, 140), (94, 201, 98), (253, 231, 37)]
CAMERA = dict(eye=[0, 0, 10], center=[0, 0, 0], up=[0, 1, 0], fov_deg=60, width=40, height=30)


def quad(x0, x1, y0, y1, z):
    """Two triangles wound counter-clockwise seen from +z (normal +z)."""
    return [[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], [[0, 1, 2], [0, 2, 3]]


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    meshes = [
        quad(-1, 1, -1, 1, 2),  # geometry 0: near, facing the camera
        quad(-3, 3, -3, 3, 0),  # geometry 1: far, behind it
        quad(1.5, 2.5, 1.5, 2.5, 1),  # geometry 2: a marker at +x +y, between them
    ]
    path = outcore.pack(meshes, tmp_path_factory.mktemp("render") / "scene.oc", binary=binary())
    server = Server(path)
    with outcore.SceneClient(server.address, timeout=60) as c:
        yield c
    assert server.stop() == 0, "".join(server.lines)


def id_colour(geometry_id: int) -> tuple[int, int, int]:
    """splitmix64 with Python integers, independently of outcore.render."""
    mask = (1 << 64) - 1
    x = (geometry_id + 0x9E3779B97F4A7C15) & mask
    z = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & mask
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
    z ^= z >> 31
    return tuple(64 + ((z >> shift) & 0xFF) % 192 for shift in (0, 8, 16))


def geometry_of(client) -> np.ndarray:
    # The picture's rays: Open3D's camera asked with the world's down (render's rule).
    rays = outcore.create_rays_pinhole(CAMERA["fov_deg"], CAMERA["center"], CAMERA["eye"], -np.array(CAMERA["up"]),
                                       CAMERA["width"], CAMERA["height"])
    return np.asarray(client.cast_rays(rays)["geometry_ids"]).astype(np.int64)


def test_every_mode_is_an_rgb_image_of_the_cameras_rays_with_misses_black(client):
    geometry = geometry_of(client)
    miss = geometry == outcore.INVALID_ID
    assert miss.any() and (geometry == 0).any() and (geometry == 1).any() and (geometry == 2).any()
    for mode in ("depth", "normals", "ids"):
        image = outcore.render(client, **CAMERA, mode=mode)
        assert image.shape == (30, 40, 3) and image.dtype == np.uint8
        assert np.all(image[miss] == 0), mode
        assert np.all(image[~miss].max(axis=-1) > 0), mode


def test_depth_makes_the_nearest_surface_brightest_and_the_farthest_darkest(client):
    geometry = geometry_of(client)
    image = outcore.render(client, **CAMERA)  # depth is the default
    # t is the depth along the view axis (Open3D's rays): 8, 9 and 10 for the
    # planes at z = 2, 1, 0, so s = 1, 0.5 and 0: exactly stops 4, 2 and 0.
    assert np.all(image[geometry == 0] == STOPS[4])
    assert np.all(image[geometry == 2] == STOPS[2])
    assert np.all(image[geometry == 1] == STOPS[0])
    brightness = image.astype(int).sum(axis=-1)
    assert brightness[geometry == 0].min() > brightness[geometry == 2].max() > brightness[geometry == 1].max()


def test_normals_colour_an_axis_aligned_face_by_its_normal(client):
    geometry = geometry_of(client)
    image = outcore.render(client, **CAMERA, mode="normals")
    # Unit normal (0, 0, 1): 255 * (0 * 0.5 + 0.5) = 127.5 rounds away from zero to 128.
    for g in (0, 1, 2):
        assert np.all(image[geometry == g] == (128, 128, 255)), g


def test_ids_colour_each_geometry_by_splitmix64_of_its_id(client):
    geometry = geometry_of(client)
    image = outcore.render(client, **CAMERA, mode="ids")
    colours = [id_colour(g) for g in (0, 1, 2)]
    assert len(set(colours)) == 3
    for g in (0, 1, 2):
        assert np.all(image[geometry == g] == colours[g]), g


def test_the_picture_is_upright_with_the_worlds_up(client):
    # Looking down -z with y up, the marker at +x +y is in the top rows and
    # the right columns, as a photograph shows it.
    geometry = geometry_of(client)
    rows, columns = np.nonzero(geometry == 2)
    assert rows.max() < 15 and columns.min() >= 20
    image = outcore.render(client, **CAMERA, mode="ids")
    assert np.all(image[rows, columns] == id_colour(2))


def test_bad_render_arguments_are_value_errors_naming_them(client):
    for name, value, match in (("mode", "colour", "mode"), ("width", 0, "width"), ("height", 1.5, "height"),
                               ("fov_deg", 200, "fov_deg"), ("eye", [0, 0, 0], "eye"), ("up", [0, 0, 2], "up")):
        kwargs = dict(CAMERA)
        kwargs[name] = value
        with pytest.raises(ValueError, match=match):
            outcore.render(client, **kwargs)


def synthetic(t=None, normals=None, geometry=None):
    n = len(next(a for a in (t, normals, geometry) if a is not None))
    t = np.full(n, 1.0, np.float32) if t is None else np.asarray(t, np.float32)
    hit = np.isfinite(t)
    return {
        "t_hit": t,
        "geometry_ids": np.where(hit, 0 if geometry is None else geometry, outcore.INVALID_ID).astype(np.uint32),
        "primitive_ids": np.where(hit, 0, outcore.INVALID_ID).astype(np.uint32),
        "primitive_uvs": np.zeros((n, 2), np.float32),
        "primitive_normals": np.zeros((n, 3), np.float32) if normals is None else np.asarray(normals, np.float32),
    }


def test_depth_interpolates_between_stops_and_rounds_halves_away_from_zero():
    # tmin 0, tmax 1: t = 0.875 is s = 0.125, halfway from stop 0 to stop 1:
    # (63.5, 41.5, 111.5) -> (64, 42, 112); t = 0.5 is stop 2; 0.375 is s =
    # 0.625, halfway from stop 2 to stop 3: (63.5, 173, 119).
    image = hits_to_image(synthetic(t=[0.0, 1.0, 0.875, 0.5, 0.375, np.inf]), "depth")
    assert image.tolist() == [list(STOPS[4]), list(STOPS[0]), [64, 42, 112], list(STOPS[2]), [64, 173, 119],
                              [0, 0, 0]]
    # One depth only: v = 0, s = 1.
    assert hits_to_image(synthetic(t=[3.0, 3.0, np.inf]), "depth").tolist() == [list(STOPS[4])] * 2 + [[0, 0, 0]]


def test_normal_and_id_colours_follow_their_formulas():
    s = np.float32(np.sqrt(0.5))
    image = hits_to_image(synthetic(normals=[[-1, 0, 1], [s, -s, 0]]), "normals")
    # 255 * (s * 0.5 + 0.5) = 217.66 -> 218; 255 * (0.5 - s * 0.5) = 37.34 -> 37.
    assert image.tolist() == [[0, 128, 255], [218, 37, 128]]
    ids = [0, 1, 7, 4294967294]
    image = hits_to_image(synthetic(geometry=np.array(ids)), "ids")
    assert image.tolist() == [list(id_colour(g)) for g in ids]
    assert int(splitmix64(np.array([0]))[0]) == 0xE220A8397B1DCDAF  # splitmix64's first output from seed 0


def test_write_png_writes_a_png_that_decodes_to_the_image(tmp_path):
    image = np.random.default_rng(1).integers(0, 256, (5, 7, 3), dtype=np.uint8)
    path = tmp_path / "picture.png"
    outcore.write_png(path, image)
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    chunks, at = {}, 8
    while at < len(data):
        (length,) = struct.unpack(">I", data[at:at + 4])
        kind, body = data[at + 4:at + 8], data[at + 8:at + 8 + length]
        (crc,) = struct.unpack(">I", data[at + 8 + length:at + 12 + length])
        assert crc == zlib.crc32(kind + body), kind
        chunks[kind] = body
        at += 12 + length
    assert list(chunks) == [b"IHDR", b"IDAT", b"IEND"]
    assert struct.unpack(">IIBBBBB", chunks[b"IHDR"]) == (7, 5, 8, 2, 0, 0, 0)
    rows = np.frombuffer(zlib.decompress(chunks[b"IDAT"]), np.uint8).reshape(5, 1 + 7 * 3)
    assert np.all(rows[:, 0] == 0)
    assert np.array_equal(rows[:, 1:].reshape(5, 7, 3), image)
    assert [p.name for p in tmp_path.iterdir()] == ["picture.png"]  # no temporary file left
    with pytest.raises(ValueError, match="uint8"):
        outcore.write_png(tmp_path / "x.png", image.astype(np.float32))
    with pytest.raises(ValueError, match="shape"):
        outcore.write_png(tmp_path / "x.png", np.zeros((4, 4, 2), np.uint8))
