// `gaitmon record` end to end: `gaitmon fake-insole --pty` streams a session through a real
// pseudo-terminal, the serial driver and the decoder; the recording reads back as the same
// frames at the same times. Frames the recording cannot hold are skipped and counted, a link
// that delivers nothing leaves no file, and a driver that throws ends the command with its error.
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <fstream>
#include <iterator>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "drivers/byte_source.hpp"
#include "drivers/wire_format.hpp"
#include "gaitmon/config.hpp"
#include "gaitmon/session.hpp"
#include "lcm/bus_support.hpp"
#include "live_support.hpp"
#include "log_capture.hpp"
#include "monitor_support.hpp"
#include "replay/pseudo_terminal.hpp"
#include "src/cli/commands.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;
using test::ChildProcess;
using Clock = std::chrono::steady_clock;

TEST(RecordCommand, WritesWhatTheDeviceSentAsASessionFile) {
  const fs::path dir = test::scratch_dir("record");
  const fs::path session = test::cut_session(test::demo_session(), dir / "demo10.csv", 10.0);
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

  const SessionHeader recorded_header = test::expect_recording_of(out, session);
  EXPECT_EQ(recorded_header.sample_rate_hz, 100.0);
}

/// What an insole sends: frames in the shipped wire format.
struct WireStream {
  /// Appends a frame to `stream`; its readings depend on the time.
  void add(Foot foot, InsoleSize size, std::uint16_t sensors, std::uint32_t time_us) {
    SensorFrame f;
    f.foot = foot;
    f.size = size;
    f.sensor_count = sensors;
    f.sequence = ++sequence[static_cast<std::size_t>(foot)];
    f.device_time_us = time_us;
    for (std::size_t i = 0; i < sensors; ++i) f.bits[i] = static_cast<std::uint8_t>(i + time_us);
    std::vector<std::uint8_t> bytes(4096);
    bytes.resize(drivers::encode_frame(format, f, bytes));
    stream.insert(stream.end(), bytes.begin(), bytes.end());
  }

  const Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  const drivers::WireFormat format{config.wire};
  std::vector<std::uint8_t> stream;
  std::array<std::uint32_t, 2> sequence{};
};

// `gaitmon record` on a fresh pseudo-terminal, started and connected.
struct RecordFromPty : WireStream {
  fs::path out;
  replay::PseudoTerminal pty;
  ChildProcess record;
  explicit RecordFromPty(const std::string& scratch)
      : out(test::scratch_dir(scratch) / "recorded.csv"),
        record({test::gaitmon_binary().string(), "record", "--out", out.string(), "--serial",
                pty.path()}) {}
  bool connected() {
    return !record
                .read_until(ChildProcess::Stderr, "link connected",
                            Clock::now() + std::chrono::seconds(20))
                .empty();
  }

  /// Sends `stream`, waits until the recorder has read it all, stops it with SIGINT and returns
  /// its exit status (nullopt if it did not end), its stdout and its log.
  std::optional<int> send_and_stop(std::string& text, std::string& log) {
    replay::write_all(pty.fd(), stream);
    if (pty.wait_drained(std::chrono::seconds(20)) != 0) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    record.signal(SIGINT);
    const auto status = record.wait(Clock::now() + std::chrono::seconds(10));
    for (const auto& l :
         record.read_rest(ChildProcess::Stdout, Clock::now() + std::chrono::seconds(5))) {
      text += l + "\n";
    }
    for (const auto& l :
         record.read_rest(ChildProcess::Stderr, Clock::now() + std::chrono::seconds(5))) {
      log += l + "\n";
    }
    return status;
  }
};

