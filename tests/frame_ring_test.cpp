// FrameRing: capacity, FIFO order, batch pops, exact drop counting, and two-thread stress (run
// under TSan).
#include "gaitmon/frame_ring.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <thread>
#include <vector>

namespace gaitmon {
namespace {

SensorFrame frame_with(std::uint32_t sequence) {
  SensorFrame f;
  f.sequence = sequence;
  f.sensor_count = 3;
  f.bits[0] = static_cast<std::uint8_t>(sequence & 0xFF);
  f.bits[2] = static_cast<std::uint8_t>((sequence >> 8) & 0xFF);
  return f;
}

TEST(FrameRing, RefusesZeroCapacity) {
  EXPECT_THROW(FrameRing(0), std::invalid_argument);
}

TEST(FrameRing, HoldsExactlyItsCapacityAndCountsEveryDrop) {
  FrameRing ring(4);
  EXPECT_EQ(ring.capacity(), 4u);
  for (std::uint32_t i = 0; i < 4; ++i) EXPECT_TRUE(ring.try_push(frame_with(i)));
  EXPECT_EQ(ring.depth(), 4u);
  EXPECT_FALSE(ring.try_push(frame_with(4)));
  EXPECT_FALSE(ring.try_push(frame_with(5)));
  EXPECT_EQ(ring.drops(), 2u);
  EXPECT_EQ(ring.pushed(), 4u);
  EXPECT_EQ(ring.depth(), 4u);

  SensorFrame out;
  for (std::uint32_t i = 0; i < 4; ++i) {
    ASSERT_TRUE(ring.try_pop(out));
    EXPECT_EQ(out.sequence, i);
    EXPECT_EQ(out.bits[0], i);
  }
  EXPECT_FALSE(ring.try_pop(out));
  EXPECT_EQ(ring.depth(), 0u);
  EXPECT_EQ(ring.popped(), 4u);
  // Room again after the consumer caught up; the drop count stays.
  EXPECT_TRUE(ring.try_push(frame_with(6)));
  EXPECT_EQ(ring.drops(), 2u);
  EXPECT_EQ(ring.depth(), 1u);
}

TEST(FrameRing, BatchPopTakesWhatIsWaitingUpToItsSize) {
  FrameRing ring(4);
  std::vector<SensorFrame> out(8);
  EXPECT_EQ(ring.try_pop_batch(out), 0u);
  EXPECT_EQ(ring.popped(), 0u);
  for (std::uint32_t i = 0; i < 3; ++i) ASSERT_TRUE(ring.try_push(frame_with(i)));
  ASSERT_EQ(ring.try_pop_batch(std::span(out).first(2)), 2u);
  EXPECT_EQ(out[0].sequence, 0u);
  EXPECT_EQ(out[1].sequence, 1u);
  EXPECT_EQ(ring.popped(), 2u);
  EXPECT_EQ(ring.depth(), 1u);
  // Four more: the ring's storage wraps in the middle of the next batch.
  for (std::uint32_t i = 3; i < 6; ++i) ASSERT_TRUE(ring.try_push(frame_with(i)));
  EXPECT_EQ(ring.depth(), 4u);
  ASSERT_EQ(ring.try_pop_batch(out), 4u);
  for (std::uint32_t i = 0; i < 4; ++i) {
    EXPECT_EQ(out[i].sequence, i + 2);
    EXPECT_EQ(out[i].bits[0], i + 2);
  }
  EXPECT_EQ(ring.try_pop_batch(out), 0u);
  EXPECT_EQ(ring.popped(), 6u);
  EXPECT_EQ(ring.pushed(), 6u);
  EXPECT_EQ(ring.depth(), 0u);
}

TEST(FrameRing, WaitingPushGivesUpOnlyWhenStopped) {
  FrameRing ring(1);
  std::atomic<bool> stop{true};
  ASSERT_TRUE(ring.push_wait(frame_with(0), stop));  // room: stop is not even looked at
  EXPECT_FALSE(ring.push_wait(frame_with(1), stop));
  EXPECT_EQ(ring.drops(), 0u);
  EXPECT_EQ(ring.pushed(), 1u);
}

TEST(FrameRing, WaitingPushResumesWhenTheConsumerMakesRoom) {
  FrameRing ring(1);
  std::atomic<bool> stop{false};
  std::atomic<bool> waiting{false};
  ASSERT_TRUE(ring.try_push(frame_with(0)));
  std::thread consumer([&] {
    // Room is made only after the producer is about to wait for it (and, 20 ms later, most
    // likely waiting), so that the push cannot simply find room.
    while (!waiting.load()) std::this_thread::yield();
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    EXPECT_EQ(ring.depth(), 1u) << "the waiting push went through a full ring";
    SensorFrame out;
    ASSERT_TRUE(ring.try_pop(out));
    EXPECT_EQ(out.sequence, 0u);
  });
  waiting.store(true);
  EXPECT_TRUE(ring.push_wait(frame_with(1), stop));
  consumer.join();
  SensorFrame out;
  ASSERT_TRUE(ring.try_pop(out));
  EXPECT_EQ(out.sequence, 1u);
}

// A fast producer against a slower consumer: what arrives is exactly what try_push accepted, in
// order, and the drop count equals the producer's own count of refusals.
TEST(FrameRing, TwoThreadStressKeepsOrderAndCountsDropsExactly) {
  constexpr std::uint32_t kFrames = 200000;
  FrameRing ring(64);
  std::vector<std::uint32_t> accepted;
  accepted.reserve(kFrames);
  std::atomic<bool> done{false};
  std::vector<std::uint32_t> received;
  received.reserve(kFrames);
  std::thread consumer([&] {
    SensorFrame out;
    std::uint32_t n = 0;
    for (;;) {
      if (ring.try_pop(out)) {
        received.push_back(out.sequence);
        EXPECT_EQ(out.bits[0], out.sequence & 0xFF);
        EXPECT_EQ(out.bits[2], (out.sequence >> 8) & 0xFF);
        // Slow down now and then so that the ring really fills.
        if (++n % 1024 == 0) std::this_thread::sleep_for(std::chrono::microseconds(200));
      } else if (done.load(std::memory_order_acquire)) {
        if (!ring.try_pop(out)) break;
        received.push_back(out.sequence);
      }
    }
  });
  std::uint64_t refused = 0;
  for (std::uint32_t i = 0; i < kFrames; ++i) {
    if (ring.try_push(frame_with(i))) {
      accepted.push_back(i);
    } else {
      ++refused;
    }
  }
  done.store(true, std::memory_order_release);
  consumer.join();
  EXPECT_GT(refused, 0u) << "the consumer never fell behind; the test did not exercise drops";
  EXPECT_EQ(ring.drops(), refused);
  EXPECT_EQ(ring.pushed() + ring.drops(), kFrames);
  EXPECT_EQ(ring.popped(), ring.pushed());
  EXPECT_EQ(received, accepted);
}

// The monitor's pattern: frames pushed one at a time, taken in batches of an odd size so that
// batches end at every place in the ring. Each frame must arrive exactly once, in order, whole.
TEST(FrameRing, TwoThreadBatchPopDeliversEveryFrameOnceInOrder) {
  constexpr std::uint32_t kFrames = 200000;
  FrameRing ring(256);
  std::atomic<bool> done{false};
  std::vector<std::uint32_t> received;
  received.reserve(kFrames);
  std::uint64_t damaged = 0;
  std::thread consumer([&] {
    std::vector<SensorFrame> out(37);
    for (;;) {
      // Read before popping: once the producer is done, an empty pop means the end.
      const bool finished = done.load(std::memory_order_acquire);
      const std::size_t n = ring.try_pop_batch(out);
      if (n == 0) {
        if (finished) break;
        std::this_thread::yield();
      }
      for (std::size_t i = 0; i < n; ++i) {
        received.push_back(out[i].sequence);
        damaged += out[i].bits[0] != (out[i].sequence & 0xFF) ||
                   out[i].bits[2] != ((out[i].sequence >> 8) & 0xFF);
      }
    }
  });
  // A refused push counts as a drop; here the producer offers the same frame again.
  for (std::uint32_t i = 0; i < kFrames; ++i) {
    while (!ring.try_push(frame_with(i))) std::this_thread::yield();
  }
  done.store(true, std::memory_order_release);
  consumer.join();
  EXPECT_EQ(damaged, 0u);
  EXPECT_EQ(ring.pushed(), kFrames);
  EXPECT_EQ(ring.popped(), kFrames);
  ASSERT_EQ(received.size(), kFrames);
  for (std::uint32_t i = 0; i < kFrames; ++i) ASSERT_EQ(received[i], i);
}

TEST(FrameRing, TwoThreadStressWithWaitingPushLosesNothing) {
  constexpr std::uint32_t kFrames = 200000;
  FrameRing ring(16);
  std::atomic<bool> stop{false};
  std::atomic<bool> done{false};
  std::vector<std::uint32_t> received;
  received.reserve(kFrames);
  std::thread consumer([&] {
    SensorFrame out;
    for (;;) {
      if (ring.try_pop(out)) {
        received.push_back(out.sequence);
      } else if (done.load(std::memory_order_acquire)) {
        if (!ring.try_pop(out)) break;
        received.push_back(out.sequence);
      }
    }
  });
  for (std::uint32_t i = 0; i < kFrames; ++i) {
    ASSERT_TRUE(ring.push_wait(frame_with(i), stop, std::chrono::microseconds(1)));
  }
  done.store(true, std::memory_order_release);
  consumer.join();
  EXPECT_EQ(ring.drops(), 0u);
  ASSERT_EQ(received.size(), kFrames);
  for (std::uint32_t i = 0; i < kFrames; ++i) ASSERT_EQ(received[i], i);
}

}  // namespace
}  // namespace gaitmon
