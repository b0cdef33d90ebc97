// threads.cpp: the thread-count setting and the one place the core includes TBB.
#include "riemesh/threads.h"

#include "detail/parallel.h"

#include <memory>
#include <mutex>
#include <stdexcept>

#ifdef RIEMESH_CORE_TBB
#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>
#endif

namespace riemesh {

#ifdef RIEMESH_CORE_TBB
namespace {

std::mutex& limitMutex()
{
    static std::mutex m;
    return m;
}

/// The process-wide limit set by setThreadCount() (none: all cores).
std::unique_ptr<tbb::global_control>& limit()
{
    static std::unique_ptr<tbb::global_control> control;
    return control;
}

} // namespace
#endif

void setThreadCount(int threads)
{
    if (threads < 0) throw std::invalid_argument("setThreadCount: the thread count must be >= 0");
#ifdef RIEMESH_CORE_TBB
    std::lock_guard<std::mutex> lock(limitMutex());
    limit().reset(); // the old limit goes first: a new one can only lower an active limit
    if (threads > 0)
        limit() = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
#endif
}

int threadCount()
{
#ifdef RIEMESH_CORE_TBB
    return int(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
#else
    return 1;
#endif
}

bool isParallel()
{
#ifdef RIEMESH_CORE_TBB
    return true;
#else
    return false;
#endif
}

namespace detail {

void parallelForChunks(std::size_t begin, std::size_t end, std::size_t grain,
                       const std::function<void(std::size_t, std::size_t)>& fn)
{
    if (end <= begin) return;
    if (grain == 0) grain = 1;
#ifdef RIEMESH_CORE_TBB
    if (end - begin > grain && threadCount() > 1) {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(begin, end, grain),
                          [&fn](const tbb::blocked_range<std::size_t>& r) { fn(r.begin(), r.end()); });
        return;
    }
#endif
    fn(begin, end);
}

struct Background::Impl {
#ifdef RIEMESH_CORE_TBB
    tbb::task_group group;
#endif
    bool running = false;
};

Background::Background() : mImpl(std::make_unique<Impl>()) {}

Background::~Background()
{
    try {
        wait();
    } catch (...) { // (a job that threw, never waited for: nothing to report it to)
    }
}

bool Background::concurrent() const
{
#ifdef RIEMESH_CORE_TBB
    return threadCount() > 1;
#else
    return false;
#endif
}

void Background::run(std::function<void()> fn)
{
    wait();
#ifdef RIEMESH_CORE_TBB
    if (concurrent()) {
        mImpl->running = true;
        mImpl->group.run(std::move(fn));
        return;
    }
#endif
    fn();
}

void Background::wait()
{
    if (!mImpl->running) return;
    mImpl->running = false;
#ifdef RIEMESH_CORE_TBB
    mImpl->group.wait();
#endif
}

} // namespace detail

} // namespace riemesh
