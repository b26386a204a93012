// Counts every allocation of a test program, so that a test can prove that a hot path allocates
// nothing, and makes a thread's next allocations fail when a test asks, so that it can show that
// memory running out is survived. It replaces the global operator new and delete (keeping their
// behaviour otherwise), so it belongs in exactly one translation unit of a program.
#pragma once

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <new>

namespace gaitmon::test {
inline std::atomic<std::uint64_t> allocations{0};
/// When not negative: how many of this thread's allocations succeed before one throws
/// std::bad_alloc (and the count goes back to -1).
inline thread_local int allocations_until_failure = -1;
}  // namespace gaitmon::test

[[gnu::noinline]] void* operator new(std::size_t size) {
  if (gaitmon::test::allocations_until_failure >= 0 &&
      gaitmon::test::allocations_until_failure-- == 0) {
    throw std::bad_alloc();
  }
  gaitmon::test::allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
// Replaced too, or its memory (std::stable_sort's buffer) would come from the sanitizer's own
// operator new and go back through the free() below.
[[gnu::noinline]] void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
  try {
    return ::operator new(size);
  } catch (const std::bad_alloc&) {
    return nullptr;
  }
}
[[gnu::noinline]] void operator delete(void* p) noexcept {
  std::free(p);
}
[[gnu::noinline]] void operator delete(void* p, std::size_t) noexcept {
  std::free(p);
}
