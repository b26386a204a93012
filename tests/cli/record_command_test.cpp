// `gaitmon record` end to end: `gaitmon fake-insole --pty` streams a session through a real
// pseudo-terminal, the serial driver and the decoder; the recording reads back as the same
// frames at the same times.
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <string>
#include <vector>

#include "gaitmon/session.hpp"
#include "lcm/bus_support.hpp"
#include "monitor_support.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;
using test::ChildProcess;
using Clock = std::chrono::steady_clock;

std::vector<Frame> read_all(const fs::path& path, SessionHeader* header = nullptr) {
  SessionReader reader(path);
  if (header != nullptr) *header = reader.header();
  std::vector<Frame> frames;
  Frame frame;
  while (reader.next(frame)) frames.push_back(frame);
  return frames;
}

TEST(RecordCommand, WritesWhatTheDeviceSentAsASessionFile) {
  const fs::path dir = test::scratch_dir("record");
  const fs::path session = test::cut_session(
      test::source_dir() / "replay" / "demo-simulated-37-38.csv", dir / "demo10.csv", 10.0);
  const fs::path out = dir / "recorded.csv";
  const std::string binary = test::gaitmon_binary().string();
  ChildProcess fake({binary, "fake-insole", session.string(), "--pty", "--speed", "max"});
  const auto pty = fake.read_line(ChildProcess::Stdout, Clock::now() + std::chrono::seconds(20));
  ASSERT_TRUE(pty.has_value()) << "fake-insole printed no pty";
  ChildProcess record(
      {binary, "--log-level", "warn", "record", "--out", out.string(), "--serial", *pty});
  // fake-insole ends once the reader has taken every byte.
  ASSERT_TRUE(fake.wait(Clock::now() + std::chrono::seconds(60)).has_value());
  EXPECT_FALSE(fs::exists(out)) << "the recording is complete only when it ends";
  record.signal(SIGINT);
  const auto status = record.wait(Clock::now() + std::chrono::seconds(10));
  ASSERT_TRUE(status.has_value()) << "gaitmon record still running 10 s after SIGINT";
  EXPECT_EQ(*status, 0);
  ASSERT_TRUE(fs::exists(out));
  EXPECT_FALSE(fs::exists(out.string() + ".partial"));

  SessionHeader original_header;
  SessionHeader recorded_header;
  const std::vector<Frame> original = read_all(session, &original_header);
  const std::vector<Frame> recorded = read_all(out, &recorded_header);
  EXPECT_EQ(recorded_header.insole_size, original_header.insole_size);
  EXPECT_EQ(recorded_header.sensors, original_header.sensors);
  EXPECT_EQ(recorded_header.sample_rate_hz, 100.0);
  ASSERT_EQ(recorded.size(), original.size());
  for (std::size_t i = 0; i < original.size(); ++i) {
    ASSERT_EQ(recorded[i].foot, original[i].foot) << "frame " << i;
    ASSERT_EQ(recorded[i].t_s, original[i].t_s) << "frame " << i;
    ASSERT_EQ(recorded[i].bits, original[i].bits) << "frame " << i;
  }
}

}  // namespace
}  // namespace gaitmon