TEST(RecordCommand, SkipsAndCountsFramesOfAnotherInsoleAndRepeatedTimes) {
  RecordFromPty r("record-skips");
  ASSERT_TRUE(r.connected());

  for (std::uint32_t t : {0u, 10000u, 20000u}) {
    r.add(Foot::Left, InsoleSize::S37_38, 107, t);
    r.add(Foot::Right, InsoleSize::S37_38, 107, t);
  }
  r.add(Foot::Left, InsoleSize::S41_42, 129, 30000);  // another insole: skipped
  r.add(Foot::Left, InsoleSize::S37_38, 107, 20000);  // the left foot's last time again: skipped
  r.add(Foot::Left, InsoleSize::S37_38, 107, 30000);
  std::string text;
  std::string log;
  const std::optional<int> status = r.send_and_stop(text, log);
  ASSERT_TRUE(status.has_value());
  ASSERT_EQ(*status, 0) << text << log;
  EXPECT_NE(log.find("frame skipped: foot L: a 41-42 insole with 129 sensors in a 37-38 "
                     "recording"),
            std::string::npos)
      << log;
  // The second skip is counted; its warning is held back by the log's rate limit.
  EXPECT_NE(text.find("(7 frames); 2 skipped, 0 dropped (ring full)\nlink: 1129 bytes, 9 frames "
                      "decoded; 0 CRC errors, 0 truncated, 0 bad headers, 0 resyncs; 0 frames lost "
                      "(sequence gaps), 0 device restarts, 0 reconnects"),
            std::string::npos)
      << text;

  SessionHeader header;
  const std::vector<Frame> recorded = test::file_frames(r.out, &header);
  EXPECT_EQ(header.insole_size, InsoleSize::S37_38);
  EXPECT_EQ(header.sensors, 107u);
  ASSERT_EQ(recorded.size(), 7u);
  EXPECT_EQ(recorded.back().foot, Foot::Left);
  EXPECT_DOUBLE_EQ(recorded.back().t_s, 0.03);
  EXPECT_EQ(recorded.back().bits[1], static_cast<std::uint8_t>(1 + 30000));
}

// A device that restarts starts its clock over. The live monitor restarts the foot's
// segmentation there; the recording shows a gap, so that segment and analyze do too.
TEST(RecordCommand, ADeviceRestartIsRecordedAsAGap) {
  RecordFromPty r("record-restart");
  ASSERT_TRUE(r.connected());
  for (std::uint32_t t : {5000000u, 5010000u, 5020000u, 0u, 10000u}) {
    r.add(Foot::Left, InsoleSize::S37_38, 107, t);
  }
  std::string text;
  std::string log;
  const std::optional<int> status = r.send_and_stop(text, log);
  ASSERT_TRUE(status.has_value());
  ASSERT_EQ(*status, 0) << text << log;

  const std::vector<Frame> recorded = test::file_frames(r.out);
  ASSERT_EQ(recorded.size(), 5u);
  EXPECT_DOUBLE_EQ(recorded[2].t_s, 5.02);
  // At least max_gap_s and a period after the last frame before it (more if the host saw more
  // time pass), then on at the device's pace.
  const double gap = recorded[3].t_s - recorded[2].t_s;
  EXPECT_GT(gap, r.config.segmentation.max_gap_s) << log;
  EXPECT_GE(gap, r.config.segmentation.max_gap_s + 0.01 - 1e-9);
  EXPECT_LT(gap, 5.0) << "the host saw the restart's frames come within a second";
  EXPECT_NEAR(recorded[4].t_s - recorded[3].t_s, 0.01, 1e-9);
  EXPECT_EQ(recorded[4].bits[1], static_cast<std::uint8_t>(1 + 10000));
}

// The header's rate is the config's (100 Hz): a device at 50 Hz is recorded, and said loudly,
// while one at the config's rate (with a lost frame, which the median ignores) is not.
TEST(RecordCommand, ADeviceAtAnotherRateThanTheConfigsIsWarnedOf) {
  for (const std::uint32_t spacing_us : {20000u, 10000u}) {
    SCOPED_TRACE(spacing_us);
    RecordFromPty r("record-rate-" + std::to_string(spacing_us));
    ASSERT_TRUE(r.connected());
    for (std::uint32_t i = 0; i < 12; ++i) {
      if (i == 5) continue;
      r.add(Foot::Left, InsoleSize::S37_38, 107, i * spacing_us);
      r.add(Foot::Right, InsoleSize::S37_38, 107, i * spacing_us);
    }
    std::string text;
    std::string log;
    const std::optional<int> status = r.send_and_stop(text, log);
    ASSERT_TRUE(status.has_value());
    ASSERT_EQ(*status, 0) << text << log;
    const std::string warning = "record: the device's clock shows 50.0 Hz per foot, but " +
                                r.out.string() + " says sample_rate_hz 100 (the config's, ";
    if (spacing_us == 20000u) {
      EXPECT_NE(log.find(warning), std::string::npos) << log;
    } else {
      EXPECT_EQ(log.find("the device's clock shows"), std::string::npos) << log;
    }
    EXPECT_EQ(test::file_frames(r.out).size(), 22u);
  }
}

