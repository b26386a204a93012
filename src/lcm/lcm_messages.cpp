// Field-by-field mapping between the Publisher structs and the generated LCM types.
#include "lcm_messages.hpp"

#include <cstdint>
#include <limits>

namespace gaitmon::lcm_messages {
namespace {

std::int8_t foot_code(Foot foot) {
  return foot == Foot::Left ? frame_t::LEFT : frame_t::RIGHT;
}

std::optional<Foot> foot_of(std::int8_t code) {
  if (code == frame_t::LEFT) return Foot::Left;
  if (code == frame_t::RIGHT) return Foot::Right;
  return std::nullopt;
}

// LCM has no unsigned 64-bit type; counters beyond 2^63 would take centuries to reach.
std::int64_t counter(std::uint64_t value) {
  return static_cast<std::int64_t>(value);
}

bool counter_of(std::int64_t value, std::uint64_t& out) {
  if (value < 0) return false;
  out = static_cast<std::uint64_t>(value);
  return true;
}

}  // namespace

void to_lcm(const FrameReport& report, frame_t& message) {
  message.utime = report.utime;
  message.foot = foot_code(report.foot);
  message.frame = report.frame;
  message.t_s = report.t_s;
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const RegionFrameReport& in = report.regions[i];
    region_frame_t& out = message.regions[i];
    out.force_n = in.force_n;
    out.active_area_mm2 = in.active_area_mm2;
    out.ellipse_case = static_cast<std::int8_t>(in.ellipse_case);
    out.centre_x_mm = in.centre_x_mm;
    out.centre_y_mm = in.centre_y_mm;
    out.ra_mm = in.ra_mm;
    out.rb_mm = in.rb_mm;
    out.angle_rad = in.angle_rad;
    out.ellipse_area_mm2 = in.ellipse_area_mm2;
  }
}

void to_lcm(const StepEvent& event, step_t& message) {
  message.utime = event.utime;
  message.foot = foot_code(event.foot);
  message.step = event.step;
  message.kind = event.kind == StepEvent::Kind::HeelStrike ? step_t::HEEL_STRIKE : step_t::TOE_OFF;
  message.frame = event.frame;
  message.t_s = event.t_s;
}

void to_lcm(const FitReport& report, fit_t& message) {
  message.utime = report.utime;
  message.foot = foot_code(report.foot);
  message.step = report.step;
  message.t_heel_strike_s = report.t_heel_strike_s;
  message.t_toe_off_s = report.t_toe_off_s;
  message.nrmse_total_pct = report.nrmse_total_pct;
  message.latency_ms = report.latency_ms;
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const RegionFitReport& in = report.regions[i];
    region_fit_t& out = message.regions[i];
    out.region = static_cast<std::int8_t>(index_of(in.region));
    out.region_name = region_name(in.region);
    out.status = in.status;
    out.kbar_n_per_mm3 = in.kbar_n_per_mm3;
    out.n = in.n;
    out.cbar_ns_per_mm3 = in.cbar_ns_per_mm3;
    out.m = in.m;
    out.se_kbar = in.se_kbar;
    out.se_n = in.se_n;
    out.se_cbar = in.se_cbar;
    out.se_m = in.se_m;
    out.A_mm = in.A_mm;
    out.B_mm = in.B_mm;
    out.C_mm = in.C_mm;
    out.d0_mm = in.d0_mm;
    out.nrmse_pct = in.nrmse_pct;
  }
}

void to_lcm(const StatusReport& report, status_t& message) {
  message.utime = report.utime;
  message.connection = report.connection;
  message.bytes_received = counter(report.bytes_received);
  message.frames_decoded = counter(report.frames_decoded);
  message.crc_errors = counter(report.crc_errors);
  message.resyncs = counter(report.resyncs);
  message.frames_lost_sequence = counter(report.frames_lost_sequence);
  message.reconnects = counter(report.reconnects);
  message.ring_depth = counter(report.ring_depth);
  message.ring_drops = counter(report.ring_drops);
  message.frames_processed = counter(report.frames_processed);
  message.frames_rejected = counter(report.frames_rejected);
  message.steps_detected = counter(report.steps_detected);
  message.step_backlog = counter(report.step_backlog);
  message.step_drops = counter(report.step_drops);
  message.fits_published = counter(report.fits_published);
  message.fits_failed = counter(report.fits_failed);
  message.fit_latency_p50_ms = report.fit_latency_p50_ms;
  message.fit_latency_p99_ms = report.fit_latency_p99_ms;
}

