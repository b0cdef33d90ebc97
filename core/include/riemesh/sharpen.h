// riemesh/sharpen.h: creases and corners put back on a converged surface (issue 16).
//
// The model fits a smoothed image, whose isosurface rounds every crease and corner (a Gaussian of
// width s pulls a corner in by about 1.4 s, an edge by about 0.8 s), and its curvature force rounds
// them a little more. sharpenFeatures restores them from the surface itself, as feature-preserving
// mesh denoising does: the face normals are filtered bilaterally (each face's normal becomes the
// average of its neighbours' weighted by distance and by normal similarity, Zheng et al. 2011, so
// that the faces of a rounded crease take the orientation of one of the two flat sides), then the
// vertices are moved to fit the filtered normals (Sun et al. 2007): on the flat sides nothing moves,
// and the vertices on the rounding go out to the planes' intersection, the crease or the corner.
// The planes stay put within a round (fitting through moving centroids would shrink curved parts
// as Laplacian smoothing does); a few rounds let a corner's faces settle on its three planes.
// Smoothly curved parts (whose neighbouring normals differ by less than the range width) keep
// their shape. No face is allowed to flip or collapse; the connectivity changes only at thin rims,
// whose vertices are split in two (SharpenOptions::rimAngle).
// Only the vertices on a crease or a corner move, where the filtered normals and the image both
// show one (SharpenOptions::featureAngle): fitting every vertex would flatten organic relief and
// put points on coarsely sampled round parts. Each face's plane passes where the image puts the
// surface, not through the face (planeSearch, anchorAgreement); a thin rim held by one row of
// vertices is split into two (rimAngle); a crease cut off between two vertices gets one on it,
// or on the corner where the image ends it (insertCreases, cornerInset), and the edges around the
// new vertices are flipped to run along the creases (alignCreases). Phantom 100^3 (noise 0.5,
// seed 1) through vdb2mesh, against the exact surface: mesh->true mean 0.146 -> 0.124,
// true->mesh 0.187 -> 0.133, Hausdorff 2.50 -> 1.17 voxels.
#pragma once

#include "riemesh/image.h"
#include "riemesh/mesh.h"

#include <limits>

