// Reading untrusted files in a forked, memory-limited child (isolated_read.h).
#include "isolated_read.h"

#include <openvdb/math/Maps.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <thread>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <memory>
#include <new>
#include <stdexcept>
#include <type_traits>
#include <vector>

// Under the sanitizers (scripts/test-sanitize, scripts/fuzz) a report in the child must not run the
// parent's death callback (libFuzzer's writes a crash artifact for the parent's input).
extern "C" __attribute__((weak)) void __sanitizer_set_death_callback(void (*callback)(void));

namespace riemesh::vdb::detail {

namespace {

// ---- The flat answer: header, text (grid name or refusal), tiles, leaves; native byte order. ----

constexpr char kMagic[8] = {'r', 'i', 'e', 'm', 'f', 'l', 't', '1'};

enum Answer : std::uint32_t { kGrid = 1, kRefusal = 2, kOutOfMemory = 3 };

/// The index-to-world map's OpenVDB type, so that the parent builds the same one.
enum MapKind : std::uint32_t {
    kAffine = 0,
    kUniformScale = 1,
    kUniformScaleTranslate = 2,
    kScale = 3,
    kScaleTranslate = 4,
    kTranslation = 5,
};

struct Header {
    char magic[8];
    std::uint32_t answer;
    std::uint32_t gridClass;   ///< openvdb::GridClass
    std::uint64_t textBytes;   ///< grid name or refusal message, after the header, padded to 8
    std::uint64_t tileCount;   ///< Tile records after the text
    std::uint64_t leafCount;   ///< Leaf records after the tiles
    double matrix[16];         ///< index to world, OpenVDB's Mat4d (row vectors, translation in row 3)
    std::uint32_t mapKind;     ///< MapKind
    float background;
    /// A vdbphantom grid's "riemesh:phantom" and "riemesh:size" metadata (size 0: none), which
    /// the reference measure needs for the exact distance (level_set.h, phantomReferenceDistance).
    std::int32_t phantomSize;
    char phantomShape[28];     ///< NUL-terminated
};
struct Tile {
    std::int32_t origin[3];    ///< index space, aligned to the tile's span
    std::uint32_t level;       ///< 1, 2, 3: a tile of the lower internal node, upper one, root
    float value;
    std::uint32_t active;      ///< 0 or 1
};
using LeafT = openvdb::FloatTree::LeafNodeType;
struct Leaf {
    std::int32_t origin[3];    ///< index space, multiple of 8
    std::uint32_t reserved;    ///< 0
    std::uint64_t mask[8];     ///< active voxels, openvdb::util::NodeMask<3> words
    float values[LeafT::SIZE];
};
static_assert(sizeof(Header) == 208 && sizeof(Tile) == 24 && sizeof(Leaf) == 16 + 64 + 4 * 512);
static_assert(std::is_trivially_copyable_v<Header> && std::is_trivially_copyable_v<Leaf>);

constexpr std::uint64_t kMaxTextBytes = 4096;
/// Every coordinate of an accepted grid: box extents then fit an int32 (CoordBBox::dim()).
constexpr std::int64_t kMaxCoord = std::int64_t(1) << 29;
/// log2 of a tile's span at levels 1, 2, 3 (FloatTree: 5, 4, 3 bits per level).
constexpr int kTileLog2[4] = {0, 3, 7, 12};

constexpr std::uint64_t paddedTo8(std::uint64_t n) { return (n + 7) / 8 * 8; }

/// Appends to a sink in large blocks; the header goes to offset 0 last.
class AnswerWriter {
public:
    using Sink = std::function<void(std::uint64_t offset, const char* data, std::size_t size)>;
    explicit AnswerWriter(Sink sink) : mSink(std::move(sink)) { mBuffer.reserve(kBlock); }
    void put(const void* data, std::size_t size)
    {
        const char* p = static_cast<const char*>(data);
        mBuffer.insert(mBuffer.end(), p, p + size);
        if (mBuffer.size() >= kBlock) flush();
    }
    void flush()
    {
        if (mBuffer.empty()) return;
        mSink(mWritten, mBuffer.data(), mBuffer.size());
        mWritten += mBuffer.size();
        mBuffer.clear();
    }
    void finish(const Header& header)
    {
        flush();
        mSink(0, reinterpret_cast<const char*>(&header), sizeof header);
    }

private:
    static constexpr std::size_t kBlock = std::size_t(1) << 20;
    Sink mSink;
    std::vector<char> mBuffer;
    std::uint64_t mWritten = sizeof(Header); // the header's place is kept
};

Header emptyHeader(Answer answer)
{
    Header h;
    std::memset(&h, 0, sizeof h);
    std::memcpy(h.magic, kMagic, sizeof kMagic);
    h.answer = answer;
    return h;
}

void putText(AnswerWriter& out, Header& h, const std::string& text)
{
    const std::string t = text.substr(0, kMaxTextBytes);
    h.textBytes = t.size();
    out.put(t.data(), t.size());
    const char zeros[8] = {};
    out.put(zeros, paddedTo8(t.size()) - t.size());
}

MapKind mapKindOf(const openvdb::math::MapBase& map)
{
    namespace m = openvdb::math;
    if (map.isType<m::UniformScaleMap>()) return kUniformScale;
    if (map.isType<m::UniformScaleTranslateMap>()) return kUniformScaleTranslate;
    if (map.isType<m::ScaleMap>()) return kScale;
    if (map.isType<m::ScaleTranslateMap>()) return kScaleTranslate;
    if (map.isType<m::TranslationMap>()) return kTranslation;
    return kAffine;
}

/// Tiles, then leaves, of a float or double tree; serial (no TBB in the child).
template<typename TreeT>
void putTree(AnswerWriter& out, Header& h, const TreeT& tree)
{
    using ValueT = typename TreeT::ValueType;
    const ValueT background = tree.background();
    h.background = float(background);
    auto tile = tree.cbeginValueAll();
    tile.setMaxDepth(TreeT::DEPTH - 2); // root and internal nodes: no voxel
    for (; tile; ++tile) {
        // An inactive tile of the background value is what an absent node reads: leave it out.
        if (!tile.isValueOn() && *tile == background) continue;
        Tile t;
        const openvdb::Coord o = tile.getBoundingBox().min();
        t.origin[0] = o.x(), t.origin[1] = o.y(), t.origin[2] = o.z();
        t.level = tile.getLevel();
        t.value = float(*tile);
        t.active = tile.isValueOn() ? 1 : 0;
        out.put(&t, sizeof t);
        ++h.tileCount;
    }
    for (auto leaf = tree.cbeginLeaf(); leaf; ++leaf) {
        Leaf l;
        const openvdb::Coord o = leaf->origin();
        l.origin[0] = o.x(), l.origin[1] = o.y(), l.origin[2] = o.z();
        l.reserved = 0;
        const auto& mask = leaf->getValueMask();
        for (openvdb::Index w = 0; w < 8; ++w) l.mask[w] = mask.template getWord<std::uint64_t>(w);
        const ValueT* values = leaf->buffer().data();
        for (openvdb::Index i = 0; i < LeafT::SIZE; ++i) l.values[i] = float(values[i]);
        out.put(&l, sizeof l);
        ++h.leafCount;
    }
}

void putGrid(AnswerWriter& out, const openvdb::GridBase& grid)
{
    Header h = emptyHeader(kGrid);
    h.gridClass = std::uint32_t(grid.getGridClass());
    const auto& map = *grid.transform().baseMap();
    if (!map.isLinear()) throw std::logic_error("isolated read: a grid with a non-linear transform");
    h.mapKind = mapKindOf(map);
    const openvdb::Mat4d m = map.getAffineMap()->getMat4();
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) h.matrix[4 * i + j] = m(i, j);
    const auto shape = grid.getMetadata<openvdb::StringMetadata>("riemesh:phantom");
    const auto size = grid.getMetadata<openvdb::Int32Metadata>("riemesh:size");
    if (shape && size && size->value() > 0 && shape->value().size() < sizeof h.phantomShape) {
        h.phantomSize = size->value();
        std::memcpy(h.phantomShape, shape->value().c_str(), shape->value().size() + 1);
    }
    putText(out, h, grid.getName());
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid)) putTree(out, h, f->tree());
    else if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) putTree(out, h, d->tree());
    else throw std::logic_error("isolated read: a grid of " + grid.valueType() + " values");
    out.finish(h);
}