TEST(RecordCommand, ALinkThatDeliversNothingIsAnErrorAndLeavesNoFile) {
  RecordFromPty r("record-nothing");
  ASSERT_TRUE(r.connected());
  r.record.signal(SIGTERM);
  const auto status = r.record.wait(Clock::now() + std::chrono::seconds(10));
  ASSERT_TRUE(status.has_value());
  EXPECT_EQ(*status, 1);
  const std::string err = r.record.stderr_text(Clock::now() + std::chrono::seconds(5));
  EXPECT_NE(
      err.find("gaitmon: error: no frame was received from " + r.pty.path() + "; nothing written"),
      std::string::npos)
      << err;
  EXPECT_FALSE(fs::exists(r.out));
  EXPECT_FALSE(fs::exists(r.out.string() + ".partial"));
}

// An --out that cannot take the session's name is refused before the device is opened, not after
// the whole recording (the device here does not exist: the check must come first).
TEST(RecordCommand, AnOutputThatIsAFolderIsAUsageErrorBeforeRecording) {
  const fs::path dir = test::scratch_dir("record-out-folder");
  fs::create_directories(dir / "taken");
  std::string output;
  const int status =
      test::run_command("timeout 30 " + test::gaitmon_binary().string() + " record --serial " +
                            (dir / "no-such-tty").string() + " --out " + (dir / "taken").string(),
                        &output);
  EXPECT_EQ(status, 2) << output;
  EXPECT_NE(output.find("--out: " + (dir / "taken").string() + " is a directory"),
            std::string::npos)
      << output;
  EXPECT_FALSE(fs::exists(dir / "taken.partial"));
}

// A driver that fails: it connects, delivers `bytes` and throws.
class FailingSource final : public drivers::ByteSource {
 public:
  explicit FailingSource(std::vector<std::uint8_t> bytes) : bytes_(std::move(bytes)) {}
  void run(const BytesHandler& on_bytes, const StateHandler& on_state) override {
    on_state(drivers::LinkState::Connecting, "fake");
    on_state(drivers::LinkState::Connected, "fake");
    on_bytes(bytes_);
    throw std::runtime_error("fake: the driver failed");
  }
  void stop() override {}

 private:
  std::vector<std::uint8_t> bytes_;
};

// No real driver fails at will, so the command runs in this process on a source that does: a
// writer thread left joinable by the throw would end the test program (std::terminate).
TEST(RecordCommand, ADriverThatThrowsIsAnErrorAndLeavesNoFinishedFile) {
  const fs::path out = test::scratch_dir("record-throws") / "recorded.csv";
  WireStream device;
  for (std::uint32_t t : {0u, 10000u, 20000u}) {
    device.add(Foot::Left, InsoleSize::S37_38, 107, t);
    device.add(Foot::Right, InsoleSize::S37_38, 107, t);
  }
  CLI::App app;
  cli::GlobalOptions global;
  global.config_path = test::source_dir() / "config" / "gaitmon.toml";
  global.log_level = "warn";
  cli::add_record_command(app, global, [&](const Config&, bool) {
    return std::make_unique<FailingSource>(device.stream);
  });
  const std::string out_arg = out.string();
  const std::array<const char*, 6> argv{"gaitmon",       "record",   "--out",
                                        out_arg.c_str(), "--serial", "fake"};
  try {
    app.parse(static_cast<int>(argv.size()), argv.data());
    ADD_FAILURE() << "record ended normally after its driver threw";
  } catch (const std::runtime_error& e) {
    // main() prints it as "gaitmon: error: ..." and exits 1.
    EXPECT_STREQ(e.what(), "fake: the driver failed");
  }

  // The README's promise: a failed run leaves no file that looks finished; and nothing recorded
  // is lost: the frames delivered before the failure are kept, all of them, under the partial
  // name.
  EXPECT_FALSE(fs::exists(out));
  const fs::path partial = out.string() + ".partial";
  ASSERT_TRUE(fs::exists(partial));
  const std::vector<Frame> recorded = test::file_frames(partial);
  ASSERT_EQ(recorded.size(), 6u);
  EXPECT_EQ(recorded.back().foot, Foot::Right);
  EXPECT_DOUBLE_EQ(recorded.back().t_s, 0.02);
  EXPECT_EQ(recorded.back().bits[1], static_cast<std::uint8_t>(1 + 20000));
}

