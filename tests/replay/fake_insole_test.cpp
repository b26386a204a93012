// `gaitmon fake-insole` end to end: the built program streams through a real pseudo-terminal,
// the serial driver and decoder read it, and every frame (or every injected fault) is
// accounted for against the session file.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "drivers/frame_decoder.hpp"
#include "drivers/serial_source.hpp"
#include "gaitmon/session.hpp"
#include "monitor_support.hpp"
#include "test_support.hpp"

namespace gaitmon::drivers {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// The fake device as a child process; the first line of its stdout is the pty's path.
class FakeInsole {
 public:
  explicit FakeInsole(const std::string& options) {
    const std::string command = test::gaitmon_binary().string() + " fake-insole " +
                                test::demo_session().string() + " --pty " + options;
    pipe_ = popen(command.c_str(), "r");
    if (pipe_ == nullptr) throw std::runtime_error("popen");
    std::array<char, 256> line{};
    if (std::fgets(line.data(), line.size(), pipe_) == nullptr) {
      throw std::runtime_error("fake-insole printed no path");
    }
    path_ = line.data();
    path_.erase(path_.find_last_not_of('\n') + 1);
  }
  ~FakeInsole() { finish(); }
  const std::string& path() const { return path_; }
  int finish() {
    if (pipe_ == nullptr) return status_;
    status_ = pclose(pipe_);
    pipe_ = nullptr;
    return status_;
  }

 private:
  FILE* pipe_ = nullptr;
  std::string path_;
  int status_ = -1;
};

// The serial driver and decoder on their own thread, as the monitor runs them.
class Receiver {
 public:
  explicit Receiver(const std::string& device) : source_(settings(device)) {
    thread_ = std::thread([this] {
      source_.run(
          [this](std::span<const std::uint8_t> bytes) {
            decoder_.feed(bytes, [this](const SensorFrame& frame) {
              std::lock_guard lock(mutex_);
              frames_.push_back(frame);
            });
          },
          [this](LinkState state, std::string_view) {
            if (state == LinkState::Disconnected) decoder_.reset();
            std::lock_guard lock(mutex_);
            states_.push_back(state);
            changed_.notify_all();
          });
    });
  }
  ~Receiver() { stop(); }

  // Waits for the n-th Disconnected (the fake's pty closing), then stops the driver.
  bool stop_after_disconnects(std::size_t n, std::chrono::seconds timeout) {
    std::unique_lock lock(mutex_);
    const bool seen = changed_.wait_for(lock, timeout, [&] {
      return static_cast<std::size_t>(
                 std::count(states_.begin(), states_.end(), LinkState::Disconnected)) >= n;
    });
    lock.unlock();
    stop();
    return seen;
  }
  void stop() {
    source_.stop();
    if (thread_.joinable()) thread_.join();
  }
  // After stop().
  const std::vector<SensorFrame>& frames() const { return frames_; }
  const std::vector<LinkState>& states() const { return states_; }
  DecoderCounters counters() const { return decoder_.counters(); }

