// Field-by-field mapping between the Publisher structs and the generated LCM types.
#include "lcm_messages.hpp"

#include <cstdint>
#include <limits>

#include "gaitmon/contact_ellipse.hpp"

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

// The structs and their messages name these fields alike, so one body serves both directions.
template <typename From, typename To>
void copy_region_frame_fields(const From& in, To& out) {
  out.force_n = in.force_n;
  out.active_area_mm2 = in.active_area_mm2;
  out.centre_x_mm = in.centre_x_mm;
  out.centre_y_mm = in.centre_y_mm;
  out.ra_mm = in.ra_mm;
  out.rb_mm = in.rb_mm;
  out.angle_rad = in.angle_rad;
  out.ellipse_area_mm2 = in.ellipse_area_mm2;
}

template <typename From, typename To>
void copy_fit_fields(const From& in, To& out) {
  out.utime = in.utime;
  out.step = in.step;
  out.t_heel_strike_s = in.t_heel_strike_s;
  out.t_toe_off_s = in.t_toe_off_s;
  out.nrmse_total_pct = in.nrmse_total_pct;
  out.latency_ms = in.latency_ms;
  out.effects_inside = in.effects_inside;
  out.effects_utime = in.effects_utime;
}

// A region's four tissue parameters and their standard errors, in its fit and in its pool.
template <typename From, typename To>
void copy_material_fields(const From& in, To& out) {
  out.kbar_n_per_mm3 = in.kbar_n_per_mm3;
  out.n = in.n;
  out.cbar_ns_per_mm3 = in.cbar_ns_per_mm3;
  out.m = in.m;
  out.se_kbar = in.se_kbar;
  out.se_n = in.se_n;
  out.se_cbar = in.se_cbar;
  out.se_m = in.se_m;
}

template <typename From, typename To>
void copy_region_fit_fields(const From& in, To& out) {
  out.status = in.status;
  copy_material_fields(in, out);
  out.se_kbar_total = in.se_kbar_total;
  out.se_n_total = in.se_n_total;
  out.se_cbar_total = in.se_cbar_total;
  out.se_m_total = in.se_m_total;
  out.A_mm = in.A_mm;
  out.B_mm = in.B_mm;
  out.C_mm = in.C_mm;
  out.d0_mm = in.d0_mm;
  out.nrmse_pct = in.nrmse_pct;
  out.m_steps = in.m_steps;
}

template <typename From, typename To>
void copy_effects_fields(const From& in, To& out) {
  out.utime = in.utime;
  out.final_estimate = in.final_estimate;
  out.steps = in.steps;
  out.t_first_heel_strike_s = in.t_first_heel_strike_s;
  out.t_last_toe_off_s = in.t_last_toe_off_s;
  out.baseline_nrmse_pct = in.baseline_nrmse_pct;
  out.extended_nrmse_pct = in.extended_nrmse_pct;
  out.baseline_heldout_nrmse_pct = in.baseline_heldout_nrmse_pct;
  out.extended_heldout_nrmse_pct = in.extended_heldout_nrmse_pct;
}

template <typename From, typename To>
void copy_tissue_fields(const From& in, To& out) {
  out.utime = in.utime;
  out.final_estimate = in.final_estimate;
  out.step = in.step;
  out.t_first_heel_strike_s = in.t_first_heel_strike_s;
  out.t_last_toe_off_s = in.t_last_toe_off_s;
}

template <typename From, typename To>
void copy_region_tissue_fields(const From& in, To& out) {
  out.status = in.status;
  out.steps = in.steps;
  copy_material_fields(in, out);
}

// Calls visit(report member, message member) for every counter of the status report.
template <typename Visit>
void for_each_counter(Visit&& visit) {
  visit(&StatusReport::bytes_received, &status_t::bytes_received);
  visit(&StatusReport::frames_decoded, &status_t::frames_decoded);
  visit(&StatusReport::crc_errors, &status_t::crc_errors);
  visit(&StatusReport::resyncs, &status_t::resyncs);
  visit(&StatusReport::frames_truncated, &status_t::frames_truncated);
  visit(&StatusReport::header_errors, &status_t::header_errors);
  visit(&StatusReport::frames_lost_sequence, &status_t::frames_lost_sequence);
  visit(&StatusReport::sequence_restarts, &status_t::sequence_restarts);
  visit(&StatusReport::reconnects, &status_t::reconnects);
  visit(&StatusReport::transfers_overflowed, &status_t::transfers_overflowed);
  visit(&StatusReport::ring_depth, &status_t::ring_depth);
  visit(&StatusReport::ring_drops, &status_t::ring_drops);
  visit(&StatusReport::frames_processed, &status_t::frames_processed);
  visit(&StatusReport::frames_rejected, &status_t::frames_rejected);
  visit(&StatusReport::segmentation_gaps, &status_t::segmentation_gaps);
  visit(&StatusReport::steps_detected, &status_t::steps_detected);
  visit(&StatusReport::step_backlog, &status_t::step_backlog);
  visit(&StatusReport::step_drops, &status_t::step_drops);
  visit(&StatusReport::fits_published, &status_t::fits_published);
  visit(&StatusReport::fits_failed, &status_t::fits_failed);
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
    copy_region_frame_fields(in, out);
    out.ellipse_case = static_cast<std::int8_t>(in.ellipse_case);
  }
}