void to_lcm(const RawFrameReport& report, raw_t& message) {
  message.utime = report.utime;
  message.foot = foot_code(report.foot);
  message.sequence = report.sequence;
  message.device_time_us = report.device_time_us;
  message.num_bits = static_cast<std::int32_t>(report.bits.size());
  message.bits.assign(report.bits.begin(), report.bits.end());
}

void to_lcm(const EffectsReport& report, effects_t& message) {
  message.utime = report.utime;
  message.final_estimate = report.final_estimate;
  message.steps = report.steps;
  message.t_first_heel_strike_s = report.t_first_heel_strike_s;
  message.t_last_toe_off_s = report.t_last_toe_off_s;
  message.baseline_nrmse_pct = report.baseline_nrmse_pct;
  message.extended_nrmse_pct = report.extended_nrmse_pct;
  message.baseline_heldout_nrmse_pct = report.baseline_heldout_nrmse_pct;
  message.extended_heldout_nrmse_pct = report.extended_heldout_nrmse_pct;
  message.num_params = static_cast<std::int16_t>(report.params.size());
  message.params.resize(report.params.size());
  for (std::size_t i = 0; i < report.params.size(); ++i) {
    const EffectParamReport& in = report.params[i];
    effect_param_t& out = message.params[i];
    out.effect = in.effect;
    out.name = in.name;
    out.value = in.value;
    out.se = in.se;
  }
}

std::optional<FrameReport> from_lcm(const frame_t& message) {
  FrameReport report;
  const auto foot = foot_of(message.foot);
  if (!foot) return std::nullopt;
  report.utime = message.utime;
  report.foot = *foot;
  report.frame = message.frame;
  report.t_s = message.t_s;
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const region_frame_t& in = message.regions[i];
    if (in.ellipse_case < 0) return std::nullopt;
    RegionFrameReport& out = report.regions[i];
    out.force_n = in.force_n;
    out.active_area_mm2 = in.active_area_mm2;
    out.ellipse_case = static_cast<std::uint8_t>(in.ellipse_case);
    out.centre_x_mm = in.centre_x_mm;
    out.centre_y_mm = in.centre_y_mm;
    out.ra_mm = in.ra_mm;
    out.rb_mm = in.rb_mm;
    out.angle_rad = in.angle_rad;
    out.ellipse_area_mm2 = in.ellipse_area_mm2;
  }
  return report;
}

std::optional<StepEvent> from_lcm(const step_t& message) {
  StepEvent event;
  const auto foot = foot_of(message.foot);
  if (!foot) return std::nullopt;
  if (message.kind == step_t::HEEL_STRIKE) {
    event.kind = StepEvent::Kind::HeelStrike;
  } else if (message.kind == step_t::TOE_OFF) {
    event.kind = StepEvent::Kind::ToeOff;
  } else {
    return std::nullopt;
  }
  event.utime = message.utime;
  event.foot = *foot;
  event.step = message.step;
  event.frame = message.frame;
  event.t_s = message.t_s;
  return event;
}