namespace riemesh {

struct SharpenOptions {
    int rounds = 4;            ///< rounds of filtering the normals, then fitting the vertices to them
    int normalIterations = 8;  ///< bilateral passes over the face normals per round
    double sigmaNormal = 0.3;  ///< range width of the filter, on |n_f - n_g| (0.3: about 17 degrees)
    /// Weight of a vertex's own position against each of its faces' planes: what holds a vertex
    /// along a crease, where the planes leave it free.
    double pull = 0.02;
    /// Largest move of a vertex from where it started, world units (vdb2mesh: 2.5 voxels; the
    /// blur of sigma 1 pulls a cube's corner in by about 1.4 voxels) ...
    double maxMove = std::numeric_limits<double>::infinity();
    double maxMoveEdges = 2.0; ///< ... and times the mean length of its edges
    /// With an image: no vertex is moved where the image puts it farther than maxOutside outside the
    /// isosurface (estimated as (I - iso) / |grad I|): a thin plate's rim, too thin for the mesh to
    /// have faces on, otherwise grows a fin out to where the top and bottom planes are extended.
    const ScalarImage* image = nullptr;
    double iso = 0.5;
    bool objectBrighter = true;
    double maxOutside = std::numeric_limits<double>::infinity();
    /// ... nor farther than maxInside inside it. The planes of a concave curved wall around a
    /// vertex near a crease (the phantom's hole where it meets the cavity) meet behind the wall:
    /// without this bound such vertices went 2-2.8 voxels into the object (cube-cavity seeds 4
    /// and 5, Hausdorff 1.83 and 2.62; 1.26 with it). A blurred concave crease lies inside the
    /// isosurface too, less deep: a notched block's concave edges lose nothing at 0.5 voxel.
    double maxInside = std::numeric_limits<double>::infinity();
    /// Only the vertices on a crease or a corner move: those at which two faces side by side have
    /// filtered normals more than featureAngle (degrees) apart while, with an image, the image's own
    /// normals imageStep voxels into either face from their edge (each side's the mean of three
    /// samples along the edge, in the image's voxel coordinates: the shape as the image resolves
    /// it) differ by more than imageFeatureAngle. A crease blurred by a Gaussian of sigma 1 turns
    /// the image's normals by most of its angle within 1.5 voxels of it; a round part of radius R
    /// by 1.5 / R radians on each side. Elsewhere fitting the vertices to the filtered normals flattens organic relief
    /// (the head MRI's skin, from the image's isosurface: 0.065 -> 0.176 voxel on average when
    /// every vertex is fitted, 0.067 with these), and on a coarsely sampled round part, whose faces
    /// the filter groups into facets, it puts vertices out on the facets' corners (the torus
    /// phantom, tube radius 10 voxels: Hausdorff 0.79 -> 1.25 with the image's normals compared at
    /// the faces' centres instead; with single samples at 45 degrees, noise let 2-4 vertices of the
    /// torus through on some seeds, Hausdorff 0.73 -> 0.95 on seed 5, 0 now on seeds 1-6). 0: no
    /// condition.
    double featureAngle = 30;
    double imageFeatureAngle = 50;
    double imageStep = 1.5;
    /// With an image: each face's plane passes where the line along its filtered normal from its
    /// centroid first crosses the image's isosurface, within planeSearch voxels either way (the
    /// centroid if it does not), instead of through the centroid. A face across a rounded crease or
    /// on a thin rim lies inside the image's surface (the 3-voxel plate's rim: ~0.7 voxel), and the
    /// crease was put back that far in. The smoothed image's isosurface is within 0.2 voxel of the
    /// true faces a voxel and a half from a crease (sigma 1). Plates (noise 0.5, seeds 1-3):
    /// true->mesh 0.203-0.224 -> 0.173-0.194 voxel. 0: through the centroids.
    double planeSearch = 1.5;
    /// Thin rims (a plate thinner than the mesh's edges): a vertex whose faces make two fans with
    /// opposite normals (more than rimAngle degrees apart), the top and bottom of a rim, is split
    /// in two, one for each fan, joined by a new edge across the rim (OpenMesh's vertex_split, the
    /// inverse of a collapse), so that each crease of the rim gets a row of vertices and the rim its
    /// side faces; the fit then puts them on the creases and the plate's corners. Without it the
    /// rim is one row of vertices half-way up, which misses both creases and every corner by half
    /// the plate's thickness (3-voxel plate: Hausdorff 2.1-2.7 voxels). Adds one vertex per rim
    /// vertex (the Euler characteristic is unchanged). With an image, it must show a crease
    /// (imageFeatureAngle) across both edges between the fans: across one only let two vertices of
    /// the head MRI's surface split, and their faces crossed others. 180: never.
    double rimAngle = 120;
    /// Each face's plane offset is the mean over it and its neighbours within samePlaneAngle
    /// (degrees) of its filtered normal of their anchors' offsets, each weighted by its area times
    /// (n . m)^anchorAgreement, m the image's own normal at the anchor: an anchor near a rounded
    /// crease or corner, where the image turns away from the plane, lies inside the plane and
    /// counts for little. Phantoms (noise 0.5, seeds 1-3): true->mesh cubes 0.139-0.146 ->
    /// 0.128-0.134, plates 0.164-0.178 -> 0.147-0.164. 0: each face's own anchor.
    double anchorAgreement = 8;
    double samePlaneAngle = 8;
    /// Chamfers: where a convex crease between two planes of the surface (or a corner of three)
    /// passes over a face that lies on none of them, at least chamferDepth voxels out, a vertex is
    /// added there (a 1-to-3 split of the face), after the fit: the model's edges run along a
    /// crease only where its metric put them, and a crease between two of its vertices is cut
    /// off. The planes: the face's neighbours' filtered normals in clusters more than twice
    /// featureAngle apart; chamferAngle: the face's normal at least this far from a plane it lies
    /// on. Concave creases get none: the clusters of a curved wall (the phantom's hole) make a
    /// plane that is not there, which put a vertex 1.6 voxels into the cube.
    bool insertCreases = true;
    double chamferAngle = 20;
    double chamferDepth = 0.5;
    /// A plane within ownPlaneAngle (degrees) of the face's own normal is not one it cuts across
    /// (the chamfer's own cluster, or one it nearly lies on).
    double ownPlaneAngle = 35;
    /// Where a crease ends: from the crease's point, the line along it cornerInset voxels inside
    /// both planes is followed up to a mean edge each way to where the image says outside; the
    /// nearer end's plane (across the crease) makes the third of a corner, which the vertex takes
    /// if it still lies over the face. 0: creases only.
    double cornerInset = 1.5;
    /// Insertion passes: a vertex put on a plate's top corner leaves faces on which the second
    /// pass finds the bottom one.
    int insertPasses = 2;
    /// After the insertions, edges around the new vertices are flipped while a flip lowers the
    /// total absolute dihedral angle (sum of edge length x |dihedral|; Dyn, Hormann, Kim and
    /// Levin 2001): the mesh's edges come to run along the creases instead of across them.
    bool alignCreases = true;
    /// Passes of rim splitting and fitting: some rim vertices (a plate's corners) are split only
    /// once the first pass has laid their faces on the plate's planes.
    int passes = 2;
};

/// The bounds vdb2mesh and the viewer give a vertex (SharpenOptions::maxMove, maxOutside,
/// maxInside), in voxels: a blurred corner of a cube lies ~1.4 voxels inside the image's
/// isosurface, the fins a thin plate's rim grows without the second bound 2-2.6 voxels beyond the
/// rim; see maxInside for the third.
inline constexpr double kSharpenMaxMoveVoxels = 2.5;
inline constexpr double kSharpenMaxOutsideVoxels = 1.5;
inline constexpr double kSharpenMaxInsideVoxels = 0.5;

/// The options vdb2mesh and the viewer sharpen with: the image (its isosurface `iso`, the object
/// brighter or darker) and the bounds above in its voxels.
SharpenOptions imageSharpenOptions(const ScalarImage& image, double iso, bool objectBrighter);

struct SharpenStats {
    std::size_t moved = 0;    ///< vertices that moved more than 1e-6 of the mean edge length
    std::size_t rimSplits = 0; ///< rim vertices split in two (see SharpenOptions::rimAngle)
    std::size_t creaseVertices = 0; ///< vertices added on creases (SharpenOptions::insertCreases)
    std::size_t creaseFlips = 0;    ///< edges flipped to run along creases (SharpenOptions::alignCreases)
    double largestMove = 0;   ///< world units
    std::size_t refused = 0;  ///< vertex moves undone because a face would flip or collapse
};

/// Moves the vertices of `mesh` (closed, oriented, triangles) onto the creases and corners its
/// faces imply; see the file comment. The topology is unchanged; the connectivity only where a thin
/// rim's vertices are split (SharpenOptions::rimAngle).
SharpenStats sharpenFeatures(Mesh& mesh, const SharpenOptions& options = {});

/// sharpenFeatures, kept only if it adds no crossing of the surface (vdb2mesh, the viewer): the
/// moves are small, a few voxels at most, but nothing checks them against the surface's other
/// sheets. The surface is searched for crossings only when something changed, and the one before
/// only when the sharpened one has some (on by default, sharpening would otherwise add two searches
/// of the whole surface to every run). Undone: `mesh` as it was, and the stats all zero.
SharpenStats sharpenFeaturesEmbedded(Mesh& mesh, const SharpenOptions& options = {});

} // namespace riemesh