// ---- The parent's checks. ----

std::runtime_error fileError(const std::string& path, const std::string& what)
{
    return std::runtime_error("'" + path + "': " + what);
}

std::runtime_error unreadable(const std::string& path, const std::string& why)
{
    return fileError(path, "corrupt or unreadable VDB file (" + why + ")");
}

/// A text from the child as one line: control characters become spaces (UTF-8 file names stay).
std::string printable(const char* text, std::size_t size)
{
    std::string s(text, size);
    for (char& c : s)
        if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = ' ';
    return s;
}

std::string megabytes(std::uint64_t bytes) { return std::to_string((bytes + (1u << 19)) >> 20) + " MB"; }

bool isAligned(const std::int32_t origin[3], int log2)
{
    for (int a = 0; a < 3; ++a) {
        if (std::int64_t(origin[a]) < -kMaxCoord || std::int64_t(origin[a]) > kMaxCoord) return false;
        if ((std::int64_t(origin[a]) & ((std::int64_t(1) << log2) - 1)) != 0) return false;
    }
    return true;
}

openvdb::math::Transform::Ptr transformOf(const Header& h, const std::string& path)
{
    namespace m = openvdb::math;
    openvdb::Mat4d mat;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            const double v = h.matrix[4 * i + j];
            if (!std::isfinite(v)) throw unreadable(path, "a non-finite transform");
            mat(i, j) = v;
        }
    if (mat(0, 3) != 0 || mat(1, 3) != 0 || mat(2, 3) != 0 || mat(3, 3) != 1)
        throw unreadable(path, "a transform that is not affine");
    const double det = mat.getMat3().det();
    if (!std::isnormal(det)) throw unreadable(path, "a singular transform");
    const m::Vec3d scale(mat(0, 0), mat(1, 1), mat(2, 2)), translation = mat.getTranslation();
    const bool diagonal = mat(0, 1) == 0 && mat(0, 2) == 0 && mat(1, 0) == 0 && mat(1, 2) == 0 && mat(2, 0) == 0 &&
                          mat(2, 1) == 0;
    const bool uniform = diagonal && scale[0] == scale[1] && scale[0] == scale[2];
    const bool translated = translation != m::Vec3d(0);
    m::MapBase::Ptr map;
    m::Transform::Ptr transform;
    // (The Transform simplifies an affine map into a scale or a translation map, whose constructors
    // throw too: a translation of 5e120 made OpenVDB 10.0.1's ScaleTranslateMap throw its
    // ArithmeticError, which escaped as something other than a refusal.)
    try {
        switch (h.mapKind) {
        case kAffine: map = std::make_shared<m::AffineMap>(mat); break;
        case kUniformScale:
            if (uniform && !translated) map = std::make_shared<m::UniformScaleMap>(scale[0]);
            break;
        case kUniformScaleTranslate:
            if (uniform) map = std::make_shared<m::UniformScaleTranslateMap>(scale[0], translation);
            break;
        case kScale:
            if (diagonal && !translated) map = std::make_shared<m::ScaleMap>(scale);
            break;
        case kScaleTranslate:
            if (diagonal) map = std::make_shared<m::ScaleTranslateMap>(scale, translation);
            break;
        case kTranslation:
            if (diagonal && scale == m::Vec3d(1)) map = std::make_shared<m::TranslationMap>(translation);
            break;
        default: break;
        }
        if (map) transform = std::make_shared<m::Transform>(map);
    } catch (const std::exception& e) {
        throw unreadable(path, std::string("an invalid transform: ") + e.what());
    }
    if (!map) throw unreadable(path, "a transform whose type and matrix disagree");
    return transform;
}

