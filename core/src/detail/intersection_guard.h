// detail/intersection_guard.h: "does this edit make faces cross?" for the regularity step's
// collapses and flips (issue 17). A hashed grid of the faces' boxes (detail::CentreGrid: each
// face in the cell of its box's centre; built at the first question, kept up to date by update()
// after every edit) gives the faces near the triangles an edit would make; a separating plane
// (detail::separatedBeyondShared) settles most, exact triangle-triangle tests
// (detail/triangle_intersection.h, shared vertices classified as in findSelfIntersections) decide
// the others. Private to core/src.
#pragma once

#include "riemesh/mesh.h"

#include "detail/box_grid.h"

#include <array>
#include <atomic>
#include <vector>

namespace riemesh::detail {

/// What a regularity step's edits made without asking the guard (see
/// IntersectionGuard::facesAroundAreClear): the vertices all of whose faces an edit made or moved
/// (a collapse's kept vertex, the new vertex of a split of such a face), and the two faces each
/// flip made.
struct MadeFaces {
    std::vector<int> vertices;
    std::vector<std::array<int, 2>> flipped;
    void clear()
    {
        vertices.clear();
        flipped.clear();
    }
};

/// The guard's grid kept from one regularity step to the next (RegularityCache). Each vertex has
/// a reference position, each face is entered with the box of its corners' references grown by
/// a margin: while every corner stays within the margin of its reference (on each axis), the
/// face stays within that box. A step gives a vertex that has left its reference, or whose faces
/// an edit changed (kGuardEditedProperty), a new reference and enters its faces again: a pass
/// over the vertices instead of one over the faces and their boxes.
struct GuardGrid {
    /// Brought up to date on another thread (RegularityCache::bringUpToDate, from a copy of the
    /// mesh as the regularity step finds it): kPending until that thread begins, kRunning while
    /// it works, kReady after. The step's first guard (IntersectionGuard::build) takes it: if
    /// the other thread has not begun, it is called off (kNone: that thread does nothing, the
    /// guard brings the grid up to date itself, as without); else, once kReady, the guard enters
    /// only the faces around the vertices marked since (kGuardEditedProperty) and sets kNone.
    enum : int { kNone = 0, kPending = 1, kRunning = 2, kReady = 3 };
    std::atomic<int> beside{kNone};
    /// kNone after; true if it was brought up to date beside (waited for if under way), false if
    /// not (or called off before it began).
    bool takeBeside();
    CentreGrid grid;
    std::vector<Vec3> ref;   ///< by vertex index: its reference (NaN: none yet)
    double margin = 0;       ///< world units
    std::size_t vertices = 0; ///< live vertices when the grid was built
    std::size_t faces = 0;    ///< faces (deleted ones included) when it was last brought up to date
    bool valid = false;
    std::vector<char> moved;   ///< (scratch: by vertex index, to be given a new reference)
    std::vector<int> flagged;  ///< (scratch: those vertices)
    std::vector<unsigned> seen; ///< (scratch: by face index, the pass that entered it last)
    unsigned stamp = 0;
};

class IntersectionGuard {
public:
    /// minSeparation > 0: an edit is refused too when its new faces come closer than that (world
    /// units) to a face they share no vertex with (trianglesCloserThan, riemesh/ccd.h). With
    /// `kept`, the grid of the faces is kept there for the next guard (see GuardGrid), else built
    /// for this one.
    explicit IntersectionGuard(Mesh& mesh, double minSeparation = 0, GuardGrid* kept = nullptr)
        : mMesh(mesh), mMinSeparation(minSeparation), mKept(kept ? kept : &mOwn)
    {
    }

    /// Collapsing h (its from-vertex into its to-vertex, moved to `target`, world units) leaves
    /// no two faces crossing (given none crossed before).
    bool isCollapseSafe(HalfedgeHandle h, const Vec3& target);
    /// Flipping e leaves no two faces crossing.
    bool isFlipSafe(EdgeHandle e);
    /// After an edit that changed the faces around v (a split, a collapse kept v, a flip made v a
    /// corner of both new faces): enters them with their new boxes (v's reference renewed if it
    /// moved off it).
    void update(VertexHandle v);
    /// The grid (`kept`) made to hold every live face of the mesh, from its marks and the
    /// references (the work of the first question; public for RegularityCache::bringUpToDate).
    void bringUpToDate();
    /// After edits made without asking (see RegularityOptions::checkEditsTogether): the live faces
    /// around the vertices made.vertices and the live faces of made.flipped cross no face and come
    /// no closer than minSeparation to a face they share no vertex with (the tests of
    /// isCollapseSafe, each pair once), in parallel.
    bool facesAroundAreClear(const MadeFaces& made);

private:
    struct Triangle {
        std::array<int, 3> ids;
        std::array<Vec3, 3> p;
    };
    /// One search's buffers (a thread's own in facesAroundAreClear).
    struct Scratch {
        std::vector<Box6> boxes;
        std::vector<int> near;
    };
    void build();
    /// After the grid was brought up to date beside (GuardGrid::beside): the faces around the
    /// vertices the edits marked since entered again; false if it cannot tell (then build anew).
    bool enterMarked();
    /// The flagged vertices (GuardGrid::flagged) given their positions as references, their
    /// marks cleared, their faces entered again (each once).
    void enterFlagged(std::vector<char>& marked);
    /// Enters face f with the box of its corners' references, unless the box it has holds that.
    void enter(FaceHandle f);
    /// Gives v its position as reference if it is off its reference (or has none); true if so.
    bool renewReference(VertexHandle v);
    /// One of `made` (new triangles) meets another or a live face of the mesh, but for those
    /// skip(face index, its corners) leaves out.
    template <class Skip>
    bool crosses(const std::vector<Triangle>& made, Scratch& scratch, Skip&& skip) const;
    Box6 faceBox(FaceHandle f) const;
    Triangle triangle(FaceHandle f) const;

    Mesh& mMesh; ///< (written: the guard's edit marks it has seen are cleared)
    double mMinSeparation = 0;
    GuardGrid mOwn;
    GuardGrid* mKept;
    bool mBuilt = false;
    std::vector<Box6> mBoxes;    // scratch
    std::vector<Triangle> mMade; // scratch
    Scratch mScratch;
    std::vector<int> mOwner;      // (facesAroundAreClear's, by face index)
    std::vector<std::size_t> mStart; // (facesAroundAreClear's)
    std::vector<int> mOwned;         // (facesAroundAreClear's)
};

/// RegularityCache::handOver's work on the guard's grid `g`: the guard's marks of `mesh` copied to
/// `snapshot` (a copy of it; they stay in `mesh`: they are its next guard's to clear), g marked
/// kPending; false (nothing done) if `mesh` has no marks.
bool handOverMarks(Mesh& mesh, Mesh& snapshot, GuardGrid& g);
/// RegularityCache::bringUpToDate's: unless called off (see GuardGrid::beside), g brought up to
/// date from `snapshot`, then kReady (also if that throws: g is then invalid, built anew by the
/// guard that waits for it).
void bringUpToDateFrom(Mesh& snapshot, GuardGrid& g);

} // namespace riemesh::detail
