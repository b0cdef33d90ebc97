// vdb/apps/cli.h: what the command-line apps share: the bad-input error (exit code 1) and strict
// number parsing for flags (vdb2mesh, vdbphantom, bench/vdb_bench).
#pragma once

#include <cerrno>
#include <cmath>
#include <cstdlib>
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

} // namespace riemesh::apps