// ---- The child. ----

/// The child's exit status when it cannot even write its answer.
constexpr int kExitNoAnswer = 70;

/// In the child: a flag in memory shared with the parent, set when an allocation has failed. Code
/// that does not expect a failed allocation may crash right after one (a segmentation fault where
/// OpenVDB unwinds, or where C code gets NULL from malloc): the parent then still reports the limit.
volatile std::uint32_t* gAllocationFailed = nullptr;

void onAllocationFailure()
{
    if (gAllocationFailed) *gAllocationFailed = 1;
    throw std::bad_alloc();
}

/// C code (Blosc) dereferences the NULL that malloc returns at the limit: a segmentation fault.
/// Its handler sets the flag when the address space is within `gLimitMargin` of its limit.
std::uint64_t gAddressLimit = 0, gLimitMargin = 0, gPageSize = 4096;

/// The mapped bytes from /proc/self/statm with async-signal-safe calls only; 0 when unknown.
std::uint64_t addressSpaceBytesInHandler()
{
    const int f = ::open("/proc/self/statm", O_RDONLY | O_CLOEXEC);
    if (f < 0) return 0;
    char text[64];
    const ssize_t n = ::read(f, text, sizeof text - 1);
    ::close(f);
    std::uint64_t pages = 0;
    for (ssize_t i = 0; i < n && text[i] >= '0' && text[i] <= '9'; ++i) pages = pages * 10 + std::uint64_t(text[i] - '0');
    return pages * gPageSize;
}

