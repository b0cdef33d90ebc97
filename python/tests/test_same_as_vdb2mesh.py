"""The Python call and vdb2mesh give the same mesh (same vertex count, positions and faces) on the same
image and parameters, whatever way the image reaches Python: file path, riemesh.Volume, numpy array
(C or Fortran order, float32 or float64), pyopenvdb grid. And the same statistics fields and error
messages."""
import json

import numpy as np
import pytest

import riemesh
from conftest import read_ply, run


def vdb2mesh(bin_dir, tmp_path, image, *flags):
    out = tmp_path / "cli.ply"
    stats = tmp_path / "cli.json"
    run(bin_dir / "vdb2mesh", image, out, "--stats", stats, "-q", *flags)
    vertices, faces = read_ply(out)
    return vertices, faces, json.loads(stats.read_text())


def assert_same_mesh(result, vertices, faces):
    assert result.vertices.shape == vertices.shape
    # PLY stores float32: the Python vertices (float64) round to exactly the file's.
    assert np.array_equal(result.vertices.astype(np.float32), vertices)
    assert np.array_equal(result.faces, faces)


@pytest.mark.parametrize("flags,kwargs", [
    ((), {}),
    (("--metric", "euclidean", "--delta", "2"), {"metric": "euclidean", "delta": 2}),
    (("--mu-max", "4", "--edge-gain", "2", "--sigma", "1.5", "--rho", "3"),
     {"mu_max": 4, "edge_gain": 2, "sigma": 1.5, "rho": 3}),
    (("--zeta", "3", "--smooth", "0.5", "--downsample", "2", "--open-borders"),
     {"zeta": 3, "smooth": 0.5, "downsample": 2, "open_borders": True}),
    (("--no-sharpen",), {"sharpen": False}),
    (("--face-samples",), {"face_samples": True}),
])
def test_file_path_gives_vdb2mesh_mesh(bin_dir, tmp_path, phantom_file, flags, kwargs):
    vertices, faces, _ = vdb2mesh(bin_dir, tmp_path, phantom_file, *flags)
    assert_same_mesh(riemesh.mesh(phantom_file, **kwargs), vertices, faces)
    assert_same_mesh(riemesh.mesh(riemesh.read_volume(phantom_file), **kwargs), vertices, faces)


def test_arrays_give_vdb2mesh_mesh(bin_dir, tmp_path, phantom_file, phantom_array):
    vertices, faces, _ = vdb2mesh(bin_dir, tmp_path, phantom_file)
    assert phantom_array.flags.c_contiguous and phantom_array.dtype == np.float32
    assert_same_mesh(riemesh.mesh(phantom_array, 0.5), vertices, faces)
    assert_same_mesh(riemesh.mesh(np.asfortranarray(phantom_array), 0.5), vertices, faces)
    assert_same_mesh(riemesh.mesh(phantom_array.astype(np.float64), grid_class="fog"), vertices, faces)


def test_pyopenvdb_grid_gives_vdb2mesh_mesh_and_stays_unchanged(bin_dir, tmp_path, phantom_file):
    pyopenvdb = pytest.importorskip("pyopenvdb")
    assert riemesh.has_pyopenvdb
    vertices, faces, _ = vdb2mesh(bin_dir, tmp_path, phantom_file, "--grid", "density")
    grid = pyopenvdb.read(str(phantom_file), "density")
    before = np.zeros((52, 52, 52), np.float32)
    grid.copyToArray(before, ijk=(-2, -2, -2))
    assert_same_mesh(riemesh.mesh(grid), vertices, faces)
    after = np.zeros_like(before)
    grid.copyToArray(after, ijk=(-2, -2, -2))
    assert np.array_equal(before, after)  # border closing and smoothing worked on a copy
    assert grid.activeVoxelCount() == 48 ** 3


def test_level_set_defaults_to_iso_zero_inside_negative(bin_dir, tmp_path, phantom_file):
    vertices, faces, cli = vdb2mesh(bin_dir, tmp_path, phantom_file, "--grid", "sdf")
    result = riemesh.mesh(phantom_file, grid="sdf")
    assert_same_mesh(result, vertices, faces)
    assert result.stats["parameters"]["iso"] == cli["parameters"]["iso"] == 0


def test_stats_have_the_cli_fields_and_values(bin_dir, tmp_path, phantom_file):
    _, _, cli = vdb2mesh(bin_dir, tmp_path, phantom_file)
    stats = riemesh.mesh(phantom_file).stats

    def shape(d):
        return {k: shape(v) if isinstance(v, dict) else None for k, v in d.items()}

    assert shape(stats) == shape(cli)
    assert stats.keys() == cli.keys()
    assert stats["iterations"][0].keys() == cli["iterations"][0].keys()
    for key in ("image", "parameters", "metric"):
        assert stats[key] == cli[key]
    # Timings, and whether malloc used huge pages (vdb2mesh restarts itself for them; Python does not).
    timings = {"seconds", "read_seconds", "metric_seconds", "stage_seconds", "evolve_seconds", "evolve_phase_seconds",
               "write_seconds",
               "malloc_huge_pages"}
    assert {k: v for k, v in stats["summary"].items() if k not in timings} == \
        {k: v for k, v in cli["summary"].items() if k not in timings}
    assert stats["input"] == str(phantom_file) and stats["output"] is None
    assert [i["vertices"] for i in stats["iterations"]] == [i["vertices"] for i in cli["iterations"]]


@pytest.mark.parametrize("flags,kwargs", [
    (("--zeta", "1.5"), {"zeta": 1.5}),
    (("--mu-max", "0.5"), {"mu_max": 0.5}),
    (("--delta", "-1"), {"delta": -1}),
    (("--iso", "7"), {"iso": 7}),
    (("--init", "cone"), {"init": "cone"}),
    (("--init", "sphere:1,2,3"), {"init": "sphere:1,2,3"}),
    (("--metric", "fancy"), {"metric": "fancy"}),
    (("--max-vertices", "100"), {"max_vertices": 100}),
])
def test_errors_are_value_errors_with_vdb2mesh_messages(bin_dir, tmp_path, phantom_file, flags, kwargs):
    cli = run(bin_dir / "vdb2mesh", phantom_file, tmp_path / "x.ply", *flags, check=False)
    assert cli.returncode == 1
    message = cli.stderr.strip().removeprefix("vdb2mesh: error: ")
    with pytest.raises(ValueError) as error:
        riemesh.mesh(phantom_file, **kwargs)
    assert str(error.value) == message
    assert not (tmp_path / "x.ply").exists()
