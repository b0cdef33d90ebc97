"""The rest of the module: read_volume and phantom, Volume copies, the result's save(), progress
callbacks and stopping early, init specs."""
import numpy as np
import pytest

import riemesh
from conftest import read_ply


def test_read_volume_and_phantom(phantom_file):
    volume = riemesh.read_volume(phantom_file)
    info = volume.info
    assert info["format"] == "vdb" and info["grid"] == "density" and info["class"] == "fog"
    assert info["dims"] == (48, 48, 48) and info["voxel_size"] == 1
    assert info["world_bounds"] == ((0, 0, 0), (47, 47, 47))
    assert riemesh.read_volume(phantom_file, grid="sdf").info["class"] == "levelset"
    made = riemesh.phantom("cube-cavity", size=48, noise=0.5, seed=1)
    assert made.info["min"] == info["min"] and made.info["max"] == info["max"]
    assert "torus" in riemesh.phantom_shapes()
    torus = riemesh.mesh(riemesh.phantom("torus", size=40, noise=0.2))
    assert torus.stats["summary"]["genus"] == 1
    assert repr(torus).startswith("<riemesh.Mesh ") and "genus 1" in repr(torus)


def test_file_errors(tmp_path, phantom_file):
    with pytest.raises(FileNotFoundError, match="no such file"):
        riemesh.read_volume(tmp_path / "none.vdb")
    bad = tmp_path / "bad.vdb"
    bad.write_bytes(b"not a vdb file at all")
    with pytest.raises(ValueError, match="not a VDB file"):
        riemesh.mesh(bad)
    text = tmp_path / "image.txt"
    text.write_text("x")
    with pytest.raises(ValueError, match="unknown input extension '.txt'"):
        riemesh.read_volume(text)
    with pytest.raises(ValueError, match="no grid named 'smoke'"):
        riemesh.read_volume(phantom_file, grid="smoke")
    with pytest.raises(ValueError, match="grid: applies to a .vdb or .nvdb file path only"):
        riemesh.mesh(riemesh.read_volume(phantom_file), grid="sdf")
    with pytest.raises(ValueError, match="dodecahedron"):
        riemesh.phantom("dodecahedron")


def test_meshing_a_volume_leaves_it_unchanged(phantom_file):
    volume = riemesh.read_volume(phantom_file)
    first = riemesh.mesh(volume)
    assert volume.info == riemesh.read_volume(phantom_file).info
    second = riemesh.mesh(volume)
    assert np.array_equal(first.vertices, second.vertices)
    copy = volume.copy()
    assert copy.info == volume.info


def test_save_writes_every_format_atomically(tmp_path, phantom_file):
    result = riemesh.mesh(phantom_file)
    for ext in (".obj", ".ply", ".off", ".stl", ".vdb"):
        result.save(tmp_path / ("m" + ext))
        assert (tmp_path / ("m" + ext)).stat().st_size > 0
    vertices, faces = read_ply(tmp_path / "m.ply")
    assert np.array_equal(vertices, result.vertices.astype(np.float32)) and np.array_equal(faces, result.faces)
    assert riemesh.read_volume(tmp_path / "m.vdb").info["class"] == "levelset"
    with pytest.raises(ValueError, match="'.xyz'"):
        result.save(tmp_path / "m.xyz")
    with pytest.raises(RuntimeError, match="does not exist"):
        result.save(tmp_path / "no" / "m.ply")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.obj", "m.off", "m.ply", "m.stl", "m.vdb"]


def test_progress_receives_every_iteration_and_can_stop_early(phantom_file):
    seen = []
    result = riemesh.mesh(phantom_file, progress=seen.append)
    assert [s["iteration"] for s in seen] == list(range(1, len(result.stats["iterations"]) + 1))
    assert seen == result.stats["iterations"][:len(seen)] or \
        [{k: v for k, v in s.items() if k != "ms"} for s in seen] == \
        [{k: v for k, v in s.items() if k != "ms"} for s in result.stats["iterations"]]
    assert seen[0].keys() == result.stats["iterations"][0].keys()

    stopped = riemesh.mesh(phantom_file, progress=lambda s: s["iteration"] < 5)
    assert len(stopped.stats["iterations"]) == 5
    assert stopped.stats["summary"]["stop"] == "interrupted"
    assert len(stopped.vertices) == stopped.stats["summary"]["vertices"] > 0

    def boom(stats):
        if stats["iteration"] == 3:
            raise ZeroDivisionError("from the callback")
    with pytest.raises(ZeroDivisionError, match="from the callback"):
        riemesh.mesh(phantom_file, progress=boom)
    with pytest.raises(TypeError, match="progress: must be callable"):
        riemesh.mesh(phantom_file, progress=3)


def test_init_spheres_inflate_inside_the_object():
    i, j, k = np.meshgrid(*[np.arange(40.0)] * 3, indexing="ij")
    two = np.maximum(np.clip(8 - np.sqrt((i - 10) ** 2 + (j - 20) ** 2 + (k - 20) ** 2), 0, 1),
                     np.clip(8 - np.sqrt((i - 30) ** 2 + (j - 20) ** 2 + (k - 20) ** 2), 0, 1))
    result = riemesh.mesh(two, 0.5, init="sphere:10,20,20,3;30,20,20,3", delta=1.5)
    assert result.stats["parameters"]["init"] == "sphere:10,20,20,3;30,20,20,3"
    assert result.stats["summary"]["components"] == 2


def test_intersection_free_reaches_the_evolution():
    # Two balls 2 voxels apart: the guarded evolution ends embedded, with the flag in the stats
    # (the same flag as vdb2mesh --intersection-free; default off).
    i, j, k = np.meshgrid(*[np.arange(48.0)] * 3, indexing="ij")
    two = np.maximum(np.clip(9 - np.sqrt((i - 13) ** 2 + (j - 24) ** 2 + (k - 24) ** 2), 0, 1),
                     np.clip(9 - np.sqrt((i - 35) ** 2 + (j - 24) ** 2 + (k - 24) ** 2), 0, 1))
    plain = riemesh.mesh(two, 0.5)
    assert plain.stats["parameters"]["intersection_free"] is False
    guarded = riemesh.mesh(two, 0.5, intersection_free=True)
    assert guarded.stats["parameters"]["intersection_free"] is True
    assert guarded.stats["summary"]["self_intersections"] == 0
    assert guarded.stats["summary"]["components"] == 2
    with pytest.raises(TypeError):
        riemesh.mesh(two, 0.5, intersection_free="yes please")