void onFault(int)
{
    // SA_RESETHAND: the faulting instruction runs again on return and ends the child by the signal.
    if (gAllocationFailed && gAddressLimit && addressSpaceBytesInHandler() + gLimitMargin >= gAddressLimit)
        *gAllocationFailed = 1;
}

void handleFaultsNearTheLimit()
{
    static char altStack[64 * 1024]; // a stack that cannot grow may be what failed
    stack_t st{};
    st.ss_sp = altStack;
    st.ss_size = sizeof altStack;
    if (::sigaltstack(&st, nullptr) != 0) return;
    struct sigaction sa {};
    sa.sa_handler = onFault;
    sa.sa_flags = SA_ONSTACK | SA_RESETHAND;
    sigemptyset(&sa.sa_mask);
    ::sigaction(SIGSEGV, &sa, nullptr);
    ::sigaction(SIGBUS, &sa, nullptr);
}

/// Bytes of address space mapped now (/proc/self/statm), 0 when unknown.
std::uint64_t addressSpaceBytes()
{
    std::FILE* f = std::fopen("/proc/self/statm", "r");
    if (!f) return 0;
    unsigned long long pages = 0;
    const int n = std::fscanf(f, "%llu", &pages);
    std::fclose(f);
    const long pageSize = ::sysconf(_SC_PAGE_SIZE);
    return n == 1 && pageSize > 0 ? std::uint64_t(pages) * std::uint64_t(pageSize) : 0;
}

/// Lowers the soft limit of `resource` to `bytes` (never above the hard limit); the limit set.
std::uint64_t lowerLimit(int resource, std::uint64_t bytes)
{
    rlimit r{};
    if (::getrlimit(resource, &r) != 0) return 0;
    rlim_t want = bytes >= std::uint64_t(RLIM_INFINITY) ? RLIM_INFINITY : rlim_t(bytes);
    if (r.rlim_max != RLIM_INFINITY) want = std::min(want, r.rlim_max);
    r.rlim_cur = want;
    return ::setrlimit(resource, &r) == 0 ? std::uint64_t(want) : 0;
}

void writeAll(int fd, std::uint64_t offset, const char* data, std::size_t size)
{
    while (size > 0) {
        const ssize_t n = ::pwrite(fd, data, size, off_t(offset));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) throw std::runtime_error("isolated read: cannot write the answer");
        data += n, size -= std::size_t(n), offset += std::uint64_t(n);
    }
}

/// A refusal or a memory failure: the whole answer, replacing anything written before.
void writeShortAnswer(int fd, Answer answer, const std::string& text)
{
    if (::ftruncate(fd, 0) != 0) throw std::runtime_error("isolated read: cannot reset the answer");
    AnswerWriter out([fd](std::uint64_t at, const char* p, std::size_t n) { writeAll(fd, at, p, n); });
    Header h = emptyHeader(answer);
    putText(out, h, text);
    out.finish(h);
}

/// A child asleep this long without using the processor is stuck (waitForChild).
constexpr double kStallSeconds = 2.0;

