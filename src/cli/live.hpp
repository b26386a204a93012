// What the live commands (run, replay, record) share: the link's state for the status, the
// console line per fitted step, and stopping cleanly on SIGINT or SIGTERM.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>

#include "drivers/byte_source.hpp"
#include "drivers/frame_decoder.hpp"
#include "gaitmon/config.hpp"
#include "gaitmon/log_throttle.hpp"
#include "gaitmon/publisher.hpp"

namespace gaitmon::cli {

/// The slowest playback: slower would stretch a session beyond what the pacer's clock can hold
/// (x 1e-300 is undefined behaviour) and is no use anyway.
inline constexpr double kMinSpeed = 0.001;

/// "max" (replay::kMaxSpeed) or a finite number >= kMinSpeed. Throws CLI::ValidationError
/// otherwise.
double parse_speed(const std::string& text);

/// The insole link of `run` and `record`: the USB driver of [usb] with `usb`, else the serial
/// driver of [serial]. The USB driver starts libusb's threads, so block the stop signals first.
std::unique_ptr<drivers::ByteSource> make_insole_source(const Config& config, bool usb);
/// The link's name for logs and messages: the serial device, or "USB vvvv:pppp".
std::string insole_source_name(const Config& config, bool usb);

/// The link's state and reconnections, written by the driver thread's state handler and read by
/// the status (any thread), and the link's decoder and source, for their counters.
class LinkStatus {
 public:
  LinkStatus(drivers::FrameDecoder& decoder, const drivers::ByteSource& source)
      : decoder_(decoder), source_(source) {}

  /// The ByteSource's state handler, so on the driver thread: logs every change, counts
  /// reconnections (a Connected after the first) and resets the decoder on a Disconnected, as
  /// a partial frame of the old connection must not be joined to the new one's bytes.
  void on_state(drivers::LinkState state, std::string_view detail);
  /// A Disconnected that is the planned end of a finite source (a replay's end of session or
  /// stop): handled as one, but logged as information rather than as a warning.
  void on_end(std::string_view detail);
  /// Fills the driver's fields of a status report from this, the decoder's and the source's
  /// counters.
  void fill(StatusReport& status) const;
  /// Warns of the USB transfers that overflowed since the last warning, at most once a second:
  /// their excess bytes are lost, which the decoder sees only as damaged frames and sequence
  /// gaps, and a larger [usb] transfer_bytes avoids it. For the commands' periodic work; any
  /// thread.
  void warn_of_overflows();
  /// One line of the link's totals for a command's closing summary: what was decoded, every
  /// kind of fault, the frames the sequence counters show lost, device restarts, reconnects and
  /// overflowed transfers.
  std::string summary() const;
  drivers::LinkState state() const { return state_.load(); }

 private:
  drivers::FrameDecoder& decoder_;
  const drivers::ByteSource& source_;
  std::atomic<drivers::LinkState> state_{drivers::LinkState::Connecting};
  std::atomic<std::uint64_t> connections_{0};
  std::atomic<std::uint64_t> overflows_warned_{0};
  LogThrottle overflow_log_;
};

/// Forwards every message to `next` and prints one line per fitted step on stdout: the foot,
/// the step, the stance time and every region's kbar and cbar; one per estimate of the extended
/// model's effects; and at the end a table of each region's tissue pooled over the steps.
/// Thread-safe.
class StepPrinter final : public Publisher {
 public:
  explicit StepPrinter(Publisher& next) : next_(next) {}
  void publish(const FrameReport& report) override { next_.publish(report); }
  void publish(const StepEvent& event) override { next_.publish(event); }
  void publish(const FitReport& report) override;
  void publish(const StatusReport& report) override { next_.publish(report); }
  void publish(const RawFrameReport& report) override { next_.publish(report); }
  void publish(const EffectsReport& report) override;
  void publish(const TissueReport& report) override;

 private:
  void print(const std::string& line);

  Publisher& next_;
  std::mutex print_mutex_;
};

/// From its construction on, SIGINT and SIGTERM do not kill the process: until finish() (or its
/// end) the first one calls `on_signal` (on a thread of its own) and later ones are ignored; they
/// stay blocked after that, as the command is then finishing. Construct it before starting any
/// other thread: it blocks both signals in the calling thread, and threads started later
/// inherit that. `stopping` says in the log what a signal stops, in order.
class StopOnSignal {
 public:
  StopOnSignal(std::string stopping, std::function<void(int signal)> on_signal);
  ~StopOnSignal();
  StopOnSignal(const StopOnSignal&) = delete;
  StopOnSignal& operator=(const StopOnSignal&) = delete;

  /// The signal received, 0 if none.
  int received() const { return received_.load(); }

  /// Stops watching, after a call of `on_signal` in progress has returned: from here on what
  /// `on_signal` touches may be torn down. Later signals stay blocked and pending.
  void finish();

 private:
  std::string stopping_;
  std::function<void(int)> on_signal_;
  std::atomic<int> received_{0};
  std::atomic<bool> done_{false};
  std::thread watcher_;
};

/// Calls finish() of a StopOnSignal at its end. The watcher is constructed first, so it would
/// otherwise outlive what its callback touches; declared after those, this stops it before they
/// are destroyed on every path out of the command, an exception's included.
class FinishOnExit {
 public:
  explicit FinishOnExit(StopOnSignal& watcher) : watcher_(watcher) {}
  ~FinishOnExit() { watcher_.finish(); }
  FinishOnExit(const FinishOnExit&) = delete;
  FinishOnExit& operator=(const FinishOnExit&) = delete;

 private:
  StopOnSignal& watcher_;
};

}  // namespace gaitmon::cli
