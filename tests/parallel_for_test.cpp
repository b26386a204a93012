// The batch work's thread loop: every item once, scratch per worker, progress on the caller's
// thread, and the first failure rethrown with the items not yet taken left alone.
#include "src/parallel_for.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <stdexcept>
#include <thread>
#include <vector>

namespace gaitmon::detail {
namespace {

TEST(ParallelFor, RunsEveryItemOnceWithAWorkerIndexBelowTheWorkerCount) {
  constexpr std::size_t kCount = 1000;
  std::vector<std::atomic<int>> runs(kCount);
  const std::size_t workers = parallel_workers(kCount);
  std::vector<int> per_worker(workers, 0);  // each slot written by its own worker only
  std::atomic<bool> worker_out_of_range{false};
  parallel_for_workers(kCount, [&](std::size_t i, std::size_t worker) {
    ++runs[i];
    if (worker >= workers) {
      worker_out_of_range = true;
      return;
    }
    ++per_worker[worker];
  });
  for (std::size_t i = 0; i < kCount; ++i) EXPECT_EQ(runs[i].load(), 1) << i;
  EXPECT_FALSE(worker_out_of_range.load());
  int total = 0;
  for (int n : per_worker) total += n;
  EXPECT_EQ(total, static_cast<int>(kCount));
}

TEST(ParallelFor, UsesNoMoreThreadsThanItemsOrCores) {
  EXPECT_EQ(parallel_workers(0), 1u);
  EXPECT_EQ(parallel_workers(1), 1u);
  EXPECT_LE(parallel_workers(1000), std::max(1u, std::thread::hardware_concurrency()));
  std::vector<int> ran;
  parallel_for(0, [&](std::size_t i) { ran.push_back(static_cast<int>(i)); });
  EXPECT_TRUE(ran.empty());
}

TEST(ParallelFor, ProgressComesOnTheCallingThreadAndNeverGoesBack) {
  constexpr std::size_t kCount = 200;
  const auto caller = std::this_thread::get_id();
  std::vector<std::size_t> progress;
  bool other_thread = false;
  // Items that take a while, so that the calling thread gets some (with empty ones another
  // worker may take them all before it starts, and it then reports nothing: seen under TSan).
  parallel_for_workers(
      kCount,
      [](std::size_t, std::size_t) { std::this_thread::sleep_for(std::chrono::microseconds(200)); },
      [&](std::size_t done) {
        other_thread = other_thread || std::this_thread::get_id() != caller;
        progress.push_back(done);
      });
  ASSERT_FALSE(progress.empty());
  EXPECT_FALSE(other_thread);
  EXPECT_TRUE(std::is_sorted(progress.begin(), progress.end()));
  EXPECT_LE(progress.back(), kCount);
  EXPECT_GE(progress.front(), 1u);
}

TEST(ParallelFor, TheFirstFailureIsRethrownAndTheRestAreNotStarted) {
  constexpr std::size_t kCount = 10000;  // 0.5 s of work per thread if nothing stopped it
  std::atomic<std::size_t> started{0};
  EXPECT_THROW(parallel_for(kCount,
                            [&](std::size_t i) {
                              ++started;
                              if (i == 10) throw std::runtime_error("item 10");
                              std::this_thread::sleep_for(std::chrono::microseconds(100));
                            }),
               std::runtime_error);
  // The other threads finish what they took while the failure was recorded, and take no more.
  EXPECT_LT(started.load(), 200u);
}

}  // namespace
}  // namespace gaitmon::detail
