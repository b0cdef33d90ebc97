// riemesh/vdb/phantom.h: synthetic test volumes with a known surface (paper 5, Fig. 4).
//
// Every phantom is an N^3 box of unit voxels (world = index, voxel centres at 0..N-1). Two grids:
// - "density": a fog volume, 1 inside the object and 0 outside with a one-voxel partial-volume ramp
//   across the surface (clamp(0.5 - sdf, 0, 1): its 0.5 isosurface is the true surface), plus additive
//   Gaussian noise of standard deviation `noise`, seeded. Every voxel of the box is active (zeros too),
//   so the model sees image data everywhere in the box.
// - "sdf": the exact signed Euclidean distance to the true surface (world units, negative inside),
//   every voxel active, class level set; for accuracy measurements.
#pragma once

#include <openvdb/openvdb.h>

#include <cstdint>
#include <string>
#include <vector>

namespace riemesh::vdb {

enum class PhantomShape {
    CubeCavity, ///< the paper's phantom: a cube with a spherical cavity opening through a hole in its top face (genus 0)
    Ball,       ///< a ball (genus 0)
    Torus,      ///< a torus (genus 1)
    TwoSpheres, ///< two balls three voxels apart (two components: a model must not merge them)
    ThinPlate,  ///< a square plate three voxels thick (genus 0: a coarse model punches holes in it)
    /// a cube (half-size 0.3 N) with a notch cut along one of its edges (x and z above 0.05 N from
    /// the centre): two concave edges, where the others are convex (genus 0)
    NotchedBlock
};

/// "cube-cavity", "ball", "torus", "two-spheres", "thin-plate", "notched-block".
std::vector<std::string> phantomShapeNames();
/// Throws std::invalid_argument listing the valid names when unknown.
PhantomShape phantomShapeFromName(const std::string& name);

struct PhantomOptions {
    int size = 100;          ///< N, voxels per axis (>= 16)
    double noise = 0.0;      ///< standard deviation of the additive Gaussian noise (intensity)
    std::uint64_t seed = 1;  ///< noise seed (same seed, same volume)
};

/// Exact signed distance (world units, negative inside) of `shape` in a box of `size` voxels.
double phantomDistance(PhantomShape shape, int size, const openvdb::Vec3d& p);

struct Phantom {
    openvdb::FloatGrid::Ptr density; ///< "density", fog volume
    openvdb::FloatGrid::Ptr sdf;     ///< "sdf", level set class
};

Phantom makePhantom(PhantomShape shape, const PhantomOptions& options = {});

} // namespace riemesh::vdb
