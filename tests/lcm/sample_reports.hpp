// Reports with a distinct, hand-picked value in every field, so that a field mapped to the wrong
// place or lost on the way shows up; shared by the tests in tests/lcm/.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "gaitmon/publisher.hpp"

namespace gaitmon::test {

inline FrameReport sample_frame() {
  FrameReport r;
  r.utime = 1763737200123456;
  r.foot = Foot::Right;
  r.frame = 4242;
  r.t_s = 42.42;
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const double k = static_cast<double>(i);
    RegionFrameReport& g = r.regions[i];
    g.force_n = 100.25 + k;
    g.active_area_mm2 = 225.5 + k;
    g.ellipse_case = static_cast<std::uint8_t>(i % 6);
    g.centre_x_mm = -10.125 - k;
    g.centre_y_mm = 150.0625 + k;
    g.ra_mm = 20.5 + k;
    g.rb_mm = 10.75 + k;
    g.angle_rad = 0.3 + 0.01 * k;
    g.ellipse_area_mm2 = 700.125 + k;
  }
  return r;
}

inline StepEvent sample_step() {
  StepEvent e;
  e.utime = 1763737200223456;
  e.foot = Foot::Left;
  e.step = 17;
  e.kind = StepEvent::Kind::ToeOff;
  e.complete = false;
  e.frame = 1234;
  e.t_s = 12.34;
  return e;
}

inline FitReport sample_fit() {
  FitReport r;
  r.utime = 1763737200323456;
  r.foot = Foot::Right;
  r.step = 23;
  r.t_heel_strike_s = 30.125;
  r.t_toe_off_s = 30.75;
  r.nrmse_total_pct = 4.5;
  r.latency_ms = 1.875;
  r.effects_inside = "stress_relaxation,hysteresis";
  r.effects_utime = 1763737199000000;
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const double k = static_cast<double>(i);
    RegionFitReport& g = r.regions[i];
    g.region = kRegions[i];
    g.status = i == 6 ? "fit_failed:no convergence" : (i == 7 ? "no_contact" : "ok");
    g.kbar_n_per_mm3 = 0.117 + 0.001 * k;
    g.n = 0.5 + 0.01 * k;
    g.cbar_ns_per_mm3 = 0.02 + 0.001 * k;
    g.m = 1.1 + 0.01 * k;
    g.se_kbar = 0.003 + 0.0001 * k;
    g.se_n = 0.02 + 0.001 * k;
    g.se_cbar = 0.002 + 0.0001 * k;
    g.se_m = 0.05 + 0.001 * k;
    g.se_kbar_total = 0.005 + 0.0001 * k;
    g.se_n_total = 0.03 + 0.001 * k;
    g.se_cbar_total = 0.004 + 0.0001 * k;
    g.se_m_total = 0.0625 + 0.001 * k;
    g.A_mm = 40.5 + k;
    g.B_mm = 30.25 + k;
    g.C_mm = 60.125 + k;
    g.d0_mm = 10.5 + k;
    g.nrmse_pct = 3.25 + k;
    g.m_steps = i < 3 ? static_cast<int>(40 + i) : 0;
  }
  return r;
}

inline StatusReport sample_status() {
  StatusReport s;
  s.utime = 1763737200423456;
  s.connection = "connected";
  s.bytes_received = 123456789;
  s.frames_decoded = 98765;
  s.crc_errors = 3;
  s.resyncs = 5;
  s.frames_truncated = 37;
  s.header_errors = 41;
  s.frames_lost_sequence = 7;
  s.sequence_restarts = 43;
  s.reconnects = 2;
  s.transfers_overflowed = 53;
  s.ring_depth = 11;
  s.ring_drops = 13;
  s.frames_processed = 98700;
  s.frames_rejected = 31;
  s.segmentation_gaps = 47;
  s.steps_detected = 17;
  s.step_backlog = 19;
  s.step_drops = 23;
  s.fits_published = 29;
  s.fits_failed = 31;
  s.fit_latency_p50_ms = 1.5;
  s.fit_latency_p99_ms = 12.25;
  return s;
}

inline RawFrameReport sample_raw() {
  RawFrameReport r;
  r.utime = 1763737200523456;
  r.foot = Foot::Left;
  r.sequence = 4000000000U;  // above INT32_MAX: the unsigned range must survive
  r.device_time_us = 3999999999U;
  for (int i = 0; i < 161; ++i) r.bits.push_back(static_cast<std::uint8_t>((i * 37) % 256));
  return r;
}

inline EffectsReport sample_effects() {
  EffectsReport r;
  r.utime = 1763737200623456;
  r.final_estimate = true;
  r.steps = 97;
  r.t_first_heel_strike_s = 11.25;
  r.t_last_toe_off_s = 63.5;
  r.baseline_nrmse_pct = 6.75;
  r.extended_nrmse_pct = 6.375;
  r.baseline_heldout_nrmse_pct = 6.8125;
  r.extended_heldout_nrmse_pct = 6.4375;
  r.params = {{"stress_relaxation", "strength", 0.3325, 0.0094},
              {"stress_relaxation", "tau_s", 0.228125, 0.0083},
              {"impact_transient", "amplitude_n", 81.5, 4.25}};
  return r;
}

inline TissueReport sample_tissue() {
  TissueReport r;
  r.utime = 1763737200723456;
  r.final_estimate = false;
  r.foot = Foot::Left;
  r.step = 41;
  r.t_first_heel_strike_s = 2.5;
  r.t_last_toe_off_s = 95.25;
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const double k = static_cast<double>(i);
    RegionTissueReport& g = r.regions[i];
    g.region = kRegions[i];
    g.status = i >= 5 ? "not_pooled:the pooled mean leaves the fit bounds" : "ok";
    g.steps = 80 - static_cast<int>(i);
    g.kbar_n_per_mm3 = 0.125 + 0.001 * k;
    g.n = 0.375 + 0.01 * k;
    g.cbar_ns_per_mm3 = 0.015625 + 0.001 * k;
    g.m = 1.0625 + 0.01 * k;
    g.se_kbar = 0.0046 + 0.0001 * k;
    g.se_n = 0.021 + 0.001 * k;
    g.se_cbar = 0.0013 + 0.0001 * k;
    g.se_m = 0.061 + 0.001 * k;
  }
  return r;
}

/// One of each sample, in the order of the Publisher interface.
inline void publish_samples(Publisher& publisher) {
  publisher.publish(sample_frame());
  publisher.publish(sample_step());
  publisher.publish(sample_fit());
  publisher.publish(sample_status());
  publisher.publish(sample_raw());
  publisher.publish(sample_effects());
  publisher.publish(sample_tissue());
}

}  // namespace gaitmon::test
