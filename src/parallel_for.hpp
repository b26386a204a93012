// Independent work items run on every core, each writing its own result slot, so that the outcome
// never depends on the threads. Internal: not part of the public API.
#pragma once

#include <cstddef>
#include <functional>

namespace gaitmon::detail {

/// The threads parallel_for uses for `count` items: one per core, at most `count`, at least 1.
std::size_t parallel_workers(std::size_t count);

/// Runs work(i, worker) for every i in [0, count) on parallel_workers(count) threads, the calling
/// thread being worker 0, so that a caller can keep scratch per worker. `on_done`, if set, is
/// called on the calling thread after each item it finishes, with the number that all threads
/// have finished. After an exception the items no thread has taken yet are not run; the first
/// exception is rethrown once every thread has stopped.
void parallel_for_workers(std::size_t count,
                          const std::function<void(std::size_t, std::size_t)>& work,
                          const std::function<void(std::size_t)>& on_done = {});

/// parallel_for_workers for work that needs no scratch of its own.
void parallel_for(std::size_t count, const std::function<void(std::size_t)>& work);

}  // namespace gaitmon::detail
