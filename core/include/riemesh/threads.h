// riemesh/threads.h: how many threads the core's parallel loops may use.
//
// Natively the core runs its per-vertex and per-edge loops (forces, integration, metric sampling,
// regularity measurements, collision candidates) on TBB; built without TBB (WebAssembly) they run
// on the calling thread. Either way the result is the same for any thread count, bit for bit: a
// parallel loop only writes its own elements' outputs, sums are taken in index order, and every
// mesh edit stays sequential. One job runs beside the iteration instead of in it when there are
// several threads: the intersection-free step's measurement of the clearances it renews
// (SafeStepCache in riemesh/ccd.h), which reads only what it noted before and is waited for
// before its results are used.
#pragma once

namespace riemesh {

/// Limits the core's parallel loops (and, natively, every TBB algorithm of the process) to
/// `threads` worker threads for the rest of the process, or until the next call; 0 lifts the
/// limit (all cores). Throws std::invalid_argument for a negative count.
void setThreadCount(int threads);

/// The number of threads a parallel loop may use now (1 without TBB).
int threadCount();

/// True when the core was built with TBB (else every loop runs on the calling thread).
bool isParallel();

} // namespace riemesh
