"""Ray batch checks and conversion (outcore._rays): what is accepted, what is
rejected with a ValueError naming the problem. Needs no server."""

import numpy as np
import pytest

from outcore._rays import as_wire_rays


def test_float32_contiguous_rays_pass_without_copy():
    rays = np.zeros((10, 6), dtype=np.float32)
    flat, batch_shape = as_wire_rays(rays)
    assert flat.base is rays or flat is rays
    assert batch_shape == (10,)


def test_other_dtypes_and_layouts_become_contiguous_little_endian_float32():
    rays64 = np.arange(80, dtype=np.float64).reshape(8, 10)[:, 1:9]  # non-contiguous float64
    flat, batch_shape = as_wire_rays(rays64)
    assert flat.dtype == np.dtype("<f4") and flat.flags.c_contiguous
    assert batch_shape == (8,)
    np.testing.assert_array_equal(flat, rays64.astype(np.float32))
    big_endian = np.ones((3, 6), dtype=">f4")
    assert as_wire_rays(big_endian)[0].dtype == np.dtype("<f4")
    assert as_wire_rays(np.ones((2, 6), dtype=np.int32))[0].dtype == np.dtype("<f4")
    assert as_wire_rays([[0, 0, 0, 1, 0, 0]])[0].shape == (1, 6)


def test_leading_batch_dims_are_flattened_and_reported():
    rays = np.zeros((4, 5, 8), dtype=np.float32)
    flat, batch_shape = as_wire_rays(rays)
    assert flat.shape == (20, 8)
    assert batch_shape == (4, 5)
    flat, batch_shape = as_wire_rays(np.zeros((0, 6), np.float32))
    assert flat.shape == (0, 6) and batch_shape == (0,)


@pytest.mark.parametrize(
    "rays,needle",
    [
        (np.zeros((5, 7), np.float32), "shape (5, 7)"),
        (np.zeros(6, np.float32), "shape (6,)"),
        (np.float32(1.0), "shape ()"),
        (np.zeros((5, 6, 1), np.float32), "shape (5, 6, 1)"),
        (np.zeros((5, 6), np.complex64), "dtype complex64"),
        (np.zeros((5, 6), bool), "dtype bool"),
        (np.array([["a"] * 6]), "dtype <U1"),
        (np.empty((2, 6), dtype=object), "dtype object"),
        ([[1, 2, 3], [1, 2]], "array of numbers"),
    ],
)
def test_bad_rays_are_a_value_error_naming_the_problem(rays, needle):
    with pytest.raises(ValueError) as error:
        as_wire_rays(rays)
    assert needle in str(error.value)
