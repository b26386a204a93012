// The live commands' shared pieces: link status, the per-step console line, signal handling.
#include "live.hpp"

#include <fmt/format.h>
#include <signal.h>
#include <spdlog/spdlog.h>

#include <CLI/Error.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <iterator>
#include <string>
#include <system_error>

#include "commands.hpp"
#include "drivers/serial_source.hpp"
#include "drivers/usb_source.hpp"
#include "replay/pacer.hpp"

namespace gaitmon::cli {

double parse_speed(const std::string& text) {
  if (text == "max") return replay::kMaxSpeed;
  std::size_t used = 0;
  double speed = 0.0;
  try {
    speed = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != text.size() || !(speed >= kMinSpeed) || !std::isfinite(speed)) {
    throw CLI::ValidationError(
        "--speed",
        fmt::format("must be a number >= {:g} (x real time) or max, got {}", kMinSpeed, text));
  }
  return speed;
}

std::unique_ptr<drivers::ByteSource> make_insole_source(const Config& config, bool usb) {
  if (usb && config.usb.vendor_id == 0 && config.usb.product_id == 0) {
    // No device has these ids, so the driver would wait for it without a word.
    spdlog::warn(
        "[usb] vendor_id and product_id of {} are 0000:0000, the shipped placeholders: set them "
        "to your insole's (lsusb lists them)",
        config.source.string());
  }
  if (usb) return std::make_unique<drivers::UsbSource>(config.usb);
  return std::make_unique<drivers::SerialSource>(config.serial);
}

std::string insole_source_name(const Config& config, bool usb) {
  return usb ? fmt::format("USB {:04x}:{:04x}", config.usb.vendor_id, config.usb.product_id)
             : config.serial.device;
}

void LinkStatus::on_state(drivers::LinkState state, std::string_view detail) {
  state_.store(state);
  if (state == drivers::LinkState::Connected) {
    connections_.fetch_add(1);
    spdlog::info("link connected: {}", detail);
  } else if (state == drivers::LinkState::Disconnected) {
    decoder_.reset();
    spdlog::warn("link disconnected: {}", detail);
  } else {
    spdlog::info("link connecting: {}", detail);
  }
}

void LinkStatus::on_end(std::string_view detail) {
  state_.store(drivers::LinkState::Disconnected);
  decoder_.reset();
  spdlog::info("link ended: {}", detail);
}

void LinkStatus::fill(StatusReport& status) const {
  const drivers::DecoderCounters c = decoder_.counters();
  status.connection = std::string(drivers::link_state_name(state_.load()));
  status.bytes_received = c.bytes;
  status.frames_decoded = c.frames;
  status.crc_errors = c.crc_errors;
  status.resyncs = c.resyncs;
  status.frames_truncated = c.truncated_frames;
  status.header_errors = c.header_errors;
  status.frames_lost_sequence = c.lost_frames_total();
  status.sequence_restarts = c.sequence_restarts;
  const std::uint64_t connections = connections_.load();
  status.reconnects = connections > 0 ? connections - 1 : 0;
  status.transfers_overflowed = source_.counters().transfers_overflowed;
}

void LinkStatus::warn_of_overflows() {
  const std::uint64_t overflowed = source_.counters().transfers_overflowed;
  if (overflowed <= overflows_warned_.load() || !overflow_log_.allow()) return;
  const std::uint64_t warned = overflows_warned_.exchange(overflowed);
  spdlog::warn(
      "link: {} USB transfers overflowed, {} in all: the device sent more than a transfer holds "
      "and the excess bytes were lost; raise [usb] transfer_bytes",
      overflowed - warned, overflowed);
}

std::string LinkStatus::summary() const {
  StatusReport s;
  fill(s);
  std::string line = fmt::format(
      "link: {} bytes, {} frames decoded; {} CRC errors, {} truncated, {} bad headers, {} resyncs; "
      "{} frames lost (sequence gaps), {} device restarts, {} reconnects",
      s.bytes_received, s.frames_decoded, s.crc_errors, s.frames_truncated, s.header_errors,
      s.resyncs, s.frames_lost_sequence, s.sequence_restarts, s.reconnects);
  // Only USB sources count overflows: a replay or a serial link would report a USB fault as none.
  if (s.transfers_overflowed > 0) {
    fmt::format_to(std::back_inserter(line), ", {} USB transfers overflowed",
                   s.transfers_overflowed);
  }
  return line;
}

void StepPrinter::publish(const FitReport& report) {
  next_.publish(report);
  std::string line = fmt::format(
      "{} step {:>4}  stance {:.3f} s  kbar N/mm3 | cbar Ns/mm3:", foot_name(report.foot),
      report.step, report.t_toe_off_s - report.t_heel_strike_s);
  for (const RegionFitReport& r : report.regions) {
    if (r.status == "ok") {
      fmt::format_to(std::back_inserter(line), "  {} {:.4f}|{:.5f}", region_name(r.region),
                     r.kbar_n_per_mm3, r.cbar_ns_per_mm3);
    } else {
      fmt::format_to(std::back_inserter(line), "  {} {}", region_name(r.region), r.status);
    }
  }
  // Without it a refitted step's kbar could be read as the baseline's.
  if (!report.effects_inside.empty()) {
    fmt::format_to(std::back_inserter(line), "  ({} inside)", report.effects_inside);
  }
  // Nor a cbar fitted at the running m ([model] m_per_session) as one at the step's own m.
  const auto most = std::max_element(
      report.regions.begin(), report.regions.end(),
      [](const RegionFitReport& a, const RegionFitReport& b) { return a.m_steps < b.m_steps; });
  if (most->m_steps > 0) {
    fmt::format_to(std::back_inserter(line), "  (at the running m of up to {} steps)",
                   most->m_steps);
  }
  print(line);
}

void StepPrinter::publish(const EffectsReport& report) {
  next_.publish(report);
  std::string line = fmt::format(
      "{} over {} steps ({:.1f}-{:.1f} s):", report.final_estimate ? "effects, final," : "effects",
      report.steps, report.t_first_heel_strike_s, report.t_last_toe_off_s);
  for (const EffectParamReport& p : report.params) {
    fmt::format_to(std::back_inserter(line), " {}.{} = {};", p.effect, p.name,
                   estimate_text(p.value, p.se, " +- "));
  }
  fmt::format_to(std::back_inserter(line),
                 " pooled NRMSE {:.2f} % -> {:.2f} % (held-out {:.2f} % -> {:.2f} %)",
                 report.baseline_nrmse_pct, report.extended_nrmse_pct,
                 report.baseline_heldout_nrmse_pct, report.extended_heldout_nrmse_pct);
  print(line);
}

void StepPrinter::publish(const TissueReport& report) {
  next_.publish(report);
  // After every step the same table would bury the steps' lines; the run ends with the last one.
  if (!report.final_estimate) return;
  std::string text = fmt::format(
      "tissue over the steps of {:.1f}-{:.1f} s, pooled, +- one standard error with "
      "the measurement chain's error:",
      report.t_first_heel_strike_s, report.t_last_toe_off_s);
  for (const RegionTissueReport& r : report.regions) {
    fmt::format_to(std::back_inserter(text), "\n  {:<18} {:>4} steps  ", region_name(r.region),
                   r.steps);
    if (r.status == "ok") {
      fmt::format_to(
          std::back_inserter(text), "kbar {} N/mm3  n {}  cbar {} Ns/mm3  m {}",
          estimate_text(r.kbar_n_per_mm3, r.se_kbar, " +- "), estimate_text(r.n, r.se_n, " +- "),
          estimate_text(r.cbar_ns_per_mm3, r.se_cbar, " +- "), estimate_text(r.m, r.se_m, " +- "));
    } else {
      const std::string_view prefix = "not_pooled:";
      const std::string_view status = r.status;
      fmt::format_to(std::back_inserter(text), "not pooled: {}",
                     status.starts_with(prefix) ? status.substr(prefix.size()) : status);
    }
  }
  print(text);
}

void StepPrinter::print(const std::string& line) {
  const std::lock_guard lock(print_mutex_);
  std::fputs(line.c_str(), stdout);
  std::fputc('\n', stdout);
  std::fflush(stdout);
}

namespace {

sigset_t stop_signals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  return set;
}

}  // namespace