std::optional<FitReport> from_lcm(const fit_t& message) {
  FitReport report;
  const auto foot = foot_of(message.foot);
  if (!foot) return std::nullopt;
  report.utime = message.utime;
  report.foot = *foot;
  report.step = message.step;
  report.t_heel_strike_s = message.t_heel_strike_s;
  report.t_toe_off_s = message.t_toe_off_s;
  report.nrmse_total_pct = message.nrmse_total_pct;
  report.latency_ms = message.latency_ms;
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const region_fit_t& in = message.regions[i];
    if (in.region < 0 || static_cast<std::size_t>(in.region) >= kRegionCount) return std::nullopt;
    RegionFitReport& out = report.regions[i];
    out.region = kRegions[static_cast<std::size_t>(in.region)];
    out.status = in.status;
    out.kbar_n_per_mm3 = in.kbar_n_per_mm3;
    out.n = in.n;
    out.cbar_ns_per_mm3 = in.cbar_ns_per_mm3;
    out.m = in.m;
    out.se_kbar = in.se_kbar;
    out.se_n = in.se_n;
    out.se_cbar = in.se_cbar;
    out.se_m = in.se_m;
    out.A_mm = in.A_mm;
    out.B_mm = in.B_mm;
    out.C_mm = in.C_mm;
    out.d0_mm = in.d0_mm;
    out.nrmse_pct = in.nrmse_pct;
  }
  return report;
}

std::optional<StatusReport> from_lcm(const status_t& message) {
  StatusReport report;
  report.utime = message.utime;
  report.connection = message.connection;
  const bool ok = counter_of(message.bytes_received, report.bytes_received) &&
                  counter_of(message.frames_decoded, report.frames_decoded) &&
                  counter_of(message.crc_errors, report.crc_errors) &&
                  counter_of(message.resyncs, report.resyncs) &&
                  counter_of(message.frames_lost_sequence, report.frames_lost_sequence) &&
                  counter_of(message.reconnects, report.reconnects) &&
                  counter_of(message.ring_depth, report.ring_depth) &&
                  counter_of(message.ring_drops, report.ring_drops) &&
                  counter_of(message.frames_processed, report.frames_processed) &&
                  counter_of(message.frames_rejected, report.frames_rejected) &&
                  counter_of(message.steps_detected, report.steps_detected) &&
                  counter_of(message.step_backlog, report.step_backlog) &&
                  counter_of(message.step_drops, report.step_drops) &&
                  counter_of(message.fits_published, report.fits_published) &&
                  counter_of(message.fits_failed, report.fits_failed);
  if (!ok) return std::nullopt;
  report.fit_latency_p50_ms = message.fit_latency_p50_ms;
  report.fit_latency_p99_ms = message.fit_latency_p99_ms;
  return report;
}

std::optional<RawFrameReport> from_lcm(const raw_t& message) {
  constexpr std::int64_t kMaxU32 = std::numeric_limits<std::uint32_t>::max();
  const auto foot = foot_of(message.foot);
  if (!foot || message.sequence < 0 || message.sequence > kMaxU32 || message.device_time_us < 0 ||
      message.device_time_us > kMaxU32 ||
      message.num_bits != static_cast<std::int64_t>(message.bits.size())) {
    return std::nullopt;
  }
  RawFrameReport report;
  report.utime = message.utime;
  report.foot = *foot;
  report.sequence = static_cast<std::uint32_t>(message.sequence);
  report.device_time_us = static_cast<std::uint32_t>(message.device_time_us);
  report.bits.assign(message.bits.begin(), message.bits.end());
  return report;
}

std::optional<EffectsReport> from_lcm(const effects_t& message) {
  if (message.steps < 0 || message.num_params < 0 ||
      static_cast<std::size_t>(message.num_params) != message.params.size()) {
    return std::nullopt;
  }
  EffectsReport report;
  report.utime = message.utime;
  report.final_estimate = message.final_estimate;
  report.steps = message.steps;
  report.t_first_heel_strike_s = message.t_first_heel_strike_s;
  report.t_last_toe_off_s = message.t_last_toe_off_s;
  report.baseline_nrmse_pct = message.baseline_nrmse_pct;
  report.extended_nrmse_pct = message.extended_nrmse_pct;
  report.baseline_heldout_nrmse_pct = message.baseline_heldout_nrmse_pct;
  report.extended_heldout_nrmse_pct = message.extended_heldout_nrmse_pct;
  for (const effect_param_t& p : message.params) {
    report.params.push_back({p.effect, p.name, p.value, p.se});
  }
  return report;
}

}  // namespace gaitmon::lcm_messages
