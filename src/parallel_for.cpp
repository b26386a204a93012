// The one thread pool loop of the batch work (step analyses, session fits, candidate grids).
#include "parallel_for.hpp"

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace gaitmon::detail {

std::size_t parallel_workers(std::size_t count) {
  const std::size_t cores = std::max(1u, std::thread::hardware_concurrency());
  return std::clamp<std::size_t>(count, 1, cores);
}

void parallel_for_workers(std::size_t count,
                          const std::function<void(std::size_t, std::size_t)>& work,
                          const std::function<void(std::size_t)>& on_done) {
  std::atomic<std::size_t> next{0};
  std::atomic<std::size_t> done{0};
  std::exception_ptr failure;
  std::mutex failure_mutex;
  const auto run = [&](std::size_t worker) {
    try {
      for (std::size_t i = next++; i < count; i = next++) {
        work(i, worker);
        const std::size_t finished = ++done;
        if (worker == 0 && on_done) on_done(finished);
      }
    } catch (...) {
      const std::lock_guard lock(failure_mutex);
      if (!failure) failure = std::current_exception();
      next = count;
    }
  };
  {
    std::vector<std::jthread> workers;
    for (std::size_t w = 1; w < parallel_workers(count); ++w) workers.emplace_back(run, w);
    run(0);
  }
  if (failure) std::rethrow_exception(failure);
}

void parallel_for(std::size_t count, const std::function<void(std::size_t)>& work) {
  parallel_for_workers(count, [&](std::size_t i, std::size_t) { work(i); });
}

}  // namespace gaitmon::detail
