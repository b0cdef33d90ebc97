// vdb/src/isolated_read.h: a reader of untrusted files run in a forked, memory-limited child
// (issue 17). OpenVDB 10.0.1's reader corrupts memory on some hostile .vdb files (io::bloscFromStream
// reads a stored byte count's worth into a smaller buffer); here it can only kill a child process.
//
// The child runs the read, then writes the grid as a flat buffer (header, name, tiles, leaves) into a
// memfd and _exit()s. The parent waits for it, checks every count, alignment, coordinate and map
// parameter of the buffer, and builds the OpenVDB tree from the records itself. The child uses no
// TBB (a fork keeps none of the parent's worker threads), no atexit handler and no stdio buffer.
#pragma once

#include <openvdb/openvdb.h>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>

namespace riemesh::vdb::detail {

/// Runs `read` in a forked child whose address space may grow by `memoryLimitBytes` (setrlimit
/// RLIMIT_AS; RLIMIT_FSIZE bounds its answer the same) and that may use 4 processor seconds plus
/// one per MB of the file at `path` (RLIMIT_CPU: "ran past its N s time limit"). `read` returns a float or double grid with a
/// linear transform, or throws std::runtime_error (a refusal: its message is rethrown here) or
/// std::bad_alloc. Returns the grid as a FloatGrid with the same name, class, background and
/// transform, the same tiles and active voxels (double values rounded to float). A child that
/// crashes, runs out of its limit or answers a malformed buffer ends as std::runtime_error
/// "'path': corrupt or unreadable VDB file (the reader crashed: signal 6)" (or "ran out of the N MB
/// memory limit", ...).
openvdb::FloatGrid::Ptr readGridInChild(const std::string& path, std::uint64_t memoryLimitBytes,
                                        const std::function<openvdb::GridBase::ConstPtr()>& read);

/// The parent's half: the FloatGrid a child's answer of `size` bytes describes, every field checked
/// before use; std::runtime_error naming `path` for a refusal, a memory failure (naming
/// `memoryLimitBytes`) or a malformed buffer. Any bytes are safe to pass (fuzz/vdb_flat_fuzz.cpp).
openvdb::FloatGrid::Ptr gridFromChildAnswer(const void* bytes, std::size_t size, const std::string& path,
                                            std::uint64_t memoryLimitBytes);

/// The flat answer for `grid` (float or double, linear transform), as a child writes it; for tests
/// and the fuzzer's seeds.
std::string childAnswerOf(const openvdb::GridBase& grid);

} // namespace riemesh::vdb::detail
