// fuzz/bounded_new.cpp: global operator new/delete for the targets that hand bytes to OpenVDB.
//
// OpenVDB allocates whatever size a corrupt file states (e.g. bloscFromStream: new char[n] with n
// read from the file, found by fuzz_vdb_read). A real allocator refuses an impossible size with
// std::bad_alloc, which our reader catches and reports as a corrupt file; AddressSanitizer's
// operator new instead aborts the process ("allocation-size-too-big"). Here requests above
// kLimit throw std::bad_alloc as a real allocator would, so the fuzzer checks that our reader
// turns them into a clean error, and keeps fuzzing past them. Everything else goes to malloc,
// which ASan still checks. Every variant is defined, so none of ASan's is linked.
#include <cstddef>
#include <cstdlib>
#include <new>

namespace {

#ifndef RIEMESH_BOUNDED_NEW_MB
#define RIEMESH_BOUNDED_NEW_MB 1024 // libFuzzer's -malloc_limit_mb in scripts/fuzz
#endif
constexpr std::size_t kLimit = std::size_t(RIEMESH_BOUNDED_NEW_MB) << 20;

void* allocate(std::size_t size, std::size_t alignment, bool nothrow)
{
    void* p = nullptr;
    if (size <= kLimit) {
        if (alignment <= alignof(std::max_align_t)) p = std::malloc(size ? size : 1);
        else if (::posix_memalign(&p, alignment, size ? size : 1) != 0) p = nullptr;
    }
    if (!p && !nothrow) throw std::bad_alloc();
    return p;
}

} // namespace

void* operator new(std::size_t n) { return allocate(n, 0, false); }
void* operator new[](std::size_t n) { return allocate(n, 0, false); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return allocate(n, 0, true); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept { return allocate(n, 0, true); }
void* operator new(std::size_t n, std::align_val_t a) { return allocate(n, std::size_t(a), false); }
void* operator new[](std::size_t n, std::align_val_t a) { return allocate(n, std::size_t(a), false); }
void* operator new(std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept { return allocate(n, std::size_t(a), true); }
void* operator new[](std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept { return allocate(n, std::size_t(a), true); }

void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