StopOnSignal::StopOnSignal(std::string stopping, std::function<void(int)> on_signal)
    : stopping_(std::move(stopping)), on_signal_(std::move(on_signal)) {
  const sigset_t set = stop_signals();
  if (const int rc = pthread_sigmask(SIG_BLOCK, &set, nullptr); rc != 0) {
    throw std::system_error(rc, std::generic_category(), "pthread_sigmask");
  }
  watcher_ = std::thread([this, set] {
    // Wakes every 100 ms to notice the end of the command.
    const timespec period{0, 100'000'000};
    while (!done_.load()) {
      const int signal = sigtimedwait(&set, nullptr, &period);
      if (signal <= 0 || received_.load() != 0) continue;
      received_.store(signal);
      spdlog::info("{}: stopping ({})", signal == SIGINT ? "SIGINT" : "SIGTERM", stopping_);
      try {
        on_signal_(signal);
      } catch (const std::exception& e) {
        spdlog::error("stopping failed: {}", e.what());
      }
    }
  });
}

// The signals stay blocked: unblocking would let a second Ctrl-C, pending meanwhile, kill a
// command that is about to exit 0.
StopOnSignal::~StopOnSignal() {
  finish();
}

void StopOnSignal::finish() {
  done_.store(true);
  if (watcher_.joinable()) watcher_.join();
}

}  // namespace gaitmon::cli