/// The processor seconds the child may use to read a file of `bytes`: OpenVDB 10.0.1 believes the
/// counts a file gives (a root node "with" 2^31 tiles reads past the end for minutes: fuzz_vdb_read
/// finding), and a legitimate file reads at hundreds of MB per second, so a few seconds and one
/// more per MB never stop a good file.
std::uint64_t readSecondsFor(std::uint64_t bytes) { return 4 + bytes / (std::uint64_t(1) << 20); }

[[noreturn]] void childMain(int fd, int errFd, volatile std::uint32_t* allocationFailed, const std::string& path,
                            std::uint64_t memoryLimit, std::uint64_t cpuSeconds,
                            const std::function<openvdb::GridBase::ConstPtr()>& read)
{
    gAllocationFailed = allocationFailed;
    std::set_new_handler(onAllocationFailure);
    // What the child says (glibc's "double free or corruption", a sanitizer's report) goes to the
    // parent's message, not to the user's terminal.
    (void)::dup2(errFd, STDERR_FILENO);
    // Die of what kills us, with no handler of the parent's (vdb2mesh's SIGINT flag, libFuzzer's
    // crash handler): the parent reads the signal from waitpid.
    for (int s : {SIGABRT, SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGALRM, SIGUSR1, SIGUSR2, SIGXFSZ, SIGXCPU, SIGPIPE})
        std::signal(s, SIG_DFL);
    if (__sanitizer_set_death_callback) __sanitizer_set_death_callback(nullptr);
    // The limit counts from what the parent had mapped (libraries, thread stacks, sanitizer shadow).
    if (const long pageSize = ::sysconf(_SC_PAGE_SIZE); pageSize > 0) gPageSize = std::uint64_t(pageSize);
    gLimitMargin = std::min<std::uint64_t>(memoryLimit / 4, std::uint64_t(64) << 20);
    gAddressLimit = lowerLimit(RLIMIT_AS, addressSpaceBytes() + memoryLimit);
    handleFaultsNearTheLimit();
    (void)lowerLimit(RLIMIT_FSIZE, memoryLimit);
    (void)lowerLimit(RLIMIT_CPU, cpuSeconds); // SIGXCPU (default: terminate) when it runs past
    // TBB is not fork-safe: the child inherits the parent's default arena as it was at the fork,
    // workers counted in it that do not exist here, and a parallel loop in it (OpenVDB frees a
    // tree's nodes with one) can wait for them forever (vdb_bench reading its image, then the
    // reference: about 1 run in 30 hung). Everything here runs in an arena of its own with no
    // worker slot, and the grid read is never freed (the process ends with it).
    int status = 0;
    tbb::task_arena serial(1);
    serial.execute([&] {
        try {
            try {
                static openvdb::GridBase::ConstPtr grid;
                grid = read();
                AnswerWriter out([fd](std::uint64_t at, const char* p, std::size_t n) { writeAll(fd, at, p, n); });
                putGrid(out, *grid);
            } catch (const std::bad_alloc&) {
                writeShortAnswer(fd, kOutOfMemory, {});
            } catch (const std::runtime_error& e) {
                writeShortAnswer(fd, kRefusal, e.what()); // our reader's message, naming the file
            } catch (const std::exception& e) {
                writeShortAnswer(fd, kRefusal, "'" + path + "': corrupt or unreadable VDB file (" + e.what() + ")");
            }
        } catch (...) {
            status = kExitNoAnswer;
        }
    });
    ::_exit(status); // no atexit handler, no flush of the parent's stdio buffers
}

/// The first line the child wrote to its stderr, printable and short ("" when silent).
std::string firstLineOf(int errFd)
{
    char text[512];
    const ssize_t n = ::pread(errFd, text, sizeof text, 0);
    if (n <= 0) return {};
    std::string line;
    for (ssize_t i = 0; i < n; ++i) {
        if (text[i] == '\n' && !line.empty()) break;
        if (text[i] != '\n') line += text[i];
    }
    line = printable(line.data(), line.size());
    if (line.size() > 160) line = line.substr(0, 160) + "...";
    return line;
}

