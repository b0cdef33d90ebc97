// vdb/apps/cli.h: what the command-line apps share: the bad-input error (exit code 1) and strict
// number parsing for flags (vdb2mesh, vdbphantom, bench/vdb_bench).
#pragma once

#include <gnu/libc-version.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <string>

namespace riemesh::apps {

/// Bad input or parameters: reported as one line, exit code 1, before any long work.
struct BadInput : std::runtime_error {
    using std::runtime_error::runtime_error;
};

/// The whole of `text` as a finite number, or BadInput naming `flag`.
inline double parseNumber(const std::string& flag, const std::string& text)
{
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || *end != '\0' || errno == ERANGE || !std::isfinite(v))
        throw BadInput(flag + ": '" + text + "' is not a number");
    return v;
}

/// The whole of `text` as an integer >= `lo`, or BadInput naming `flag`.
inline int parseCount(const std::string& flag, const std::string& text, int lo)
{
    const double v = parseNumber(flag, text);
    if (v != std::floor(v) || v < lo || v > 1e9)
        throw BadInput(flag + ": '" + text + "' must be an integer >= " + std::to_string(lo));
    return int(v);
}

/// The glibc tunable that has malloc advise its memory for transparent huge pages.
inline constexpr const char* kHugePageTunable = "glibc.malloc.hugetlb=1";

/// Starts this program again (same process, arguments, descriptors) with malloc advising its memory
/// for transparent huge pages, where that helps: the kernel gives huge pages only to advised
/// memory ("madvise", the mode of this VM and of many distributions), and glibc (>= 2.35) advises
/// malloc's memory only when the tunable is set before the program starts. The volume stages
/// allocate hundreds of thousands of small OpenVDB nodes; at about 15 us per 4 KB page fault on
/// the 2-core VM the benchmarks run on, the phantom 400^3 took 9-11 s with 318k page faults, and
/// 6.8-7.3 s with 46k once malloc used huge pages (peak memory +0.3-2%); the head MRI 1.35-1.59 s
/// against 0.94-1.23 s. The second start costs about 0.1 s (loading the shared libraries).
/// Not done when RIEMESH_MALLOC_HUGEPAGES=0, when the tunable is already set (or the restart did
/// not take), under valgrind (the restarted program would run outside it), when glibc is older or
/// the kernel's mode is not "madvise"; on any failure the program simply goes on as it is.
inline void restartWithHugePageMalloc(char** argv)
{
    if (const char* off = std::getenv("RIEMESH_MALLOC_HUGEPAGES"); off && std::strcmp(off, "0") == 0) return;
    const char* tunables = std::getenv("GLIBC_TUNABLES");
    if (tunables && std::strstr(tunables, "glibc.malloc.hugetlb")) return;
    if (const char* preload = std::getenv("LD_PRELOAD"); preload && std::strstr(preload, "vgpreload")) return;
    int major = 0, minor = 0;
    if (std::sscanf(gnu_get_libc_version(), "%d.%d", &major, &minor) != 2 || major < 2 || (major == 2 && minor < 35)) return;
    std::string mode;
    std::getline(std::ifstream("/sys/kernel/mm/transparent_hugepage/enabled"), mode);
    if (mode.find("[madvise]") == std::string::npos) return;
    const std::string value = tunables && *tunables ? std::string(tunables) + ":" + kHugePageTunable : std::string(kHugePageTunable);
    if (::setenv("GLIBC_TUNABLES", value.c_str(), 1) != 0) return;
    std::fflush(nullptr);
    ::execv("/proc/self/exe", argv); // returns only on failure
}

} // namespace riemesh::apps
