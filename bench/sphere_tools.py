#!/usr/bin/python3
"""Level-set spheres for the scale benchmark, and a two-sided distance between a mesh and a sphere.

    sphere_tools.py make RADIUS OUT.vdb        pyopenvdb.createLevelSetSphere(radius, voxelSize 1,
                                               halfWidth 3) centred at the origin, grid "ls";
                                               prints its active and bounding-box voxels (JSON)
    sphere_tools.py error MESH.obj RADIUS      one line of JSON, distances in voxels:
        mesh_to_sphere_mean / _max: area-weighted over 45 samples per triangle (vertices, edges and
            interiors: barycentric grid of step 1/8), | |p| - R |
        sphere_to_mesh_mean / _max: over 20,000 points spread evenly on the true sphere, the distance
            along the ray from the centre to where it meets the mesh (the mesh is star-shaped about
            the centre; a ray that meets no triangle counts as the whole radius: a hole)
        mean: the mean of the two means (the two-sided mean distance)

Debian's python3-openvdb, python3-numpy and python3-scipy.
"""
import json
import sys

import numpy as np


def make(radius, out):
    import pyopenvdb as vdb
    g = vdb.createLevelSetSphere(radius=radius, center=(0, 0, 0), voxelSize=1.0, halfWidth=3.0)
    g.name = "ls"
    vdb.write(out, grids=[g])
    lo, hi = g.evalActiveVoxelBoundingBox()
    print(json.dumps({"active_voxels": int(g.activeVoxelCount()),
                      "box_voxels": int((hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1))}))


def read_obj(path):
    v, f = [], []
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                v.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                f.append([int(x.split("/")[0]) - 1 for x in line.split()[1:4]])
    return np.array(v), np.array(f, dtype=np.int64)


def error(path, radius):
    from scipy.spatial import cKDTree
    v, f = read_obj(path)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    # Mesh to sphere: a barycentric grid on every triangle.
    n = 8
    ij = [(i, j) for i in range(n + 1) for j in range(n + 1 - i)]
    total, worst, weight = 0.0, 0.0, 0.0
    for i, j in ij:
        p = a + (b - a) * (i / n) + (c - a) * (j / n)
        d = np.abs(np.linalg.norm(p, axis=1) - radius)
        total += float(np.sum(d * area))
        weight += float(np.sum(area))
        worst = max(worst, float(d.max()))
    m2s_mean, m2s_max = total / weight, worst
    # Sphere to mesh: rays from the centre through a Fibonacci lattice of directions.
    k = 20000
    t = np.arange(k) + 0.5
    z = 1 - 2 * t / k
    phi = np.pi * (1 + 5 ** 0.5) * t
    s = np.sqrt(1 - z * z)
    dirs = np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)
    centroid = (a + b + c) / 3
    tree = cKDTree(centroid / np.linalg.norm(centroid, axis=1)[:, None])
    _, cand = tree.query(dirs, k=16)
    best = np.full(k, np.inf)
    for col in range(cand.shape[1]):
        tri = cand[:, col]
        e1, e2 = b[tri] - a[tri], c[tri] - a[tri]
        pv = np.cross(dirs, e2)
        det = np.sum(e1 * pv, axis=1)
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tv = -a[tri]  # ray origin is the centre (0, 0, 0)
        u = np.sum(tv * pv, axis=1) * inv
        qv = np.cross(tv, e1)
        w = np.sum(dirs * qv, axis=1) * inv
        dist = np.sum(e2 * qv, axis=1) * inv
        hit = ok & (u >= -1e-9) & (w >= -1e-9) & (u + w <= 1 + 1e-9) & (dist > 0)
        gap = np.where(hit, np.abs(dist - radius), np.inf)
        best = np.minimum(best, gap)
    holes = int(np.sum(~np.isfinite(best)))
    best[~np.isfinite(best)] = radius
    s2m_mean, s2m_max = float(best.mean()), float(best.max())
    print(json.dumps({"mesh_to_sphere_mean": m2s_mean, "mesh_to_sphere_max": m2s_max,
                      "sphere_to_mesh_mean": s2m_mean, "sphere_to_mesh_max": s2m_max, "rays_missed": holes,
                      "mean": 0.5 * (m2s_mean + s2m_mean), "max": max(m2s_max, s2m_max),
                      "vertices": int(len(v)), "triangles": int(len(f))}))


def main():
    if len(sys.argv) == 4 and sys.argv[1] == "make":
        make(float(sys.argv[2]), sys.argv[3])
        return 0
    if len(sys.argv) == 4 and sys.argv[1] == "error":
        error(sys.argv[2], float(sys.argv[3]))
        return 0
    print(__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
