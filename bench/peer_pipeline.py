#!/usr/bin/python3
"""The peer riemesh is measured against: what an OpenVDB user runs today, in one Python process.

    peer_pipeline.py INPUT.vdb OUTPUT.ply [--grid NAME] [--iso V] [--sigma S] [--adaptivity A]

Reads the grid with pyopenvdb; for a fog volume or other image (not a level set) with --sigma > 0,
smooths it with scipy.ndimage.gaussian_filter over its active bounding box (copyToArray /
copyFromArray: the usual way to smooth a VDB from Python); meshes it with OpenVDB's volumeToMesh
(grid.convertToPolygons, quads split into triangles, winding flipped to face outward) and writes a
binary PLY. Prints one line of JSON: phases in seconds, vertices, triangles. Run it under
/usr/bin/time -f %M for the peak memory. Debian's python3-openvdb, python3-scipy, python3-numpy.
"""
import argparse
import json
import sys
import time

import numpy as np
import pyopenvdb as vdb


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("input")
    ap.add_argument("output")
    ap.add_argument("--grid", default=None)
    ap.add_argument("--iso", type=float, default=None)
    ap.add_argument("--sigma", type=float, default=1.5)
    ap.add_argument("--adaptivity", type=float, default=0.5)
    a = ap.parse_args()
    t0 = time.monotonic()
    if a.grid:
        grid = vdb.read(a.input, a.grid)
    else:
        grid = vdb.readAllGridMetadata(a.input)[0]
        grid = vdb.read(a.input, grid.name)
    t1 = time.monotonic()
    level_set = grid.gridClass == vdb.GridClass.LEVEL_SET
    iso = a.iso if a.iso is not None else (0.0 if level_set else 0.5)
    if a.sigma > 0 and not level_set:
        from scipy import ndimage
        lo, hi = grid.evalActiveVoxelBoundingBox()
        shape = tuple(h - l + 1 for l, h in zip(lo, hi))
        arr = np.zeros(shape, dtype=np.float32)
        grid.copyToArray(arr, ijk=lo)
        arr = ndimage.gaussian_filter(arr, a.sigma, mode="nearest")
        smooth = vdb.FloatGrid(grid.background)
        smooth.transform = grid.transform
        smooth.copyFromArray(arr, ijk=lo, tolerance=0)
        del arr
        grid = smooth
    t2 = time.monotonic()
    points, tris, quads = grid.convertToPolygons(isovalue=iso, adaptivity=a.adaptivity)
    faces = np.concatenate([tris.reshape(-1, 3),
                            quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]).astype(np.int32)
    faces = faces[:, ::-1]  # volumeToMesh winds clockwise seen from outside
    t3 = time.monotonic()
    with open(a.output, "wb") as f:
        f.write(("ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
                 "property float z\nelement face %d\nproperty list uchar int vertex_indices\nend_header\n"
                 % (len(points), len(faces))).encode())
        f.write(points.astype("<f4").tobytes())
        rec = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
        rec["n"] = 3
        rec["v"] = faces
        f.write(rec.tobytes())
    t4 = time.monotonic()
    print(json.dumps({"read": t1 - t0, "smooth": t2 - t1, "mesh": t3 - t2, "write": t4 - t3, "seconds": t4 - t0,
                      "vertices": int(len(points)), "triangles": int(len(faces))}))


if __name__ == "__main__":
    sys.exit(main())