 private:
  static SerialSettings settings(const std::string& device) {
    SerialSettings s;
    s.device = device;
    s.reconnect_initial_ms = 20;
    s.reconnect_max_ms = 100;
    return s;
  }
  SerialSource source_;
  FrameDecoder decoder_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<SensorFrame> frames_;
  std::vector<LinkState> states_;
  std::thread thread_;
};

nlohmann::json read_json(const fs::path& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

// Each decoded frame equals the file's frame with its foot and sequence number.
void expect_frames_match(const std::vector<SensorFrame>& got, const std::vector<Frame>& file) {
  std::array<std::vector<const Frame*>, 2> by_foot;
  for (const Frame& f : file) by_foot[static_cast<std::size_t>(f.foot)].push_back(&f);
  for (const SensorFrame& g : got) {
    const auto& list = by_foot[static_cast<std::size_t>(g.foot)];
    ASSERT_LT(g.sequence, list.size());
    const Frame& want = *list[g.sequence];
    ASSERT_EQ(g.device_time_us / 1e6, want.t_s);
    ASSERT_TRUE(std::equal(want.bits.begin(), want.bits.end(), g.bits.begin()));
  }
}

// Options that cannot work together or out of range are a command-line error (exit 2) naming the
// option, before anything is streamed.
TEST(FakeInsole, BadOptionsAreExitCodeTwoAndSayWhy) {
  struct Case {
    std::string args;
    std::string message;
  };
  for (const Case& c : {
           Case{"--reopen-after 1", "--reopen-after: needs --pty and --link"},
           Case{"--pty --reopen-after 1", "--reopen-after: needs --pty and --link"},
           Case{"--hold", "--link and --hold: need --pty"},
           Case{"--pty --reopen-after nan", "--reopen-after: 'nan' is not in [0, 86400]"},
           Case{"--speed 1e-12",
                "--speed: must be a number >= 0.001 (x real time) or max, got 1e-12"},
           Case{"--seed -1", "--seed: '-1' is not a whole number"},
           Case{"--garbage-rate nan", "--garbage-rate: 'nan' is not in [0, 1]"},
           Case{"--crc-rate 1.5", "--crc-rate: '1.5' is not in [0, 1]"},
           // Refused before the playback, not after it.
           Case{"--summary /proc/no-such/s.json",
                "--summary: the folder /proc/no-such does not exist"},
           Case{"--pty --link " + test::demo_session().string(),
                "--link: " + test::demo_session().string() + " exists and is not a symlink"},
           // Empty paths used to be taken for the options left out.
           Case{"--summary ''", "--summary: the path is empty"},
           Case{"--pty --link ''", "--link: the path is empty"},
       }) {
    SCOPED_TRACE(c.args);
    std::string out;
    EXPECT_EQ(test::run_command("timeout 30 " + test::gaitmon_binary().string() + " fake-insole " +
                                    test::demo_session().string() + " " + c.args,
                                &out),
              2)
        << out;
    EXPECT_NE(out.find(c.message), std::string::npos) << out;
  }
}

// A bad line late in the file used to be found after the frames before it were sent, as a
// device that streams half a recording and then stops.
TEST(FakeInsole, ABadLastLineIsFoundBeforeAnyFrameIsSent) {
  const fs::path dir = test::scratch_dir("fake-bad-line");
  const fs::path good = test::cut_session(test::demo_session(), dir / "good.csv", 5.0);
  std::ifstream in(good);
  std::string text;
  std::size_t lines = 0;
  for (std::string line; std::getline(in, line); ++lines) text += line + "\n";
  text += "99.0,L,not-a-number\n";
  const fs::path session = test::write_text(dir / "bad.csv", text);
  const fs::path wire = dir / "wire.bin";
  std::string out;
  // The wire goes to a file, the messages to `out`.
  EXPECT_EQ(test::run_command("(timeout 30 " + test::gaitmon_binary().string() + " fake-insole " +
                                  session.string() + " --speed max > " + wire.string() + ")",
                              &out),
            2)
      << out;
  EXPECT_NE(out.find("bad.csv:" + std::to_string(lines + 1)), std::string::npos) << out;
  EXPECT_EQ(fs::file_size(wire), 0u);
}

// Both read the session twice (checked whole, then played): a pipe gives its lines once.
TEST(FakeInsole, APipeForASessionIsRefusedWithTheReason) {
  const fs::path fifo = test::scratch_dir("fake-pipe") / "session.csv";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  for (const char* command : {"fake-insole", "replay"}) {
    SCOPED_TRACE(command);
    std::string out;
    EXPECT_EQ(test::run_command("timeout 30 " + test::gaitmon_binary().string() + " " + command +
                                    " " + fifo.string(),
                                &out),
              2)
        << out;
    EXPECT_NE(out.find("is not a regular file; this command reads a session twice"),
              std::string::npos)
        << out;
  }
}

TEST(FakeInsole, StreamsTheSessionThroughAPty) {
  const fs::path summary = test::scratch_dir("fake-plain") / "summary.json";
  FakeInsole fake("--speed max --summary " + summary.string());
  Receiver receiver(fake.path());
  ASSERT_TRUE(receiver.stop_after_disconnects(1, 60s));
  EXPECT_EQ(fake.finish(), 0);
  const std::vector<Frame> file = test::file_frames(test::demo_session());
  ASSERT_EQ(receiver.frames().size(), file.size());
  expect_frames_match(receiver.frames(), file);
  for (std::size_t i = 0; i < file.size(); ++i) ASSERT_EQ(receiver.frames()[i].foot, file[i].foot);
  const DecoderCounters c = receiver.counters();
  EXPECT_EQ(c.bytes, file.size() * 123);
  EXPECT_EQ(c.garbage_bytes, 0U);
  EXPECT_EQ(c.lost_frames_total(), 0U);
  const nlohmann::json s = read_json(summary);
  EXPECT_EQ(s["frames"], file.size());
  EXPECT_EQ(s["unread_bytes_at_exit"], 0);
}

TEST(FakeInsole, EveryInjectedFaultShowsUpInTheCounters) {
  const fs::path summary = test::scratch_dir("fake-faults") / "summary.json";
  FakeInsole fake(
      "--speed max --seed 5 --garbage-rate 0.05 --crc-rate 0.01 "
      "--truncate-rate 0.01 --summary " +
      summary.string());
  Receiver receiver(fake.path());
  ASSERT_TRUE(receiver.stop_after_disconnects(1, 60s));
  EXPECT_EQ(fake.finish(), 0);
  const nlohmann::json s = read_json(summary);
  const std::uint64_t crc = s["crc_corrupted"];
  const std::uint64_t truncated = s["truncated"];
  ASSERT_GT(crc, 50U);
  ASSERT_GT(truncated, 50U);
  ASSERT_GT(s["garbage_bursts"].get<int>(), 300);

  const DecoderCounters c = receiver.counters();
  EXPECT_EQ(c.crc_errors, crc);
  EXPECT_EQ(c.truncated_frames, truncated);
  EXPECT_EQ(c.header_errors, 0U);
  EXPECT_EQ(c.garbage_bytes, s["garbage_bytes"].get<std::uint64_t>() + 123 * (crc + truncated) -
                                 s["dropped_bytes"].get<std::uint64_t>());
  const std::vector<Frame> file = test::file_frames(test::demo_session());
  EXPECT_EQ(receiver.frames().size(), file.size() - crc - truncated);
  expect_frames_match(receiver.frames(), file);
  // Every frame not faulted arrived; every faulted one before a foot's last frame is lost.
  std::array<std::uint64_t, 2> last{};
  for (const SensorFrame& f : receiver.frames()) {
    last[static_cast<std::size_t>(f.foot)] = f.sequence;
  }
  for (std::size_t foot = 0; foot < 2; ++foot) {
    const std::vector<std::uint32_t> faulted = s["faulted_sequences"][foot == 0 ? "L" : "R"];
    const auto lost = std::count_if(faulted.begin(), faulted.end(),
                                    [&](std::uint32_t q) { return q < last[foot]; });
    EXPECT_EQ(c.lost_frames[foot], static_cast<std::uint64_t>(lost));
  }
}

TEST(FakeInsole, APtyClosedAndReopenedIsReconnectedThroughTheLink) {
  const fs::path dir = test::scratch_dir("fake-reopen");
  const fs::path link = dir / "insole";
  const fs::path summary = dir / "summary.json";
  // 60 s at x30: the pty closes after 0.7 s and is back 0.2 s later.
  FakeInsole fake("--speed 30 --link " + link.string() +
                  " --reopen-after 0.7 --reopen-gap-ms 200 --summary " + summary.string());
  Receiver receiver(link.string());
  ASSERT_TRUE(receiver.stop_after_disconnects(2, 60s));
  EXPECT_EQ(fake.finish(), 0);
  const nlohmann::json s = read_json(summary);
  EXPECT_EQ(s["reopens"], 1);
  ASSERT_EQ(s["paths"].size(), 2U);

  const std::vector<LinkState> want{LinkState::Connecting,   LinkState::Connected,
                                    LinkState::Disconnected, LinkState::Connecting,
                                    LinkState::Connected,    LinkState::Disconnected};
  // The transitions: a failed open while the link is gone repeats Connecting with its reason
  // (serial_source.hpp). After the last Disconnected the driver may already be trying again
  // before stop().
  std::vector<LinkState> changes;
  for (LinkState state : receiver.states()) {
    if (changes.empty() || changes.back() != state) changes.push_back(state);
  }
  ASSERT_GE(changes.size(), want.size());
  EXPECT_EQ(
      std::vector<LinkState>(changes.begin(), changes.begin() + static_cast<long>(want.size())),
      want);
  const std::vector<Frame> file = test::file_frames(test::demo_session());
  const DecoderCounters c = receiver.counters();
  // Bytes still in the old pty at the close are lost, as with an unplug; the sequence
  // numbers account for every one of those frames.
  EXPECT_EQ(receiver.frames().size() + c.lost_frames_total(), file.size());
  EXPECT_GT(receiver.frames().size(), file.size() / 2);
  expect_frames_match(receiver.frames(), file);
}

}  // namespace
}  // namespace gaitmon::drivers