// A driver that delivers `frames` frames of each foot in pieces, and ends when it has or when
// it is stopped.
class StreamingSource final : public drivers::ByteSource {
 public:
  explicit StreamingSource(std::uint32_t frames) {
    WireStream device;
    for (std::uint32_t k = 0; k < frames; ++k) {
      device.add(Foot::Left, InsoleSize::S37_38, 107, k * 10000);
      device.add(Foot::Right, InsoleSize::S37_38, 107, k * 10000);
    }
    const std::size_t piece_bytes = 200 * device.format.frame_bytes(107);
    for (std::size_t at = 0; at < device.stream.size(); at += piece_bytes) {
      const auto from = device.stream.begin() + static_cast<std::ptrdiff_t>(at);
      pieces_.emplace_back(from, from + static_cast<std::ptrdiff_t>(
                                            std::min(piece_bytes, device.stream.size() - at)));
    }
  }
  void run(const BytesHandler& on_bytes, const StateHandler& on_state) override {
    on_state(drivers::LinkState::Connecting, "fake");
    on_state(drivers::LinkState::Connected, "fake");
    for (const auto& piece : pieces_) {
      if (stopped_.load()) break;
      on_bytes(piece);
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    on_state(drivers::LinkState::Disconnected, "fake: stopped");
  }
  void stop() override { stopped_.store(true); }

 private:
  std::vector<std::vector<std::uint8_t>> pieces_;
  std::atomic<bool> stopped_{false};
};

// `gaitmon record --out OUT` in this process on `source`, with the config `config`; the error
// it ended with ("" if none) and its log.
std::string record_in_process(const fs::path& config, const fs::path& out,
                              std::unique_ptr<drivers::ByteSource> source, std::string& log) {
  CLI::App app;
  cli::GlobalOptions global;
  global.config_path = config;
  global.log_level = "warn";
  cli::add_record_command(app, global, [&](const Config&, bool) { return std::move(source); });
  const std::string out_arg = out.string();
  const std::array<const char*, 6> argv{"gaitmon",       "record",   "--out",
                                        out_arg.c_str(), "--serial", "fake"};
  std::string error;
  const test::LogCapture capture;
  try {
    app.parse(static_cast<int>(argv.size()), argv.data());
  } catch (const std::exception& e) {
    error = e.what();
  }
  log = capture.text.str();
  return error;
}

// The writer fails (a full disk: the partial file is /dev/full) after the first megabyte of
// rows: what reached the file is kept, under the partial name, which the log names.
TEST(RecordCommand, AWriterThatFailsKeepsThePartialFile) {
  const fs::path dir = test::scratch_dir("record-writer-fails");
  const fs::path out = dir / "recorded.csv";
  const fs::path partial = out.string() + ".partial";
  fs::create_symlink("/dev/full", partial);
  std::string log;
  const std::string error = record_in_process(test::source_dir() / "config" / "gaitmon.toml", out,
                                              std::make_unique<StreamingSource>(3000), log);
  EXPECT_EQ(error, "cannot write " + partial.string() + ": No space left on device");
  EXPECT_FALSE(fs::exists(out));
  EXPECT_TRUE(fs::is_symlink(partial)) << "the partial file was removed";
  EXPECT_NE(log.find("record: writing failed after "), std::string::npos) << log;
  EXPECT_NE(log.find("; what reached the file is kept in " + partial.string()), std::string::npos)
      << log;
}

// Frames a full ring drops are logged while the recording runs, as the monitor logs them, and
// at its end; not only in the final line.
TEST(RecordCommand, FramesDroppedByAFullRingAreLogged) {
  const fs::path dir = test::scratch_dir("record-ring-drops");
  for (const char* name : {"gaitmon.toml", "insoles.toml", "tissue_seed_appendix_i.toml"}) {
    fs::copy_file(test::source_dir() / "config" / name, dir / name);
  }
  std::ifstream in(dir / "gaitmon.toml");
  std::string config((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto at = config.find("\ncapacity_frames = 4096\n");
  ASSERT_NE(at, std::string::npos);
  config.replace(at, std::string("\ncapacity_frames = 4096\n").size(), "\ncapacity_frames = 8\n");
  test::write_text(dir / "gaitmon.toml", config);
  std::string log;
  const std::string error = record_in_process(dir / "gaitmon.toml", dir / "recorded.csv",
                                              std::make_unique<StreamingSource>(1000), log);
  EXPECT_EQ(error, "");
  EXPECT_NE(log.find("record: ring full: "), std::string::npos) << log;
}

}  // namespace
}  // namespace gaitmon
