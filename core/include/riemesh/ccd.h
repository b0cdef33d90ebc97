// riemesh/ccd.h: intersection-free motion (issue 17): continuous collision detection of a step.
//
// A step moves every vertex along a straight line from its start to its end position. Two
// primitives that share no vertex (a vertex and a face, or two edges) may not come closer than a
// minimal separation eta during the step. The narrow phase is Additive CCD (Li, Kaufman and Jiang
// 2021, "Codimensional incremental potential contact", Algorithm 1): the primitives advance in time
// by steps bounded by their current distance over the largest relative speed, so they can never
// pass through each other between two evaluations; it is conservative (it may report a contact
// that a closer look would not) and never misses one. The response shortens the motion of the
// vertices of every pair found to a safe fraction, then checks again the pairs they belong to,
// until none collides (after a few rounds the vertices involved stop for this step: a motion of
// nothing crosses nothing).
#pragma once

#include "riemesh/mesh.h"

#include <array>
#include <cstddef>
#include <memory>
#include <vector>

namespace riemesh {

/// Squared distance from point p to the closed triangle (a, b, c) (world units^2). Degenerate
/// triangles are handled (the distance to their edges).
double pointTriangleDistanceSquared(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

/// Squared distance between the closed segments [p0, p1] and [q0, q1] (world units^2). Parallel
/// and degenerate segments are handled.
double segmentSegmentDistanceSquared(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1);

struct CcdResult {
    bool collides = false; ///< the distance may fall under eta (+ a fraction of the gap) during [0, 1]
    double toi = 1.0;      ///< when collides: a time in [0, 1) at which the pair is still apart
};

/// Additive CCD of point p moving linearly p0 -> p1 against the triangle (a, b, c) moving
/// a0 -> a1, ...: does their distance fall below `eta` + gapFraction (d0 - eta) during t in [0, 1]
/// (d0: the distance at t = 0)? When the primitives start closer than eta, eta is taken as 0.999 d0.
/// Conservative: a pair that comes within eta is always reported; when it is, toi is a time at
/// which the distance is still at least that gap (0 when the primitives start touching).
CcdResult pointTriangleCcd(const Vec3& p0, const Vec3& a0, const Vec3& b0, const Vec3& c0, const Vec3& p1,
                           const Vec3& a1, const Vec3& b1, const Vec3& c1, double eta, double gapFraction = 0.1);

/// The same for the segment [p, q] against the segment [r, s].
CcdResult edgeEdgeCcd(const Vec3& p0, const Vec3& q0, const Vec3& r0, const Vec3& s0, const Vec3& p1,
                      const Vec3& q1, const Vec3& r1, const Vec3& s1, double eta, double gapFraction = 0.1);

struct SafeStepOptions {
    double minSeparation = 1e-3; ///< eta (world units): the smallest distance the step may leave
    double gapFraction = 0.1;    ///< ACCD's s: a pair may close at most this much of its gap per round
    double shorten = 0.9;        ///< a colliding vertex moves this fraction of the safe time
    int shortenRounds = 4;       ///< rounds that shorten; later ones stop the vertices involved
    /// With a SafeStepCache (fractions of the faces' mean extent, see SafeStepCache): the radius
    /// up to which clearances are measured, and the motion in one step above which a vertex counts
    /// as moving far (when more than rebuildFraction / 2 of them do, the step is searched from
    /// scratch); and the fraction of the faces and edges out of their clearance at which the mesh
    /// is anchored again. Measured on the phantom (issue 17): clearance 0.2-0.5 and far motion
    /// 0.025-0.1 cost within 10% of these, rebuilding at 12% or 40% cost 25% more.
    double clearance = 0.3;
    double farMotion = 0.05;
    double rebuildFraction = 0.25;
    /// With a SafeStepCache: the fraction of the faces and edges anchored again one by one since
    /// the mesh was anchored (SafeStepCache: vertices come to rest out of their allowed drift) at
    /// which the whole mesh is anchored anew. Anchored anew, every vertex starts from a full allowed
    /// drift where it is: the vertices creeping at rest leave it later, and are not anchored and
    /// measured again one by one (a dozen grid queries each, about 25 us on the head MRI) until
    /// then. A rebuild pairs every element once (a fraction of a microsecond each), so anchoring
    /// anew once a tenth has been anchored one by one costs less than it saves. Measured (issue
    /// 17), guarded evolution, fastest of 7 alternating runs, 2 threads, at 0.5 (before) / 0.1 /
    /// 0.06 / 0.04: head MRI 0.623 / 0.600 / 0.593 / 0.594 s, phantom 100^3 0.213 / 0.208 / 0.210
    /// / 0.217 s; the same meshes. At 0.5 / 0.1, fastest of 2-4: torus 0.111 / 0.104 s,
    /// notched block 0.177 / 0.165 s, phantom 200^3 0.727 / 0.718 s, brain-extracted MRI
    /// (ch2bet, iso 40) 6.45 / 6.19 s, atlas (aal, iso 0.5) 0.936 / 0.924 s; ball, two spheres
    /// and thin plate within 2%.
    double reanchorFraction = 0.1;
    /// With a SafeStepCache: the cells of the grids of the anchored faces, edges and vertices (and
    /// of the primitives a step searches afresh against them), in multiples of the faces' mean
    /// extent. Their boxes are grown by half the clearance radius on each side: in cells of one
    /// extent, a face was entered in about 8 cells, and building the grids was half of a
    /// rebuild's work, a third of the cache's on the head MRI once the mesh is anchored anew more
    /// often (reanchorFraction). Measured (issue 17), one thread, instructions of the
    /// collision-safe steps at 1 / 1.5 / 2: head MRI (iso 40) 1,100.6 / 1,058.5 / 1,073.1 M,
    /// phantom 100^3 376.7 / 384.4 / 374.7 M, phantom 200^3 1,027.9 / 986.4 / 1,050.3 M, atlas
    /// (aal, iso 0.5) 1,996.4 / 1,895.7 / 1,910.4 M; guarded evolution, 2 threads, fastest of 6
    /// alternating runs: head 0.601 / 0.591 / 0.577 s. The same meshes (the boxes decide the
    /// pairs; the cells only where they are looked for).
    double anchoredCell = 1.5;
    /// The cells of the grids of a step searched from scratch, in multiples of the faces' mean
    /// extent. Measured (issue 17), one thread, instructions of the collision-safe steps at 1 /
    /// 1.25 / 1.5: head MRI 1,058.6 / 1,030.8 / 1,028.5 M, phantom 100^3 384.4 / 379.5 / 390.0 M;
    /// at 1 / 1.25: phantom 200^3 986.4 / 982.4 M, atlas (aal) 1,895.8 / 1,871.1 M. The same
    /// meshes.
    double scratchCell = 1.25;
    /// With a SafeStepCache: a vertex is anchored ahead of where it is, along its motion in the
    /// step that anchors it, as far as anchorAhead such motions and at most anchorAheadFraction of
    /// the largest allowed drift ((C - minSeparation) / 2): a vertex that keeps creeping the same
    /// way stays within its allowed drift longer (an anchor is the reference of a bound, not a
    /// position the mesh takes). A vertex whose anchor ahead turns out closer to another sheet
    /// than its allowed drift is anchored again where it is. Measured (issue 17), faces and
    /// edges searched afresh over the run: phantom 100^3 32,174 without -> 27,766, head MRI
    /// 46,985 -> 37,463; fractions 0.3 / 0.7 / 0.9: +3-5% / +1-5% / +9-27% searched; horizons
    /// 8 and 16 within 1.5%. Two spheres pressed together (ccd_test): anchored again 23 times in
    /// 80 steps (27 without).
    double anchorAhead = 4;
    double anchorAheadFraction = 0.5;
};

struct SafeStepStats {
    std::size_t candidates = 0; ///< vertex-face and edge-edge pairs within reach of each other
    std::size_t collisions = 0; ///< pairs found colliding (all rounds)
    std::size_t shortened = 0;  ///< vertices whose motion was shortened (or stopped)
    std::size_t stopped = 0;    ///< vertices that do not move this step at all
    int rounds = 0;
    bool rebuilt = false;   ///< with a cache: the mesh was anchored again at this step
    std::size_t dirty = 0;  ///< with a cache: faces and edges searched afresh (out of their skin, or new)
    std::size_t settled = 0; ///< with a cache: vertices anchored again at the end of the step (at rest)
};

/// The broad phase of the collision-safe step kept from step to step (Verlet lists, as in
/// molecular dynamics, with a skin of each vertex's own). At a rebuild the cache anchors every
/// vertex where it is and measures its clearance k: the smallest distance of the vertex-face and
/// edge-edge pairs (sharing no vertex) it belongs to, up to a radius C. While every vertex of a
/// primitive stays within (k - minSeparation) / 2 of its anchor (its own k) and its vertices are
/// the same, the primitive is "clean": two clean primitives stay farther apart than
/// minSeparation (their distance at the rebuild is at least either's k, and each has moved by at
/// most its vertices' largest drift), so their pairs need no test at all. The others (new faces
/// and edges of the edits, or out of their clearance) are searched afresh, against grids of the
/// anchored primitives and of each other. So the candidates are those of the search from scratch
/// less pairs that provably never come within minSeparation. The step stays collision-free, but
/// it may differ from the search from scratch's, whose conservative CCD may shorten such a pair.
/// At the end of a step, the vertices searched in it that have come to rest are anchored again
/// where they are, with their faces and edges as they are (their pairs measured again, and the
/// allowed drift of every corner of a pair closer than C lowered to match): a vertex that moved,
/// or whose faces an edit changed, is searched for a step or two instead of until the next
/// rebuild (phantom 100^3: faces and edges searched per step while the tube fills the cavity
/// 1,000-2,100 before, 450-650 now; at rest up to 2,100 before, 60-230 now). Their pairs are
/// measured beside the rest of the iteration, on another thread when the core's loops may use
/// more than one (the regularity step that follows is mostly sequential); the next step, and
/// every other use of the cache, waits for them first.
/// Deterministic for a given sequence of steps (the same for any thread count).
/// Call invalidate() when the mesh is renumbered (garbage collection, reordering) or replaced;
/// a mesh that lost elements is noticed and anchored again.
class SafeStepCache {
public:
    SafeStepCache();
    ~SafeStepCache();
    SafeStepCache(SafeStepCache&&) noexcept;
    SafeStepCache& operator=(SafeStepCache&&) noexcept;
    void invalidate();
    std::size_t rebuilds() const; ///< times the mesh was anchored (the first included)

    struct Impl;
    Impl& impl() { return *mImpl; } ///< (ccd.cpp's)

private:
    std::unique_ptr<Impl> mImpl;
};

/// The mesh holds the positions at the end of a step and `start` (indexed by vertex idx()) those
/// at its beginning. Moves back the vertices whose straight motion would bring a vertex and a
/// face, or two edges, sharing no vertex within options.minSeparation of each other (see above):
/// each ends at start + alpha (end - start) with alpha in [0, 1), and its velocity property (if
/// any) is scaled by alpha. If the start positions are embedded, so are the end positions.
/// Deterministic. Deleted elements are ignored.
/// With a cache, the candidate pairs come from it (see SafeStepCache): the step is as safe, and may
/// be shortened differently.
SafeStepStats limitStepToCollisionFree(Mesh& mesh, const std::vector<Vec3>& start, const SafeStepOptions& options = {},
                                       SafeStepCache* cache = nullptr);

/// The smallest distance between a corner of triangle a and triangle b (or a corner of b and a),
/// or an edge of a and an edge of b, over the pairs that share no vertex (ia, ib: the corners'
/// vertex indices); infinity when there is none (the same triangle). An edit that leaves new
/// faces at least some minimal separation from the rest keeps the next step's collision checks
/// out of round-off: a vertex left 1e-15 from a face is on either side of it after any motion.
double triangleSeparation(const std::array<int, 3>& ia, const std::array<Vec3, 3>& a, const std::array<int, 3>& ib,
                          const std::array<Vec3, 3>& b);

/// triangleSeparation(ia, a, ib, b) < r, without measuring the pairs whose boxes are farther
/// than r apart (the same answer, for a fraction of the work when r is small); false for r <= 0.
bool trianglesCloserThan(const std::array<int, 3>& ia, const std::array<Vec3, 3>& a, const std::array<int, 3>& ib,
                         const std::array<Vec3, 3>& b, double r);

/// True when one of the live `faces` of `mesh` meets another live face (of the list or not)
/// anywhere but where they share vertices (exact; the classification of findSelfIntersections),
/// or, with minSeparation > 0, comes closer to it than that (trianglesCloserThan).
/// O(faces of the mesh): for occasional edits (a tunnel cut); regularity uses a spatial grid.
bool facesMeetMesh(const Mesh& mesh, const std::vector<FaceHandle>& faces, double minSeparation = 0);

/// The smallest distance between a vertex and a face, or two edges, that share no vertex (world
/// units); `radius` when none is closer than that (only pairs within radius are measured).
double minimumSeparation(const Mesh& mesh, double radius);

} // namespace riemesh