/// The child's end, in words (after waitpid).
std::string describeChildEnd(int status, bool allocationFailed, std::uint64_t memoryLimit, std::uint64_t cpuSeconds,
                             const std::string& said)
{
    if (allocationFailed && (WIFSIGNALED(status) || WEXITSTATUS(status) != 0))
        return "ran out of the " + megabytes(memoryLimit) + " memory limit";
    const std::string saying = said.empty() ? "" : ": " + said;
    if (WIFSIGNALED(status)) {
        const int s = WTERMSIG(status);
        if (s == SIGXFSZ) return "ran out of the " + megabytes(memoryLimit) + " memory limit";
        if (s == SIGXCPU)
            return "the reader ran past its " + std::to_string(cpuSeconds) + " s time limit";
        if (s == SIGINT || s == SIGTERM || s == SIGHUP) return "the reader was interrupted: signal " + std::to_string(s);
        return "the reader crashed: signal " + std::to_string(s) + saying;
    }
    if (WIFEXITED(status)) return "the reader failed: exit status " + std::to_string(WEXITSTATUS(status)) + saying;
    return "the reader ended abnormally";
}

struct FdCloser {
    int fd;
    ~FdCloser() { ::close(fd); }
};

/// How the wait for a child ended.
enum class ChildEnd { Exited, Stalled, TimedOut };

/// A process's scheduling state (R, S, D, ...) and processor time so far (clock ticks), from
/// /proc/<pid>/stat; false if it cannot be read.
bool processProgress(pid_t pid, char& state, long long& ticks)
{
    char path[64];
    std::snprintf(path, sizeof path, "/proc/%d/stat", int(pid));
    std::FILE* f = std::fopen(path, "r");
    if (!f) return false;
    char text[1024];
    const std::size_t n = std::fread(text, 1, sizeof text - 1, f);
    std::fclose(f);
    text[n] = 0;
    const char* close = std::strrchr(text, ')'); // the command name may hold spaces and parentheses
    if (!close) return false;
    long long utime = 0, stime = 0;
    // state ppid pgrp session tty tpgid flags minflt cminflt majflt cmajflt utime stime
    if (std::sscanf(close + 1, " %c %*d %*d %*d %*d %*d %*u %*u %*u %*u %*u %lld %lld", &state, &utime, &stime) != 3) return false;
    ticks = utime + stime;
    return true;
}

/// Waits for the child `pid`. A child asleep that has used no processor time for stallSeconds is
/// stuck (TBB is not fork-safe: a lock one of the parent's worker threads held at the fork stays
/// held in the child forever; a fuzz_vdb_read run in CI waited on one) and one that runs past
/// wallSeconds is late: both are killed (SIGKILL) and reaped. `status` as from waitpid.
ChildEnd waitForChild(pid_t pid, int& status, double stallSeconds, double wallSeconds)
{
    using Clock = std::chrono::steady_clock;
    const auto start = Clock::now();
    auto lastProgress = start;
    long long lastTicks = -1;
    auto end = [&](ChildEnd how) {
        ::kill(pid, SIGKILL);
        while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {}
        return how;
    };
    for (int polls = 0;; ++polls) {
        const pid_t done = ::waitpid(pid, &status, WNOHANG);
        if (done == pid) return ChildEnd::Exited;
        if (done < 0 && errno != EINTR) throw std::runtime_error(std::string("waitpid: ") + std::strerror(errno));
        const auto now = Clock::now();
        char state = '?';
        long long ticks = 0;
        if (!processProgress(pid, state, ticks) || state == 'R' || state == 'D' || ticks != lastTicks) {
            lastProgress = now;
            lastTicks = ticks;
        } else if (std::chrono::duration<double>(now - lastProgress).count() > stallSeconds) {
            return end(ChildEnd::Stalled);
        }
        if (std::chrono::duration<double>(now - start).count() > wallSeconds) return end(ChildEnd::TimedOut);
        // Every millisecond at first (most reads take a few), then every 20.
        std::this_thread::sleep_for(std::chrono::milliseconds(polls < 200 ? 1 : 20));
    }
}

} // namespace

