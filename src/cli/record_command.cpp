// `gaitmon record`: what the driver receives, written as a session CSV v1.
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <ctime>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "drivers/frame_decoder.hpp"
#include "gaitmon/device_clock.hpp"
#include "gaitmon/frame_ring.hpp"
#include "gaitmon/log_throttle.hpp"
#include "gaitmon/session.hpp"
#include "live.hpp"
#include "output_file.hpp"

namespace gaitmon::cli {
namespace {

struct RecordArgs {
  std::filesystem::path out;
  std::string serial;
  bool usb = false;
};

std::string utc_now_iso8601() {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  std::array<char, 32> text{};
  std::strftime(text.data(), text.size(), "%Y-%m-%dT%H:%M:%SZ", &utc);
  return text.data();
}

/// The writer thread's side: frames from the ring into the session file, which is created at
/// the first frame (its insole size and sensor count fix the header).
class SessionRecorder {
 public:
  SessionRecorder(std::filesystem::path partial, double sample_rate_hz, double max_gap_s,
                  std::string source)
      : partial_(std::move(partial)),
        rate_hz_(sample_rate_hz),
        max_gap_us_(std::llround(max_gap_s * 1e6)),
        source_(std::move(source)) {}

  void write(const SensorFrame& in) {
    if (!writer_) open(in);
    if (in.size != header_.insole_size || in.sensor_count != header_.sensors) {
      skip(fmt::format("foot {}: a {} insole with {} sensors in a {} recording", foot_name(in.foot),
                       insole_size_name(in.size), in.sensor_count,
                       insole_size_name(header_.insole_size)));
      return;
    }
    const auto foot = static_cast<std::size_t>(in.foot);
    auto& clock = clocks_[foot];
    if (!clock) clock.emplace(rate_hz_);
    const std::int64_t before_us = clock->time_us();
    const DeviceClock::Tick tick = clock->advance(in.device_time_us);
    if (tick == DeviceClock::Tick::Forward && spacings_us_.size() < kRateSpacings) {
      spacings_us_.push_back(clock->time_us() - before_us);
    }
    if (tick == DeviceClock::Tick::Repeated) {
      skip(fmt::format("foot {}: device time {} us repeated", foot_name(in.foot),
                       in.device_time_us));
      return;
    }
    if (tick == DeviceClock::Tick::WentBack) {
      // The device restarted, and its counter says nothing of the time in between; the host's
      // clock does. More than max_gap_s, so that segment and analyze restart the foot's
      // segmentation there, as the live monitor does.
      const std::int64_t host_us = (in.host_time_ns - last_host_ns_[foot]) / 1000;
      restart_offsets_us_[foot] +=
          std::max(host_us, max_gap_us_ + clock->period_us()) - clock->period_us();
    }
    last_host_ns_[foot] = in.host_time_ns;
    frame_.t_s = static_cast<double>(clock->time_us() + restart_offsets_us_[foot]) / 1e6;
    frame_.foot = in.foot;
    frame_.bits.assign(in.bits.begin(), in.bits.begin() + in.sensor_count);
    writer_->write(frame_);
    ++written_;
  }

  /// Closes the file; false if nothing was recorded.
  bool close() {
    if (!writer_) return false;
    writer_->close();
    return true;
  }
  std::uint64_t written() const { return written_; }
  std::uint64_t skipped() const { return skipped_; }

  /// The device's rate per foot from the median spacing of its first frames (a lost frame or a
  /// gap does not move a median); none before 10 spacings.
  std::optional<double> device_rate_hz() const {
    if (spacings_us_.size() < 10) return std::nullopt;
    std::vector<std::int64_t> sorted = spacings_us_;
    const auto middle = sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2);
    std::nth_element(sorted.begin(), middle, sorted.end());
    return 1e6 / static_cast<double>(*middle);
  }

