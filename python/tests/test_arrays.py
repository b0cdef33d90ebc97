"""numpy arrays in: volume[i, j, k] as in scikit-image, world = origin + spacing * (i, j, k); float32,
float64 and integer arrays of any order or strides are read where they are (no copy: measured with
tracemalloc, which sees every numpy allocation); other dtypes are converted; bad arrays are refused."""
import tracemalloc

import numpy as np
import pytest

import riemesh


def ball(shape=(40, 36, 32), centre=(20.0, 17.0, 15.0), radius=10.0, dtype=np.float32):
    """A fog-like ball: 1 inside, 0 outside, a one-voxel ramp across the sphere."""
    i, j, k = np.meshgrid(*[np.arange(n, dtype=np.float64) for n in shape], indexing="ij")
    d = np.sqrt((i - centre[0]) ** 2 + (j - centre[1]) ** 2 + (k - centre[2]) ** 2) - radius
    return np.clip(0.5 - d, 0, 1).astype(dtype)


def allocated_during(make):
    """Peak bytes numpy (and Python) allocated while make() ran."""
    tracemalloc.start()
    tracemalloc.reset_peak()
    try:
        before = tracemalloc.get_traced_memory()[0]
        make()
        return tracemalloc.get_traced_memory()[1] - before
    finally:
        tracemalloc.stop()


def test_c_ordered_float32_is_not_copied(phantom_array):
    array = np.ascontiguousarray(np.tile(phantom_array, (2, 1, 1)))  # 96x48x48, 884 KB
    assert array.flags.c_contiguous and array.dtype == np.float32
    copied = allocated_during(lambda: riemesh.Volume(array))
    assert copied < array.nbytes / 20, copied
    # Other layouts read in place too: Fortran order, float64, a strided view, integers.
    for view in (np.asfortranarray(array), array.astype(np.float64), array[::2, :, ::-1], (array * 100).astype(np.int16)):
        assert allocated_during(lambda: riemesh.Volume(view)) < array.nbytes / 20
    # The measure sees a copy where there is one: float16 and byte-swapped arrays are converted to float32.
    for converted in (array.astype(np.float16), array.astype(">f4")):
        assert allocated_during(lambda: riemesh.Volume(converted)) >= array.nbytes


def test_volume_holds_the_array_values_in_every_layout():
    base = np.random.default_rng(5).normal(size=(9, 7, 5)).astype(np.float32)
    base[4, 3, 2] = 9.5
    base[0, 6, 1] = -8.25
    for array in (base, np.asfortranarray(base), base.astype(np.float64), base[::-1, :, ::-1].copy()[::-1, :, ::-1],
                  np.broadcast_to(base, base.shape)):
        info = riemesh.Volume(array).info
        assert info["dims"] == (9, 7, 5)
        assert info["min"] == -8.25 and info["max"] == 9.5
        assert info["active_voxels"] == base.size
    info = riemesh.Volume(np.arange(2 * 3 * 4, dtype=np.uint8).reshape(2, 3, 4)).info
    assert (info["min"], info["max"]) == (0, 23)


def test_world_coordinates_are_origin_plus_spacing_times_index():
    spacing, origin = (0.5, 1.0, 2.0), (10.0, -20.0, 30.0)
    result = riemesh.mesh(ball(), 0.5, spacing=spacing, origin=origin, delta=1.5)
    centre = np.array(origin) + np.array(spacing) * np.array([20.0, 17.0, 15.0])
    radii = 10.0 * np.array(spacing)
    lo, hi = result.vertices.min(axis=0), result.vertices.max(axis=0)
    assert np.allclose(lo, centre - radii, atol=1.0 * np.array(spacing))
    assert np.allclose(hi, centre + radii, atol=1.0 * np.array(spacing))
    # An ellipsoid with those semi-axes: (x - c) / r has unit length at the vertices, within a voxel.
    unit = np.linalg.norm((result.vertices - centre) / radii, axis=1)
    assert np.abs(unit - 1).max() < 0.1
    assert result.stats["summary"]["genus"] == 0 and result.stats["summary"]["components"] == 1
    assert result.vertices.dtype == np.float64 and result.faces.dtype == np.int32
    assert result.vertices.shape[1] == 3 and result.faces.shape[1] == 3
    assert result.faces.min() == 0 and result.faces.max() == len(result.vertices) - 1


def test_faces_wind_outward():
    result = riemesh.mesh(ball(), 0.5)
    v, f = result.vertices, result.faces
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    signed_volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
    assert signed_volume > 0
    assert abs(signed_volume - 4 / 3 * np.pi * 10 ** 3) < 0.2 * 4 / 3 * np.pi * 10 ** 3  # a coarse polyhedron


def test_level_set_array_meshes_its_zero_set_with_inside_negative():
    i, j, k = np.meshgrid(*[np.arange(32.0)] * 3, indexing="ij")
    sdf = np.sqrt((i - 15.5) ** 2 + (j - 15.5) ** 2 + (k - 15.5) ** 2) - 9
    result = riemesh.mesh(sdf, grid_class="levelset")
    assert result.stats["parameters"]["iso"] == 0
    r = np.linalg.norm(result.vertices - 15.5, axis=1)
    assert np.abs(r - 9).max() < 0.5


@pytest.mark.parametrize("array,message", [
    (np.zeros((10, 10)), "expected a 3D array indexed [i, j, k], got shape (10, 10)"),
    (np.zeros((10, 1, 10)), "not a 3D block"),
    (np.full((4, 4, 4), np.nan), "64 non-finite (NaN or infinite) values"),
    (np.zeros((4, 4, 4), complex), "is not a real number type"),
])
def test_bad_arrays_are_value_errors(array, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[").replace("]", r"\]")):
        riemesh.mesh(array, 0.5)


def test_bad_placement_and_missing_iso_are_value_errors():
    with pytest.raises(ValueError, match="spacing: must be > 0"):
        riemesh.Volume(ball(), spacing=(1, 0, 1))
    with pytest.raises(ValueError, match="spacing: expected a number or 3 numbers"):
        riemesh.Volume(ball(), spacing=(1, 1))
    with pytest.raises(ValueError, match="grid_class: 'smoke' is not fog, levelset or unknown"):
        riemesh.Volume(ball(), grid_class="smoke")
    with pytest.raises(ValueError, match="image 'array' is neither a fog volume nor a level set: give --iso"):
        riemesh.mesh(ball())
    with pytest.raises(ValueError, match="apply to arrays only"):
        riemesh.mesh(riemesh.Volume(ball()), 0.5, spacing=2)
    with pytest.raises(ValueError, match="the image of 4000x4000x4000 voxels needs about"):
        riemesh.Volume(np.broadcast_to(np.float32(0), (4000, 4000, 4000)), max_memory=1 << 30)
