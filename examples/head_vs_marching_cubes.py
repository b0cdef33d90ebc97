#!/usr/bin/python3
"""A head MRI (NIfTI) as a numpy array, meshed by riemesh and by scikit-image's marching cubes.

    PYTHONPATH=build/python /usr/bin/python3 examples/head_vs_marching_cubes.py \
        [IMAGE.nii.gz] [--iso 40] [--out DIR]

Default image: the Colin27 T1 MRI of Debian's mricron-data (181x217x181, 1 mm). Both get the same
float32 array (nibabel), the same isovalue and the same voxel spacing, so both meshes are in the same
coordinates (millimetres from voxel (0, 0, 0)); prints vertices, faces, components, genus and open
boundary loops side by side, and writes both meshes (PLY) to DIR (default: the current folder).
Needs python3-nibabel and python3-skimage (scripts/setup installs them).
"""
import argparse
import os
import time

import nibabel
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from skimage import measure

import riemesh


def topology(vertices, faces):
    """Vertices, faces, components, genus and boundary loops of a triangle mesh (orientable surfaces:
    Euler characteristic V - E + F = 2C - 2g - B)."""
    used = np.unique(faces)
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    n = len(vertices)
    graph = coo_matrix((np.ones(len(unique)), (unique[:, 0], unique[:, 1])), shape=(n, n))
    labels = connected_components(graph, directed=False)[1]
    components = len(np.unique(labels[used]))
    boundary = unique[count == 1]
    # Boundary loops: components of the graph of boundary edges.
    loops = 0
    if len(boundary):
        bgraph = coo_matrix((np.ones(len(boundary)), (boundary[:, 0], boundary[:, 1])), shape=(n, n))
        blabels = connected_components(bgraph, directed=False)[1]
        loops = len(np.unique(blabels[np.unique(boundary)]))
    euler = len(used) - len(unique) + len(faces)
    genus = (2 * components - euler - loops) // 2
    return {"vertices": len(used), "faces": len(faces), "components": components, "genus": genus,
            "boundary loops": loops, "non-manifold edges": int((count > 2).sum())}


def write_ply(path, vertices, faces):
    with open(path, "wb") as f:
        f.write(("ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
                 "property float z\nelement face %d\nproperty list uchar int vertex_indices\nend_header\n"
                 % (len(vertices), len(faces))).encode())
        f.write(np.asarray(vertices, "<f4").tobytes())
        packed = np.empty(len(faces), [("n", "u1"), ("i", "<i4", 3)])
        packed["n"], packed["i"] = 3, faces
        f.write(packed.tobytes())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("image", nargs="?", default="/usr/share/mricron/templates/ch2.nii.gz")
    ap.add_argument("--iso", type=float, default=40)
    ap.add_argument("--out", default=".")
    args = ap.parse_args()

    nifti = nibabel.load(args.image)
    volume = np.asarray(nifti.get_fdata(dtype=np.float32))  # C order, indexed [i, j, k]
    spacing = tuple(float(s) for s in nifti.header.get_zooms()[:3])
    print("%s: %s voxels of %s mm, values %g to %g, iso %g" % (os.path.basename(args.image), volume.shape, spacing,
                                                                volume.min(), volume.max(), args.iso))

    start = time.perf_counter()
    ours = riemesh.mesh(volume, args.iso, spacing=spacing)
    ours_seconds = time.perf_counter() - start
    start = time.perf_counter()
    verts, faces, _, _ = measure.marching_cubes(volume, args.iso, spacing=spacing)
    mc_seconds = time.perf_counter() - start

    rows = [("riemesh.mesh", topology(ours.vertices, ours.faces), ours_seconds),
            ("skimage marching_cubes", topology(verts, faces), mc_seconds)]
    keys = ["vertices", "faces", "components", "genus", "boundary loops", "non-manifold edges"]
    width = [max(len(k), 8) + 2 for k in keys]
    print("%-24s" % "" + "".join("%*s" % (w, k) for w, k in zip(width, keys)) + "%10s" % "seconds")
    for name, t, seconds in rows:
        print("%-24s" % name + "".join("%*d" % (w, t[k]) for w, k in zip(width, keys)) + "%10.2f" % seconds)
    s = ours.stats["summary"]
    print("riemesh: %d iterations (%s), %d self-intersections; vertices in mm from voxel (0, 0, 0), as "
          "marching_cubes's" % (s["iterations"], s["stop"], s["self_intersections"]))

    os.makedirs(args.out, exist_ok=True)
    ours.save(os.path.join(args.out, "head_riemesh.ply"))
    write_ply(os.path.join(args.out, "head_marching_cubes.ply"), verts, faces)
    print("wrote %s and %s" % (os.path.join(args.out, "head_riemesh.ply"),
                               os.path.join(args.out, "head_marching_cubes.ply")))


if __name__ == "__main__":
    main()