 private:
  void open(const SensorFrame& first) {
    header_.insole_size = first.size;
    header_.sample_rate_hz = rate_hz_;
    header_.sensors = first.sensor_count;
    header_.recorded_at = utc_now_iso8601();
    header_.note = "recorded by gaitmon record from " + source_;
    writer_ = std::make_unique<SessionWriter>(partial_, header_);
  }
  void skip(const std::string& why) {
    ++skipped_;
    if (auto held = skip_log_.allow()) {
      spdlog::warn("record: frame skipped: {} ({} similar suppressed)", why, *held);
    }
  }

  std::filesystem::path partial_;
  double rate_hz_;
  std::int64_t max_gap_us_;
  std::string source_;
  SessionHeader header_;
  std::unique_ptr<SessionWriter> writer_;
  std::array<std::optional<DeviceClock>, 2> clocks_;
  std::array<std::int64_t, 2> last_host_ns_{};
  std::array<std::int64_t, 2> restart_offsets_us_{};  ///< time added at device restarts
  static constexpr std::size_t kRateSpacings = 2000;
  std::vector<std::int64_t> spacings_us_;  ///< between a foot's successive device times
  Frame frame_;
  std::uint64_t written_ = 0;
  std::uint64_t skipped_ = 0;
  LogThrottle skip_log_;
};

/// The writer thread, told that the driver is done and joined at its end too, so that a driver
/// that throws does not leave a joinable thread behind (std::terminate).
class WriterThread {
 public:
  template <typename Body>
  WriterThread(std::atomic<bool>& driver_done, Body body)
      : driver_done_(driver_done), thread_(std::move(body)) {}
  ~WriterThread() { join(); }
  WriterThread(const WriterThread&) = delete;
  WriterThread& operator=(const WriterThread&) = delete;

  void join() {
    driver_done_.store(true, std::memory_order_release);
    if (thread_.joinable()) thread_.join();
  }

