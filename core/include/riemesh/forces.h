// riemesh/forces.h: the forces of the dynamics (paper 3.3, 5).
//
// F_int: regularising forces (umbrella/Laplacian, split into a tangential part that evens the
// sampling and a normal part that smooths curvature). F_ext: the inflation/deflation force along the
// vertex normal that drives vertices toward the isosurface I = iso, plus optional attraction toward
// strong gradients. Forces are displacements per iteration squared times mass (world units).
#pragma once

#include "riemesh/image.h"
#include "riemesh/mesh.h"
#include "riemesh/metric.h"

#include <vector>

namespace riemesh {

/// ForceOptions::vertexShare with face samples on (vdb2mesh --face-samples).
inline constexpr double kFaceSampleVertexShare = 0.25;

struct ForceOptions {
    double iso = 0.5;             ///< isovalue of the surface to recover (image intensity)
    double contrast = 0.0;        ///< intensity scale of (I - iso) for full push; 0 = automatic
    bool objectBrighter = true;   ///< the object is where I > iso (else where I < iso)
    double externalWeight = 1.0;  ///< stiffness of the pull toward the isosurface (force per unit of distance)
    double externalLimit = 0.125; ///< largest inflation/deflation force (x delta); free flight then runs
                                  ///< below vmax, leaving headroom for creases to catch up
    double internalWeight = 0.3;  ///< tangential umbrella (sampling regularity)
    double curvatureWeight = 0.05;///< normal umbrella near the isosurface (smoothing; shrinks curved parts)
    double freeCurvatureWeight = 0.6; ///< normal umbrella in free flight (far from the isosurface), where
                                      ///< the image says nothing and creases must not fold
    double gradientWeight = 0.0;  ///< attraction toward high |grad I| along the normal
    /// Where the external force samples the image: 1 at the vertex only (the paper). Below 1 each
    /// face's centroid is sampled too, and a vertex's distance to the isosurface is vertexShare times
    /// its own estimate plus the rest times its faces' (area-weighted) mean: the balance then holds
    /// for the faces, not just their corners. A triangle's corners on a curved isosurface put its
    /// interior inside (a chord sags by ~e^2 / 8R), and the mean of a quadratic bump over a triangle
    /// is 3/4 of its value at the centroid, hence 0.25 (kFaceSampleVertexShare). Each vertex also
    /// averages ~7 samples of the noise instead of 1. Costs one image sample per face.
    double vertexShare = 1.0;
};

/// Per-vertex total force (F_int + F_ext), indexed by vertex idx(); `delta` (world units) sets the
/// force scale. Deleted vertices get zero.
///
/// With a (non-Euclidean) `metric`, the umbrella is the Riemannian one: each neighbour is weighted by
/// the metric stretch of its edge (metric length / Euclidean length, G the mean of the endpoint
/// tensors, as in regularity). Its rest state has equal *metric* edge lengths around every vertex, so
/// the sampling densifies where the metric stretches (contour edges and corners) and thins out on flat
/// parts, instead of merely staying inside [delta, zeta*delta] (a window wide enough for a uniform
/// Euclidean mesh to satisfy it almost everywhere).
void computeForces(const Mesh& mesh, const ScalarImage& image, const ForceOptions& options, double delta,
                   std::vector<Vec3>& forces, const MetricField* metric = nullptr);

} // namespace riemesh
