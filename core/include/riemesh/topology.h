// riemesh/topology.h: automated topology changes (paper 3.2, Fig. 3).
//
// merge (Fig. 3a): two colliding vertices u, w lose their one-rings and the two boundary loops are
// joined by a band of triangles: two components become one, or a handle appears. Euler
// characteristic -2.
// cutTunnel (Fig. 3b): a tunnel that got too thin shows as a triangle loop u-v-w of edges that
// bounds no face; the surface is cut along it and both sides capped: a handle disappears or a
// component splits in two. Euler characteristic +2.
// Every operation either succeeds and leaves the mesh closed, oriented and manifold, or returns
// false and leaves the mesh untouched. No garbage_collection() here.
#pragma once

#include "riemesh/mesh.h"

#include <vector>

namespace riemesh {

/// A pair of non-neighbour vertices closer than the collision radius (metric length).
struct CollisionPair {
    VertexHandle u, w;
    double distance = 0;
};

/// An edge (u, v) too short to keep whose endpoints share the outside neighbour w (Fig. 3b).
struct TunnelCandidate {
    VertexHandle u, v, w;
};

/// Name of an optional per-vertex int property: cutTunnel tags the vertices of both caps and the
/// two rings around them with one fresh id (> 0); findCollisions never pairs two vertices with the
/// same id, so the two sides of a cut are not merged back while they separate. 0 = untagged.
inline constexpr const char* kCutIdProperty = "riemesh:cut_id";

/// Name of an optional per-vertex char property: merge tags the band's vertices and the two rings
/// around them with kMergeZoneIterations. Near a fresh merge, the two sheets it joined are close
/// along the mesh (through the band) yet still approach each other elsewhere: findCollisions
/// judges pairs with a tagged vertex (> 0) by the stricter detour rule (see collision.h).
/// Evolution counts the tags down once per iteration, so a zone lasts that many iterations (a
/// lasting zone spreads with every merge it causes: a thin plate's rim then merged and cut 1,056
/// times instead of 67). 0 = untagged.
inline constexpr const char* kMergedProperty = "riemesh:merged";
inline constexpr int kMergeZoneIterations = 10;

/// True when merge(u, w) can run: both alive and distinct, not adjacent, closed one-rings
/// disjoint, valence >= 3 each, no edge already joins a neighbour of u to a neighbour of w, and
/// the two loops can be joined by a band that is embedded: its faces cross neither each other nor
/// the rest of the surface (exact tests; see self_intersection.h for what counts), nor come
/// closer than minSeparation (world units) to a face they share no vertex with.
bool canMerge(const Mesh& mesh, VertexHandle u, VertexHandle w, double minSeparation = 0);
/// Fig. 3a. Returns false (mesh untouched) when canMerge is false. Orientation is forced by the
/// boundary halfedges of the two loops; the band zips greedily along the shorter diagonal from a
/// starting pair of loop vertices: of all starting pairs, the embedded band with the shortest
/// cross edges in total. No vertex is moved.
bool merge(Mesh& mesh, VertexHandle u, VertexHandle w, double minSeparation = 0);

/// True when cutTunnel(u, v, w) can run: the three edges exist, (u, v, w) is not a face, and the
/// faces around u, v, w split into two sides (left of u->v->w and right of it) that the loop
/// separates, each loop vertex keeping >= 2 faces on each side. Refused as well: a side that closes
/// up with its cap alone (a pinched valence-3 vertex, not a tunnel), and a vertex off the loop
/// whose faces around the loop are not one contiguous arc of its fan.
bool canCutTunnel(const Mesh& mesh, VertexHandle u, VertexHandle v, VertexHandle w);
/// Fig. 3b. Returns false (mesh untouched) when canCutTunnel is false. The left side keeps u, v, w;
/// the right side gets copies (velocity and every other non-built-in vertex property copied).
/// Each loop vertex and each copy then moves a quarter of the way toward the centroid of its own
/// side's other neighbours, so the two caps are apart. Both caps and the two rings around them get
/// a fresh kCutIdProperty id. The caps are pulled less where they would cross a face or come closer
/// to one than minSeparation (world units); no cut where even a small pull would.
bool cutTunnel(Mesh& mesh, VertexHandle u, VertexHandle v, VertexHandle w, double minSeparation = 0);

struct TopologyStats {
    int merges = 0;   ///< Fig. 3a operations performed
    int cuts = 0;     ///< Fig. 3b operations performed
    int rejected = 0; ///< candidates skipped (already consumed by another edit, or unsafe)
    /// Collision pairs left unresolved (both vertices still alive): the caller holds them still
    /// (kHoldProperty in integration.h) so the two sheets cannot cross before a later merge.
    std::vector<CollisionPair> unresolved;
};

struct TopologyOptions {
    /// A merge candidate is skipped when, after the earlier edits of the same call, w has become
    /// reachable from u by an edge path at most this long (world units): the earlier merge already
    /// joined that region. <= 0: 3 x the mean length of the edges around u and w (roughly
    /// 2 x the collision radius for a regular mesh). Pass neighbourhoodFactor * collisionRadius
    /// for the exact value used by findCollisions.
    double neighbourhoodRadius = 0.0;
    /// Merge bands and cut caps keep at least this distance (world units) from the faces they
    /// share no vertex with (0: only no crossing); the intersection-free evolution sets it.
    double minSeparation = 0.0;
};

/// Applies cuts for the tunnel candidates, then merges for the collision pairs (closest first),
/// skipping candidates whose vertices an earlier edit of this call removed or touched (changed
/// one-ring), and merge candidates that an earlier merge made mesh neighbours (see
/// TopologyOptions). Never calls garbage_collection().
TopologyStats resolveTopology(Mesh& mesh, const std::vector<CollisionPair>& collisions,
                              const std::vector<TunnelCandidate>& tunnels, const TopologyOptions& options = {});

/// Deletes every component with fewer than `minVertices` vertices or enclosing less than
/// `minVolume` (world units cubed, either sign): the specks a deflating model leaves behind after
/// a cut, which have nothing to hold on to and would shrink into degenerate faces; and every
/// component whose orientation contradicts its nesting (ComponentShape::outward(): turned inside
/// out). A cavity's inner wall (negative volume inside a solid) is kept. Returns how many went.
/// `largestInverted` (if given): the most vertices of a component deleted only for being inside
/// out (0: none), which a tangled surface leaves (Evolution then starts again, see
/// EvolutionOptions::untangle). No garbage_collection().
int removeSmallComponents(Mesh& mesh, std::size_t minVertices, double minVolume, std::size_t* largestInverted = nullptr);

} // namespace riemesh
