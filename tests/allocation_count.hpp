// Counts every allocation of a test program, so that a test can prove that a hot path allocates
// nothing. It replaces the global operator new and delete (keeping their behaviour otherwise),
// so it belongs in exactly one translation unit of a program.
#pragma once

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <new>

namespace gaitmon::test {
inline std::atomic<std::uint64_t> allocations{0};
}  // namespace gaitmon::test

[[gnu::noinline]] void* operator new(std::size_t size) {
  gaitmon::test::allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
[[gnu::noinline]] void operator delete(void* p) noexcept {
  std::free(p);
}
[[gnu::noinline]] void operator delete(void* p, std::size_t) noexcept {
  std::free(p);
}
