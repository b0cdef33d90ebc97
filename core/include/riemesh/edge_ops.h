// riemesh/edge_ops.h: the local edits of the regularity step (paper Fig. 1), as check-then-do pairs.
//
// The only place where regularity touches OpenMesh topology calls. None of these call
// garbage_collection(): deleted elements stay until the evolution compacts the mesh once per
// iteration, so handles held by the caller stay valid within an iteration.
#pragma once

#include "riemesh/mesh.h"

namespace riemesh {

/// True when edge e can be split (it exists and both sides are faces).
bool canSplit(const Mesh& mesh, EdgeHandle e);
/// Splits e at `position` (world space) into two edges and its two faces into four (Fig. 1b).
/// The new vertex's velocity is the mean of the endpoints'. Returns the new vertex.
VertexHandle split(Mesh& mesh, EdgeHandle e, const Vec3& position);

/// The vertex adjacent to both endpoints of h's edge that is not one of the two vertices opposite
/// the edge: collapsing that edge would pinch a tunnel (Fig. 3b). Invalid handle when none.
VertexHandle sharedOutsideNeighbour(const Mesh& mesh, HalfedgeHandle h);

/// True when collapsing h (from_vertex into to_vertex, which moves to `target`) keeps the mesh
/// closed, manifold and valid: the link condition holds, no tunnel (sharedOutsideNeighbour), the
/// two opposite vertices keep valence >= 3 (no valence-3 trap), the component is not a
/// tetrahedron, and no surviving face flips its normal or becomes degenerate.
bool canCollapse(const Mesh& mesh, HalfedgeHandle h, const Vec3& target);
/// Collapses h (Fig. 1c): from_vertex(h) is removed, to_vertex(h) is kept and moved to `target`;
/// its velocity becomes the mean of both. Returns the kept vertex.
VertexHandle collapse(Mesh& mesh, HalfedgeHandle h, const Vec3& target);

/// True when flipping e (Fig. 1a) keeps the mesh valid: both sides are faces, the new edge does
/// not exist yet, no vertex drops below valence 3, and neither new face is degenerate or folded.
bool canFlip(const Mesh& mesh, EdgeHandle e);
/// Flips e to join the two opposite vertices.
void flip(Mesh& mesh, EdgeHandle e);

} // namespace riemesh
