// detail/regularize.h: the regularity step's passes with the faces their edits made noted, none
// asked of the edit guard (the first half of enforceRegularity's check of the edits together, and
// what tests of that noting run). Private to core/src.
#pragma once

#include "riemesh/regularity.h"

#include "detail/intersection_guard.h"

namespace riemesh::detail {

/// The split, collapse and flip passes of enforceRegularity with `options`, none asked of the
/// guard; the faces the collapses and flips made or moved, and the splits of those, noted in
/// `made` (see MadeFaces). Every face of the mesh after is one of before, or has a corner in
/// made.vertices, or is one of made.flipped, or lies in a face of before (a half of a split
/// face no edit made). `kept`: the guard's grid, whose vertices the edits mark (kept up to date
/// later).
RegularityStats regularizeNotingEdits(Mesh& mesh, const MetricField& metric, const RegularityOptions& options,
                                      GuardGrid* kept, MadeFaces& made);

} // namespace riemesh::detail