openvdb::FloatGrid::Ptr gridFromChildAnswer(const void* bytes, std::size_t size, const std::string& path,
                                            std::uint64_t memoryLimitBytes)
{
    const char* base = static_cast<const char*>(bytes);
    Header h;
    if (size < sizeof h) throw unreadable(path, "the reader's answer is truncated");
    std::memcpy(&h, base, sizeof h);
    if (std::memcmp(h.magic, kMagic, sizeof kMagic) != 0) throw unreadable(path, "the reader's answer is malformed");
    std::uint64_t at = sizeof h, left = size - sizeof h;
    if (h.textBytes > kMaxTextBytes || paddedTo8(h.textBytes) > left)
        throw unreadable(path, "the reader's answer has a malformed text");
    const std::string text = printable(base + at, std::size_t(h.textBytes));
    const std::string name(base + at, std::size_t(h.textBytes));
    at += paddedTo8(h.textBytes), left -= paddedTo8(h.textBytes);
    if (h.answer == kOutOfMemory) throw unreadable(path, "ran out of the " + megabytes(memoryLimitBytes) + " memory limit");
    if (h.answer == kRefusal) {
        if (text.empty()) throw unreadable(path, "the reader refused it without a reason");
        throw std::runtime_error(text);
    }
    if (h.answer != kGrid) throw unreadable(path, "the reader's answer is malformed");
    // Counts against the bytes there are, before any multiplication.
    if (h.tileCount > left / sizeof(Tile)) throw unreadable(path, "the reader's answer is truncated");
    const std::uint64_t tileBytes = h.tileCount * sizeof(Tile);
    if (h.leafCount > (left - tileBytes) / sizeof(Leaf) || tileBytes + h.leafCount * sizeof(Leaf) != left)
        throw unreadable(path, "the reader's answer has the wrong size");
    if (h.gridClass > std::uint32_t(openvdb::GRID_STAGGERED)) throw unreadable(path, "an unknown grid class");
    auto transform = transformOf(h, path);

    auto grid = openvdb::FloatGrid::create(h.background);
    grid->setName(name);
    if (h.phantomSize != 0) {
        const char* shape = h.phantomShape;
        const std::size_t length = strnlen(shape, sizeof h.phantomShape);
        const bool plain = length > 0 && length < sizeof h.phantomShape &&
                           std::all_of(shape, shape + length, [](char c) { return std::islower((unsigned char)c) || c == '-'; });
        if (h.phantomSize < 0 || !plain) throw unreadable(path, "the reader's answer has malformed phantom metadata");
        grid->insertMeta("riemesh:phantom", openvdb::StringMetadata(std::string(shape, length)));
        grid->insertMeta("riemesh:size", openvdb::Int32Metadata(h.phantomSize));
    }
    grid->setGridClass(openvdb::GridClass(h.gridClass));
    grid->setTransform(transform);
    auto& tree = grid->tree();
    for (std::uint64_t i = 0; i < h.tileCount; ++i, at += sizeof(Tile)) {
        Tile t;
        std::memcpy(&t, base + at, sizeof t);
        if (t.level < 1 || t.level > 3 || t.active > 1 || !isAligned(t.origin, kTileLog2[t.level]))
            throw unreadable(path, "a malformed tile");
        tree.addTile(t.level, openvdb::Coord(t.origin[0], t.origin[1], t.origin[2]), t.value, t.active != 0);
    }
    // Leaf nodes built in parallel (allocating them is most of the cost), then linked serially.
    std::vector<LeafT*> leaves(std::size_t(h.leafCount), nullptr);
    std::atomic<bool> malformed{false};
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size(), 64), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const char* record = base + at + i * sizeof(Leaf);
            std::int32_t origin[3];
            std::uint32_t reserved;
            std::memcpy(origin, record + offsetof(Leaf, origin), sizeof origin);
            std::memcpy(&reserved, record + offsetof(Leaf, reserved), sizeof reserved);
            if (reserved != 0 || !isAligned(origin, 3)) {
                malformed = true;
                return;
            }
            auto leaf = std::make_unique<LeafT>(openvdb::Coord(origin[0], origin[1], origin[2]), h.background);
            LeafT::NodeMaskType mask;
            for (openvdb::Index w = 0; w < 8; ++w)
                std::memcpy(&mask.template getWord<std::uint64_t>(w), record + offsetof(Leaf, mask) + 8 * w, 8);
            leaf->setValueMask(mask);
            std::memcpy(leaf->buffer().data(), record + offsetof(Leaf, values), sizeof(float) * LeafT::SIZE);
            leaves[i] = leaf.release();
        }
    });
    if (malformed) {
        for (LeafT* leaf : leaves) delete leaf;
        throw unreadable(path, "a malformed leaf node");
    }
    for (LeafT* leaf : leaves) tree.addLeaf(leaf);
    return grid;
}

