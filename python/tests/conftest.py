"""Fixtures shared by the riemesh pytest files: the built command-line tools, small phantoms written by
vdbphantom, and a reader for the binary PLY files riemesh writes. ctest sets PYTHONPATH (the module in
build/python) and RIEMESH_BIN (build/bin); run by hand:
    PYTHONPATH=build/python RIEMESH_BIN=build/bin /usr/bin/python3 -m pytest python/tests
"""
import os
import pathlib
import subprocess

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def bin_dir():
    path = pathlib.Path(os.environ.get("RIEMESH_BIN", ROOT / "build" / "bin"))
    if not (path / "vdb2mesh").exists():
        pytest.fail(f"vdb2mesh not found in {path} (set RIEMESH_BIN)")
    return path


def run(*args, check=True):
    """Runs a command, returns the CompletedProcess (text output)."""
    result = subprocess.run([str(a) for a in args], capture_output=True, text=True)
    if check and result.returncode != 0:
        raise AssertionError(f"{args} failed ({result.returncode}): {result.stderr}")
    return result


@pytest.fixture(scope="session")
def phantom_file(bin_dir, tmp_path_factory):
    """The paper's phantom at 48^3 (noise 0.5, seed 1) as a .vdb with 'density' and 'sdf' grids."""
    path = tmp_path_factory.mktemp("phantom") / "cube48.vdb"
    run(bin_dir / "vdbphantom", "cube-cavity", path, "--size", "48", "--noise", "0.5", "--seed", "1")
    return path


@pytest.fixture(scope="session")
def phantom_array(phantom_file):
    """The phantom's density as a C-ordered float32 array indexed [i, j, k] (through pyopenvdb)."""
    pyopenvdb = pytest.importorskip("pyopenvdb")
    grid = pyopenvdb.read(str(phantom_file), "density")
    array = np.zeros((48, 48, 48), np.float32)
    grid.copyToArray(array)
    return array


def read_ply(path):
    """(vertices float32 N x 3, faces int32 M x 3) of a binary little-endian PLY as riemesh writes it."""
    data = pathlib.Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    counts = {line.split()[1]: int(line.split()[2]) for line in header if line.startswith("element")}
    assert "format binary_little_endian 1.0" in header
    vertices = np.frombuffer(data, "<f4", counts["vertex"] * 3, end).reshape(-1, 3)
    faces = np.frombuffer(data, [("n", "u1"), ("i", "<i4", 3)], counts["face"], end + vertices.nbytes)
    assert (faces["n"] == 3).all()
    return vertices, faces["i"]
