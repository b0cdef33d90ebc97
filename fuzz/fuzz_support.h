// fuzz/fuzz_support.h: what the libFuzzer targets share.
//
// The contract every target checks: a reader given any bytes either returns a valid result or
// throws std::runtime_error (the one-line message the apps print). Anything else - another
// exception type, a crash, a sanitizer report, an allocation beyond libFuzzer's limit - is a
// finding. Readers that only take a path get the bytes through a file of this process.
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <fstream>
#include <stdexcept>
#include <string>
#include <typeinfo>

#include <unistd.h>

namespace riemesh::fuzz {

/// A file in /tmp (one per process and extension) holding `data`; its path.
inline std::string writeInput(const std::uint8_t* data, std::size_t size, const std::string& extension)
{
    const std::string path = "/tmp/riemesh-fuzz-" + std::to_string(::getpid()) + extension;
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), std::streamsize(size));
    out.close();
    if (!out) {
        std::fprintf(stderr, "fuzz: cannot write %s\n", path.c_str());
        std::abort();
    }
    return path;
}

/// Runs `read`; a std::runtime_error is the expected refusal, anything else aborts with its type.
template<typename F>
void expectCleanRefusal(F&& read)
{
    try {
        read();
    } catch (const std::runtime_error&) {
        // The reader refused the input with a message: fine.
    } catch (const std::exception& e) {
        std::fprintf(stderr, "fuzz: unexpected %s: %s\n", typeid(e).name(), e.what());
        std::abort();
    }
}

/// Aborts with `what` when `ok` is false (a property of an accepted input does not hold).
inline void require(bool ok, const std::string& what)
{
    if (ok) return;
    std::fprintf(stderr, "fuzz: property violated: %s\n", what.c_str());
    std::abort();
}

} // namespace riemesh::fuzz
