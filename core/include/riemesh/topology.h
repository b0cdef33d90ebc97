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

bool canMerge(const Mesh& mesh, VertexHandle u, VertexHandle w);
/// Fig. 3a. Returns false (mesh untouched) when canMerge is false.
bool merge(Mesh& mesh, VertexHandle u, VertexHandle w);

bool canCutTunnel(const Mesh& mesh, VertexHandle u, VertexHandle v, VertexHandle w);
/// Fig. 3b. Returns false (mesh untouched) when canCutTunnel is false.
bool cutTunnel(Mesh& mesh, VertexHandle u, VertexHandle v, VertexHandle w);

struct TopologyStats {
    int merges = 0;   ///< Fig. 3a operations performed
    int cuts = 0;     ///< Fig. 3b operations performed
    int rejected = 0; ///< candidates skipped (already consumed by another edit, or unsafe)
};

/// Applies cuts for the tunnel candidates, then merges for the collision pairs (closest first),
/// skipping candidates whose vertices an earlier edit of this call removed or touched.
TopologyStats resolveTopology(Mesh& mesh, const std::vector<CollisionPair>& collisions,
                              const std::vector<TunnelCandidate>& tunnels);

} // namespace riemesh