 private:
  std::atomic<bool>& driver_done_;
  std::thread thread_;
};

void run_record(const GlobalOptions& global, const RecordArgs& args,
                const InsoleSourceFactory& make_source) {
  Config config = load_global_config(global);
  if (!args.serial.empty()) config.serial.device = args.serial;
  // Before the recording: a session must not be recorded and then fail to take its name.
  check_output_path(args.out, "--out");
  const std::filesystem::path partial = args.out.string() + ".partial";

  // Signals first: every thread started below inherits the blocked mask, those libusb starts
  // inside UsbSource's constructor included.
  std::atomic<drivers::ByteSource*> live_source{nullptr};
  StopOnSignal on_signal("the driver, then the writer, which writes what the ring holds", [&](int) {
    if (drivers::ByteSource* s = live_source.load()) s->stop();
  });
  const std::unique_ptr<drivers::ByteSource> source = make_source(config, args.usb);
  const FinishOnExit watching(on_signal);
  live_source.store(source.get());
  const std::string source_name = insole_source_name(config, args.usb);

  // The driver thread never waits on the disk: frames go through a ring to a writer thread, and
  // a full ring drops (and counts) them as in `gaitmon run`.
  FrameRing ring(config.ring.capacity_frames);
  drivers::FrameDecoder decoder{drivers::WireFormat(config.wire)};
  LinkStatus link(decoder, *source);
  SessionRecorder recorder(partial, config.sample_rate_hz, config.segmentation.max_gap_s,
                           source_name);
  std::atomic<bool> driver_done{false};
  std::exception_ptr writer_error;
  // As the monitor's: once per [monitor] status_period_s and at the end, so that a recording
  // that loses frames says so while it runs.
  std::uint64_t drops_logged = 0;
  const auto log_drops = [&](std::string_view when) {
    const std::uint64_t drops = ring.drops();
    if (drops <= drops_logged) return;
    spdlog::warn("record: ring full: {} frames dropped {}, {} in all", drops - drops_logged, when,
                 drops);
    drops_logged = drops;
  };
  const auto drop_period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(config.monitor.status_period_s));
  WriterThread writer(driver_done, [&] {
    try {
      SensorFrame frame;
      auto next_drop_log = std::chrono::steady_clock::now() + drop_period;
      for (;;) {
        if (const auto now = std::chrono::steady_clock::now(); now >= next_drop_log) {
          log_drops(fmt::format("in the last {:.1f} s", config.monitor.status_period_s));
          link.warn_of_overflows();
          next_drop_log = now + drop_period;
        }
        if (ring.try_pop(frame)) {
          recorder.write(frame);
        } else if (driver_done.load(std::memory_order_acquire)) {
          while (ring.try_pop(frame)) recorder.write(frame);
          return;
        } else {
          std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
      }
    } catch (...) {
      writer_error = std::current_exception();
      source->stop();
    }
  });
  spdlog::info("record: {} -> {}", source_name, args.out.string());
  // A signal that came before live_source was set found nothing to stop.
  if (on_signal.received() == 0) {
    try {
      source->run(
          [&](std::span<const std::uint8_t> bytes) {
            decoder.feed(bytes, [&](const SensorFrame& frame) { (void)ring.try_push(frame); });
          },
          [&](drivers::LinkState state, std::string_view detail) { link.on_state(state, detail); });
    } catch (...) {
      // What was recorded before the driver failed is whole rows: it is kept, under the partial
      // name, as no recording can be taken again.
      writer.join();
      log_drops("since the last warning");
      if (!writer_error && recorder.close()) {
        spdlog::error("record: the driver failed; the {} frames recorded before are kept in {}",
                      recorder.written(), partial.string());
      }
      throw;
    }
  }
  writer.join();
  log_drops("since the last warning");
  if (writer_error) {
    // As after a driver failure, what reached the file is kept: a recording cannot be taken
    // again. The rows still buffered follow when the recorder closes it; after a failed write
    // to the disk they may be lost.
    if (recorder.written() > 0) {
      spdlog::error("record: writing failed after {} frames; what reached the file is kept in {}",
                    recorder.written(), partial.string());
    } else {
      std::error_code ignored;
      std::filesystem::remove(partial, ignored);
    }
    std::rethrow_exception(writer_error);
  }
  if (!recorder.close()) {
    throw std::runtime_error("no frame was received from " + source_name + "; nothing written");
  }
  std::filesystem::rename(partial, args.out);
  // The header's rate is the config's: a device at another rate makes segment and analyze
  // misjudge every window in frames, so it must not pass quietly.
  if (const auto rate = recorder.device_rate_hz();
      rate && std::abs(*rate / config.sample_rate_hz - 1.0) > 0.05) {
    spdlog::warn(
        "record: the device's clock shows {:.1f} Hz per foot, but {} says sample_rate_hz {} (the "
        "config's, {}): correct that header line, and set sample_rate_hz in the config for `run`",
        *rate, args.out.string(), config.sample_rate_hz, config.source.string());
  }
  fmt::print("wrote {} ({} frames); {} skipped, {} dropped (ring full)\n{}\n", args.out.string(),
             recorder.written(), recorder.skipped(), ring.drops(), link.summary());
}

}  // namespace

void add_record_command(CLI::App& app, const GlobalOptions& global,
                        InsoleSourceFactory make_source) {
  if (!make_source) make_source = make_insole_source;
  auto args = std::make_shared<RecordArgs>();
  CLI::App* sub = app.add_subcommand(
      "record",
      "Records what the insole link delivers as a session CSV v1 (times from the device "
      "clock; the header's sample_rate_hz is the config's, and a device whose clock shows "
      "another rate is warned of); Ctrl-C ends the recording");
  sub->add_option("--out,-o", args->out, "Session CSV to write")->required();
  CLI::Option* serial = sub->add_option("--serial", args->serial,
                                        "Serial device (default: [serial] device of the config)");
  sub->add_flag("--usb", args->usb, "Read the insole over USB ([usb] of the config)")
      ->excludes(serial);
  sub->callback([&global, args, make_source = std::move(make_source)] {
    run_record(global, *args, make_source);
  });
}

}  // namespace gaitmon::cli