std::string childAnswerOf(const openvdb::GridBase& grid)
{
    std::string answer;
    AnswerWriter out([&answer](std::uint64_t at, const char* p, std::size_t n) {
        if (answer.size() < at + n) answer.resize(at + n);
        std::memcpy(&answer[at], p, n);
    });
    putGrid(out, grid);
    return answer;
}

openvdb::FloatGrid::Ptr readGridInChild(const std::string& path, std::uint64_t memoryLimitBytes,
                                        const std::function<openvdb::GridBase::ConstPtr()>& read)
{
    const int fd = ::memfd_create("riemesh-isolated-read", MFD_CLOEXEC);
    if (fd < 0) throw fileError(path, std::string("cannot start the isolated reader: ") + std::strerror(errno));
    FdCloser closer{fd};
    const int errFd = ::memfd_create("riemesh-isolated-read-stderr", MFD_CLOEXEC);
    if (errFd < 0) throw fileError(path, std::string("cannot start the isolated reader: ") + std::strerror(errno));
    FdCloser errCloser{errFd};
    void* shared = ::mmap(nullptr, 4096, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    if (shared == MAP_FAILED) throw fileError(path, std::string("cannot start the isolated reader: ") + std::strerror(errno));
    std::unique_ptr<void, std::function<void(void*)>> unshare(shared, [](void* p) { ::munmap(p, 4096); });
    auto* allocationFailed = static_cast<volatile std::uint32_t*>(shared);
    *allocationFailed = 0;
    struct stat file {};
    const std::uint64_t cpuSeconds = readSecondsFor(::stat(path.c_str(), &file) == 0 ? std::uint64_t(file.st_size) : 0);
    // A child that stalls (see waitForChild) is started again, once: the fork race is rare.
    for (int attempt = 0;; ++attempt) {
        const pid_t pid = ::fork();
        if (pid < 0) throw fileError(path, std::string("cannot start the isolated reader: ") + std::strerror(errno));
        if (pid == 0) childMain(fd, errFd, allocationFailed, path, memoryLimitBytes, cpuSeconds, read);
        int status = 0;
        ChildEnd end = ChildEnd::Exited;
        try {
            end = waitForChild(pid, status, kStallSeconds, 2.0 * double(cpuSeconds) + 10.0);
        } catch (const std::exception& e) {
            throw fileError(path, std::string("lost the isolated reader: ") + e.what());
        }
        if (end == ChildEnd::Stalled && attempt == 0) {
            if (::ftruncate(fd, 0) != 0 || ::ftruncate(errFd, 0) != 0)
                throw fileError(path, "cannot restart the isolated reader");
            *allocationFailed = 0;
            continue;
        }
        if (end == ChildEnd::Stalled)
            throw unreadable(path, "the reader stalled twice: no progress for " + std::to_string(int(kStallSeconds)) + " s");
        if (end == ChildEnd::TimedOut)
            throw unreadable(path, "the reader ran past its " + std::to_string(2 * cpuSeconds + 10) + " s wall-clock limit");
        if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
            throw unreadable(path, describeChildEnd(status, *allocationFailed != 0, memoryLimitBytes, cpuSeconds,
                                                    firstLineOf(errFd)));
        break;
    }
    struct stat st {};
    if (::fstat(fd, &st) != 0 || st.st_size <= 0) throw unreadable(path, "the reader gave no answer");
    const std::size_t size = std::size_t(st.st_size);
    void* mapped = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE | MAP_POPULATE, fd, 0);
    if (mapped == MAP_FAILED) throw fileError(path, std::string("cannot map the reader's answer: ") + std::strerror(errno));
    std::unique_ptr<void, std::function<void(void*)>> unmap(mapped, [size](void* p) { ::munmap(p, size); });
    return gridFromChildAnswer(mapped, size, path, memoryLimitBytes);
}

} // namespace riemesh::vdb::detail
