// The lock-free ring of decoded frames between the driver thread and the detector thread.
//
// Contract: exactly one thread (the producer) calls try_push and push_wait, and exactly one
// thread (the consumer) calls try_pop and try_pop_batch; depth, drops, pushed, popped and
// capacity may be read from any thread.
//
// Speed: each call on the queue reads the index the other thread writes, so the consumer that
// takes frames in batches (try_pop_batch) moves that cache line between the cores once per batch
// instead of once per frame, and updates popped() once per batch.
//
// Overflow policy: try_push never waits; when the ring is full the frame is dropped and counted
// (drops()). push_wait is for replays, which must not skip frames: it waits for room instead
// (backpressure), and gives up only when its stop flag is set.
#pragma once

#include <algorithm>
#include <atomic>
#include <boost/lockfree/spsc_queue.hpp>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <thread>

#include "gaitmon/sensor_frame.hpp"

namespace gaitmon {

class FrameRing {
 public:
  /// Holds up to capacity_frames frames, allocated once here. Throws std::invalid_argument if
  /// capacity_frames is 0.
  explicit FrameRing(std::size_t capacity_frames)
      : capacity_(checked(capacity_frames)), queue_(capacity_frames) {}

  FrameRing(const FrameRing&) = delete;
  FrameRing& operator=(const FrameRing&) = delete;

  /// Producer. Appends the frame, or drops and counts it when the ring is full. Never waits.
  [[nodiscard]] bool try_push(const SensorFrame& frame) {
    if (queue_.push(frame)) {
      pushed_.store(pushed_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
      return true;
    }
    drops_.store(drops_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    return false;
  }

  /// Producer. Appends the frame, waiting (sleeping `poll` at a time) while the ring is full.
  /// Returns false, without appending or counting a drop, once `stop` is true.
  [[nodiscard]] bool push_wait(const SensorFrame& frame, const std::atomic<bool>& stop,
                               std::chrono::microseconds poll = std::chrono::microseconds(100)) {
    while (!queue_.push(frame)) {
      if (stop.load(std::memory_order_acquire)) return false;
      std::this_thread::sleep_for(poll);
    }
    pushed_.store(pushed_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    return true;
  }

  /// Consumer. Moves the oldest frame into `out`; false when the ring is empty.
  [[nodiscard]] bool try_pop(SensorFrame& out) {
    if (!queue_.pop(out)) return false;
    popped_.store(popped_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    return true;
  }

  /// Consumer. Moves the oldest frames, as many as are waiting up to out.size(), into the front
  /// of `out` in order, and returns how many (0 when the ring is empty). Their slots are free for
  /// the producer when it returns.
  [[nodiscard]] std::size_t try_pop_batch(std::span<SensorFrame> out) {
    const std::size_t n = queue_.pop(out.data(), out.size());
    if (n > 0) {
      popped_.store(popped_.load(std::memory_order_relaxed) + n, std::memory_order_relaxed);
    }
    return n;
  }

  std::size_t capacity() const { return capacity_; }
  /// Frames appended so far (not counting drops).
  std::uint64_t pushed() const { return pushed_.load(std::memory_order_relaxed); }
  /// Frames taken out so far.
  std::uint64_t popped() const { return popped_.load(std::memory_order_relaxed); }
  /// Frames dropped by try_push because the ring was full.
  std::uint64_t drops() const { return drops_.load(std::memory_order_relaxed); }
  /// Frames waiting now: a snapshot, exact when neither thread is inside a call, otherwise off
  /// by at most the calls in progress; never above capacity().
  std::size_t depth() const {
    // The counters are updated just after the queue itself, so popped may pass pushed for a
    // moment; clamp rather than wrap.
    const std::uint64_t out = popped();
    const std::uint64_t in = pushed();
    return in > out ? static_cast<std::size_t>(std::min<std::uint64_t>(in - out, capacity_)) : 0;
  }

 private:
  static std::size_t checked(std::size_t capacity_frames) {
    if (capacity_frames == 0) throw std::invalid_argument("FrameRing: capacity must be > 0");
    return capacity_frames;
  }

  // The counters live on their own cache lines so the producer's and the consumer's stores do
  // not invalidate each other's line (false sharing would halve the throughput).
  std::size_t capacity_;
  boost::lockfree::spsc_queue<SensorFrame> queue_;
  alignas(64) std::atomic<std::uint64_t> pushed_{0};
  std::atomic<std::uint64_t> drops_{0};
  alignas(64) std::atomic<std::uint64_t> popped_{0};
};

}  // namespace gaitmon