void to_lcm(const StepEvent& event, step_t& message) {
  message.utime = event.utime;
  message.foot = foot_code(event.foot);
  message.step = event.step;
  message.kind = event.kind == StepEvent::Kind::HeelStrike ? step_t::HEEL_STRIKE : step_t::TOE_OFF;
  message.complete = event.complete;
  message.frame = event.frame;
  message.t_s = event.t_s;
}

void to_lcm(const FitReport& report, fit_t& message) {
  copy_fit_fields(report, message);
  message.foot = foot_code(report.foot);
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const RegionFitReport& in = report.regions[i];
    region_fit_t& out = message.regions[i];
    out.region = static_cast<std::int8_t>(index_of(in.region));
    out.region_name = region_name(in.region);
    copy_region_fit_fields(in, out);
  }
}

void to_lcm(const StatusReport& report, status_t& message) {
  message.utime = report.utime;
  message.connection = report.connection;
  for_each_counter(
      [&](auto field, auto message_field) { message.*message_field = counter(report.*field); });
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
  copy_effects_fields(report, message);
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

void to_lcm(const TissueReport& report, tissue_t& message) {
  copy_tissue_fields(report, message);
  message.foot = foot_code(report.foot);
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const RegionTissueReport& in = report.regions[i];
    region_tissue_t& out = message.regions[i];
    out.region = static_cast<std::int8_t>(index_of(in.region));
    out.region_name = region_name(in.region);
    copy_region_tissue_fields(in, out);
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
    if (in.ellipse_case < 0 || in.ellipse_case > static_cast<int>(EllipseCase::Long)) {
      return std::nullopt;
    }
    RegionFrameReport& out = report.regions[i];
    copy_region_frame_fields(in, out);
    out.ellipse_case = static_cast<std::uint8_t>(in.ellipse_case);
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
  event.complete = message.complete;
  event.frame = message.frame;
  event.t_s = message.t_s;
  return event;
}

std::optional<FitReport> from_lcm(const fit_t& message) {
  FitReport report;
  const auto foot = foot_of(message.foot);
  if (!foot) return std::nullopt;
  copy_fit_fields(message, report);
  report.foot = *foot;
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const region_fit_t& in = message.regions[i];
    if (in.region < 0 || static_cast<std::size_t>(in.region) >= kRegionCount) return std::nullopt;
    RegionFitReport& out = report.regions[i];
    out.region = kRegions[static_cast<std::size_t>(in.region)];
    copy_region_fit_fields(in, out);
  }
  return report;
}

std::optional<StatusReport> from_lcm(const status_t& message) {
  StatusReport report;
  report.utime = message.utime;
  report.connection = message.connection;
  bool ok = true;
  for_each_counter([&](auto field, auto message_field) {
    ok = ok && counter_of(message.*message_field, report.*field);
  });
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
  copy_effects_fields(message, report);
  for (const effect_param_t& p : message.params) {
    report.params.push_back({p.effect, p.name, p.value, p.se});
  }
  return report;
}

std::optional<TissueReport> from_lcm(const tissue_t& message) {
  TissueReport report;
  const auto foot = foot_of(message.foot);
  if (!foot) return std::nullopt;
  copy_tissue_fields(message, report);
  report.foot = *foot;
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const region_tissue_t& in = message.regions[i];
    if (in.region < 0 || static_cast<std::size_t>(in.region) >= kRegionCount || in.steps < 0) {
      return std::nullopt;
    }
    RegionTissueReport& out = report.regions[i];
    out.region = kRegions[static_cast<std::size_t>(in.region)];
    copy_region_tissue_fields(in, out);
  }
  return report;
}

}  // namespace gaitmon::lcm_messages
