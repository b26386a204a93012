// Tests for step segmentation, zeroing and the adaptive threshold, on synthetic and real walking.
#include "gaitmon/segmentation.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <numbers>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "gaitmon/session.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

constexpr std::size_t kSensors = 24;
constexpr std::size_t kLoaded = 16;  // sensors 0..15 share the load, 16..23 read only their bias
constexpr std::array<int, kSensors> kBias{2, 3, 1, 2, 4, 1, 3, 2, 2, 3, 1, 2,
                                          4, 1, 3, 2, 2, 3, 1, 2, 4, 1, 3, 2};  // sums to 54
constexpr double kThreshold = 142.0;
constexpr double kNewtonsPerBit = 64.0 / 255.0 * 1.125;

/// A half-sine load on frames start+1 .. start+length-1, `amplitude` summed bits at its peak.
struct Bump {
  std::int64_t start = 0;
  std::int64_t length = 60;
  double amplitude = 2000.0;
};

double bump_total(const Bump& bump, std::int64_t k) {
  if (k <= bump.start || k >= bump.start + bump.length) return 0.0;
  return bump.amplitude * std::sin(std::numbers::pi * static_cast<double>(k - bump.start) /
                                   static_cast<double>(bump.length));
}

/// First frame where the analytic bump exceeds the threshold.
std::int64_t analytic_heel_strike(const Bump& bump) {
  const double t = static_cast<double>(bump.start) + static_cast<double>(bump.length) /
                                                         std::numbers::pi *
                                                         std::asin(kThreshold / bump.amplitude);
  return static_cast<std::int64_t>(std::floor(t)) + 1;
}

/// Last frame where the analytic bump exceeds the threshold.
std::int64_t analytic_toe_off(const Bump& bump) {
  const double t =
      static_cast<double>(bump.start + bump.length) -
      static_cast<double>(bump.length) / std::numbers::pi * std::asin(kThreshold / bump.amplitude);
  return static_cast<std::int64_t>(std::ceil(t)) - 1;
}

/// Extra bits on sensor s at frame k, on top of kBias and the bump.
using Extra = std::function<int(std::int64_t k, std::size_t s)>;

/// Deterministic noise of -1, 0 or +1 bit per sensor; summed over the 24 sensors it is -8, +16,
/// -8, ... bits in successive frames.
int noise(std::int64_t k, std::size_t s) {
  const auto i = static_cast<std::int64_t>(s);
  return static_cast<int>((k * 7 + i * i) % 3) - 1;
}

std::vector<Frame> make_frames(std::int64_t count, const std::vector<Bump>& bumps,
                               const Extra& extra = nullptr) {
  std::vector<Frame> frames;
  for (std::int64_t k = 0; k < count; ++k) {
    double load = 0.0;
    for (const Bump& b : bumps) load += bump_total(b, k);
    Frame f;
    f.t_s = 0.01 * static_cast<double>(k);
    f.foot = Foot::Left;
    for (std::size_t s = 0; s < kSensors; ++s) {
      int v = kBias[s] + (extra ? extra(k, s) : 0);
      if (s < kLoaded) v += static_cast<int>(std::lround(load / static_cast<double>(kLoaded)));
      f.bits.push_back(static_cast<std::uint8_t>(std::clamp(v, 0, 255)));
    }
    frames.push_back(std::move(f));
  }
  return frames;
}

SegmentationSettings seed_settings() {
  return {142, 5, 5};
}

std::vector<Step> segment(const std::vector<Frame>& frames, double pct = 0.2,
                          const SegmenterLimits& limits = {}) {
  StepSegmenter segmenter(Foot::Left, kSensors, seed_settings(), pct, kNewtonsPerBit, limits);
  std::vector<Step> steps;
  for (const Frame& f : frames) segmenter.push(f, steps);
  segmenter.finish(steps);
  return steps;
}

/// Bumps of 60 frames separated by swings of 40: one stride per 100 frames from `first`.
std::vector<Bump> walking(std::int64_t first, int count) {
  std::vector<Bump> bumps;
  for (int i = 0; i < count; ++i) bumps.push_back({first + 100 * i, 60, 2000.0});
  return bumps;
}

void expect_same(const Step& a, const Step& b) {
  EXPECT_EQ(a.foot, b.foot);
  EXPECT_EQ(a.index, b.index);
  EXPECT_EQ(a.status, b.status);
  EXPECT_EQ(a.heel_strike_frame, b.heel_strike_frame);
  EXPECT_EQ(a.toe_off_frame, b.toe_off_frame);
  EXPECT_EQ(a.t_heel_strike_s, b.t_heel_strike_s);
  EXPECT_EQ(a.t_toe_off_s, b.t_toe_off_s);
  EXPECT_EQ(a.bias_bits, b.bias_bits);
  EXPECT_EQ(a.sensor_zero_bits, b.sensor_zero_bits);
  const auto same = [](double x, double y) { return x == y || (std::isnan(x) && std::isnan(y)); };
  EXPECT_TRUE(same(a.pre_zero_t_s, b.pre_zero_t_s)) << a.pre_zero_t_s << " " << b.pre_zero_t_s;
  EXPECT_TRUE(same(a.post_zero_t_s, b.post_zero_t_s)) << a.post_zero_t_s << " " << b.post_zero_t_s;
  EXPECT_EQ(a.max_summed_bits, b.max_summed_bits);
  EXPECT_EQ(a.zero_noise_sd_bits, b.zero_noise_sd_bits);
  EXPECT_EQ(a.threshold_floor_bits, b.threshold_floor_bits);
  EXPECT_EQ(a.adaptive_threshold_bits, b.adaptive_threshold_bits);
  EXPECT_EQ(a.peak_force_n, b.peak_force_n);
  ASSERT_EQ(a.stance.size(), b.stance.size());
  for (std::size_t i = 0; i < a.stance.size(); ++i) {
    EXPECT_EQ(a.stance[i].t_s, b.stance[i].t_s);
    EXPECT_EQ(a.stance[i].bits, b.stance[i].bits);
  }
}

TEST(AdaptiveThreshold, MatchesTheSeedsExampleOf5BitsAt0_2Percent) {
  EXPECT_DOUBLE_EQ(adaptive_threshold_bits(2500.0, 0.2), 5.0);
  EXPECT_DOUBLE_EQ(adaptive_threshold_bits(3000.0, 0.1), 3.0);
  EXPECT_DOUBLE_EQ(adaptive_threshold_bits(-40.0, 0.2), 0.0);
}

TEST(ZeroAndThreshold, SubtractsTheZeroAndDropsValuesBelowTheThreshold) {
  const std::vector<std::uint8_t> raw{0, 3, 10, 7, 255, 1};
  const std::vector<double> zero{0.0, 1.0, 2.5, 2.0, 0.0, 2.0};
  std::vector<double> out(raw.size(), -99.0);
  zero_and_threshold(raw, zero, 5.0, out);
  // zeroed: 0, 2, 7.5, 5, 255, -1; below 5 -> 0, exactly 5 stays active.
  EXPECT_EQ(out, (std::vector<double>{0.0, 0.0, 7.5, 5.0, 255.0, 0.0}));

  std::vector<double> short_out(2);
  EXPECT_THROW(zero_and_threshold(raw, zero, 5.0, short_out), std::invalid_argument);
  EXPECT_THROW(zero_and_threshold(raw, zero, -1.0, out), std::invalid_argument);
}

// 60 s of contact, 1.5 s from a swing midpoint to its step and a first swing of 0.2 s, in
// frames of the session's rate.
TEST(SegmenterLimits, FollowTheSampleRate) {
  const SegmenterLimits at100 = segmenter_limits(100.0);
  EXPECT_EQ(at100.max_stance_frames, 6000);
  EXPECT_EQ(at100.max_swing_half_frames, 150);
  EXPECT_EQ(at100.min_first_swing_frames, 20);
  EXPECT_DOUBLE_EQ(at100.sample_period_s, 0.01);
  const SegmenterLimits at50 = segmenter_limits(50.0);
  EXPECT_EQ(at50.max_stance_frames, 3000);
  EXPECT_EQ(at50.max_swing_half_frames, 75);
  EXPECT_EQ(at50.min_first_swing_frames, 10);
  EXPECT_DOUBLE_EQ(at50.sample_period_s, 0.02);
}

TEST(StepStatusName, IsOkOrIncomplete) {
  EXPECT_EQ(step_status_name(StepStatus::Ok), "ok");
  EXPECT_EQ(step_status_name(StepStatus::Incomplete), "incomplete");
}

TEST(StepSegmenter, FindsEveryStepAtTheAnalyticCrossings) {
  const std::vector<Bump> bumps = walking(50, 5);
  // The frames either side of each crossing must sit well clear of the threshold, so that the
  // noise (at most 16 bits summed), the rounding (16 x 0.5 bits) and the error of the swing
  // bias (at most 3.2 bits) cannot move the expected frames.
  for (const Bump& b : bumps) {
    const auto hs = analytic_heel_strike(b);
    const auto to = analytic_toe_off(b);
    ASSERT_GT(kThreshold - bump_total(b, hs - 1), 30.0);
    ASSERT_GT(bump_total(b, hs) - kThreshold, 30.0);
    ASSERT_GT(kThreshold - bump_total(b, to + 1), 30.0);
    ASSERT_GT(bump_total(b, to) - kThreshold, 30.0);
  }
  // By hand: 2000 sin(pi/60) = 104.7 < 142 < 209.1 = 2000 sin(2 pi/60).
  EXPECT_EQ(analytic_heel_strike(bumps[0]), 52);
  EXPECT_EQ(analytic_toe_off(bumps[0]), 108);

  const std::vector<Step> steps = segment(make_frames(560, bumps, noise));
  ASSERT_EQ(steps.size(), bumps.size());
  for (std::size_t i = 0; i < steps.size(); ++i) {
    SCOPED_TRACE("step " + std::to_string(i));
    EXPECT_EQ(steps[i].index, static_cast<int>(i));
    EXPECT_EQ(steps[i].foot, Foot::Left);
    EXPECT_EQ(steps[i].status, StepStatus::Ok);
    EXPECT_EQ(steps[i].heel_strike_frame, analytic_heel_strike(bumps[i]));
    EXPECT_EQ(steps[i].toe_off_frame, analytic_toe_off(bumps[i]));
    EXPECT_DOUBLE_EQ(steps[i].t_heel_strike_s,
                     0.01 * static_cast<double>(analytic_heel_strike(bumps[i])));
    EXPECT_DOUBLE_EQ(steps[i].t_toe_off_s, 0.01 * static_cast<double>(analytic_toe_off(bumps[i])));
    EXPECT_EQ(steps[i].stance.size(), static_cast<std::size_t>(analytic_toe_off(bumps[i]) -
                                                               analytic_heel_strike(bumps[i]) + 1));
    // The swing bias is 54 bits plus the mean noise of 5 frames: -3.2 or +1.6 bits.
    EXPECT_NEAR(steps[i].bias_bits, 54.0, 3.3);
    // Frames 29-31 of a bump carry 16 x round(2000 sin(.) / 16) = 2000 bits, one of them with
    // +16 bits of noise; less the bias error.
    EXPECT_NEAR(steps[i].max_summed_bits, 2016.0, 3.3);
    EXPECT_NEAR(steps[i].adaptive_threshold_bits, 4.032, 0.007);
    EXPECT_NEAR(steps[i].peak_force_n, 2016.0 * kNewtonsPerBit, 3.3 * kNewtonsPerBit);
  }
}

TEST(StepSegmenter, PartialStepsAtTheStartAndTheEndAreIncomplete) {
  // The recording starts at the peak of one stance and ends 19 frames into another.
  const std::vector<Bump> bumps = walking(-30, 5);
  const std::vector<Step> steps = segment(make_frames(390, bumps, noise));
  ASSERT_EQ(steps.size(), 5U);
  EXPECT_EQ(steps[0].status, StepStatus::Incomplete);
  EXPECT_EQ(steps[0].heel_strike_frame, 0);
  EXPECT_EQ(steps[0].toe_off_frame, analytic_toe_off(bumps[0]));
  EXPECT_EQ(steps[0].toe_off_frame, 28);
  for (std::size_t i = 1; i < 4; ++i) {
    SCOPED_TRACE("step " + std::to_string(i));
    EXPECT_EQ(steps[i].status, StepStatus::Ok);
    EXPECT_EQ(steps[i].heel_strike_frame, analytic_heel_strike(bumps[i]));
    EXPECT_EQ(steps[i].toe_off_frame, analytic_toe_off(bumps[i]));
  }
  EXPECT_EQ(steps[4].status, StepStatus::Incomplete);
  EXPECT_EQ(steps[4].heel_strike_frame, analytic_heel_strike(bumps[4]));
  EXPECT_EQ(steps[4].heel_strike_frame, 372);
  EXPECT_EQ(steps[4].toe_off_frame, 389);  // still loaded on the last frame
  EXPECT_EQ(steps[4].stance.size(), 18U);
  for (std::size_t i = 0; i < steps.size(); ++i) EXPECT_EQ(steps[i].index, static_cast<int>(i));
}

TEST(StepSegmenter, AContactInTheFirstFewFramesIsIncomplete) {
  // Three swing frames before the first contact: fewer than debounce_frames.
  const std::vector<Bump> bumps{{1, 60, 2000.0}, {101, 60, 2000.0}};
  const std::vector<Step> steps = segment(make_frames(200, bumps));
  ASSERT_EQ(steps.size(), 2U);
  EXPECT_EQ(steps[0].heel_strike_frame, 3);
  EXPECT_EQ(steps[0].status, StepStatus::Incomplete);
  EXPECT_EQ(steps[1].status, StepStatus::Ok);
}

TEST(StepSegmenter, ZeroingRemovesAConstantBias) {
  const std::vector<Bump> bumps = walking(50, 3);
  const std::vector<Step> steps = segment(make_frames(360, bumps));
  ASSERT_EQ(steps.size(), 3U);
  for (const Step& step : steps) {
    ASSERT_EQ(step.status, StepStatus::Ok);
    ASSERT_EQ(step.sensor_zero_bits.size(), kSensors);
    for (std::size_t s = 0; s < kSensors; ++s) EXPECT_EQ(step.sensor_zero_bits[s], kBias[s]);
    EXPECT_EQ(step.bias_bits, 54.0);
    // The peak: 16 sensors x round(125 sin(pi/2)) = 2000 bits; 0.2 % of it is 4 bits.
    EXPECT_EQ(step.max_summed_bits, 2000.0);
    EXPECT_EQ(step.adaptive_threshold_bits, 4.0);
    EXPECT_DOUBLE_EQ(step.peak_force_n, 2000.0 * 64.0 / 255.0 * 1.125);
    std::vector<double> out(kSensors);
    for (const Frame& frame : step.stance) {
      zero_and_threshold(frame.bits, step.sensor_zero_bits, step.adaptive_threshold_bits, out);
      const auto k = static_cast<std::int64_t>(std::lround(frame.t_s * 100.0));
      const double expected_load = static_cast<double>(
          std::lround(bump_total(bumps[static_cast<std::size_t>(step.index)], k) / 16.0));
      for (std::size_t s = 0; s < kSensors; ++s) {
        EXPECT_EQ(out[s], s < kLoaded ? expected_load : 0.0) << "frame " << k << " sensor " << s;
      }
    }
  }
}

TEST(StepSegmenter, ZeroingRemovesANoisyBiasBelowTheThreshold) {
  const std::vector<Bump> bumps = walking(50, 3);
  const std::vector<Step> steps = segment(make_frames(360, bumps, noise));
  ASSERT_EQ(steps.size(), 3U);
  for (const Step& step : steps) {
    for (std::size_t s = 0; s < kSensors; ++s) EXPECT_NEAR(step.sensor_zero_bits[s], kBias[s], 1.0);
    std::vector<double> out(kSensors);
    for (const Frame& frame : step.stance) {
      zero_and_threshold(frame.bits, step.sensor_zero_bits, step.adaptive_threshold_bits, out);
      for (std::size_t s = kLoaded; s < kSensors; ++s) EXPECT_EQ(out[s], 0.0);
    }
  }
}

TEST(AdaptiveThreshold, IsNeverBelowItsFloor) {
  EXPECT_DOUBLE_EQ(adaptive_threshold_bits(2500.0, 0.2, 7.0), 7.0);
  EXPECT_DOUBLE_EQ(adaptive_threshold_bits(2500.0, 0.2, 3.0), 5.0);
  EXPECT_DOUBLE_EQ(adaptive_threshold_bits(-40.0, 0.2, -1.0), 0.0);
}

std::vector<Step> segment_with(const SegmentationSettings& settings,
                               const std::vector<Frame>& frames) {
  StepSegmenter segmenter(Foot::Left, kSensors, settings, 0.2, kNewtonsPerBit, {});
  std::vector<Step> steps;
  for (const Frame& f : frames) segmenter.push(f, steps);
  segmenter.finish(steps);
  return steps;
}

TEST(StepSegmenter, TheThresholdStaysAboveTheNoiseOfTheSwingWindows) {
  // A light load (300 summed bits: 0.2 % of it is 0.6 bits) and every sensor reading one bit
  // more in every fifth frame. A window of 5 frames holds one such frame: a mean of 0.2 and
  // squared deviations 0.64 + 4 x 0.04 = 0.8, a variance of 0.8 / 4 bits^2. Zeroed, a sensor
  // reads 0.8 bits in that frame: over the seed's threshold, under the floor.
  std::vector<Bump> bumps;
  for (int i = 0; i < 3; ++i) bumps.push_back({50 + 100 * i, 60, 300.0});
  const auto fifth = [](std::int64_t k, std::size_t) { return k % 5 == 0 ? 1 : 0; };
  const std::vector<Frame> frames = make_frames(360, bumps, fifth);
  const double sd = std::sqrt(0.8 / 4.0);
  SegmentationSettings settings = seed_settings();
  ASSERT_EQ(settings.threshold_noise_sds, 4.0);
  const std::vector<Step> floored = segment_with(settings, frames);
  settings.threshold_noise_sds = 0.0;
  const std::vector<Step> seed_rule = segment_with(settings, frames);
  ASSERT_EQ(floored.size(), 3U);
  ASSERT_EQ(seed_rule.size(), 3U);
  // Sensors that read only noise, counted as loaded in a stance frame.
  const auto noise_taken_for_load = [](const Step& step) {
    int count = 0;
    std::vector<double> out(kSensors);
    for (const Frame& frame : step.stance) {
      zero_and_threshold(frame.bits, step.sensor_zero_bits, step.adaptive_threshold_bits, out);
      for (std::size_t s = kLoaded; s < kSensors; ++s) count += out[s] > 0.0;
    }
    return count;
  };
  for (std::size_t i = 0; i < floored.size(); ++i) {
    SCOPED_TRACE("step " + std::to_string(i));
    ASSERT_EQ(floored[i].status, StepStatus::Ok);
    EXPECT_DOUBLE_EQ(floored[i].zero_noise_sd_bits, sd);
    EXPECT_DOUBLE_EQ(floored[i].threshold_floor_bits, 4.0 * sd);
    EXPECT_DOUBLE_EQ(floored[i].adaptive_threshold_bits, 4.0 * sd);
    EXPECT_DOUBLE_EQ(seed_rule[i].zero_noise_sd_bits, sd);
    EXPECT_EQ(seed_rule[i].threshold_floor_bits, 0.0);
    EXPECT_DOUBLE_EQ(seed_rule[i].adaptive_threshold_bits,
                     0.2 * seed_rule[i].max_summed_bits / 100.0);
    EXPECT_LT(seed_rule[i].adaptive_threshold_bits, 0.8);
    EXPECT_EQ(noise_taken_for_load(floored[i]), 0);
    EXPECT_GT(noise_taken_for_load(seed_rule[i]), 0);
  }
}

TEST(StepSegmenter, TheNoiseIsTheQuieterWindows) {
  // Every sensor reads one bit more in every other frame, before or from frame 215, in the swing
  // after the second step (toe off 208, next heel strike 252): the second step's window before
  // it is the noisy one, or the one after. In 5 frames a sensor reads 1 in two or three:
  // squared deviations 1.2 either way, a variance of 1.2 / 4 bits^2.
  const std::vector<Bump> bumps = walking(50, 3);
  const double sd = std::sqrt(1.2 / 4.0);
  for (const bool before : {true, false}) {
    SCOPED_TRACE(before ? "noise before frame 215" : "noise from frame 215");
    const auto noise = [before](std::int64_t k, std::size_t) {
      return (k < 215) == before ? static_cast<int>(k % 2) : 0;
    };
    const std::vector<Step> steps = segment(make_frames(360, bumps, noise));
    ASSERT_EQ(steps.size(), 3U);
    EXPECT_DOUBLE_EQ(steps[0].zero_noise_sd_bits, before ? sd : 0.0);
    EXPECT_EQ(steps[1].zero_noise_sd_bits, 0.0);
    EXPECT_DOUBLE_EQ(steps[2].zero_noise_sd_bits, before ? 0.0 : sd);
  }
}

TEST(StepSegmenter, NoiseOnAMinorityOfSensorsCounts) {
  // 10 of the 24 sensors read one bit more in every other frame, the others a steady reading: the
  // median sensor does not vary, and the noisy ones are kept all the same (their squared
  // deviations, 1.2 in a window, are within 25 times the rounding's 4 / 12). Pooled over all 24:
  // 10 x 1.2 / (24 x 4) bits^2.
  const std::vector<Bump> bumps = walking(50, 3);
  const auto noise = [](std::int64_t k, std::size_t s) {
    return s % 12 < 5 ? static_cast<int>(k % 2) : 0;
  };
  const std::vector<Step> steps = segment(make_frames(360, bumps, noise));
  ASSERT_EQ(steps.size(), 3U);
  for (const Step& step : steps) {
    EXPECT_DOUBLE_EQ(step.zero_noise_sd_bits, std::sqrt(10.0 * 1.2 / (24.0 * 4.0)));
  }
}

TEST(StepSegmenter, AFlickeringSensorIsNotTakenForNoise) {
  // As above, every sensor one bit more in every other frame; one unloaded sensor 50 bits more.
  const std::vector<Bump> bumps = walking(50, 3);
  const auto noise = [](std::int64_t k, std::size_t s) {
    return static_cast<int>(k % 2) * (s == 20 ? 50 : 1);
  };
  const std::vector<Step> steps = segment(make_frames(360, bumps, noise));
  ASSERT_EQ(steps.size(), 3U);
  for (const Step& step : steps) EXPECT_DOUBLE_EQ(step.zero_noise_sd_bits, std::sqrt(1.2 / 4.0));
}

TEST(StepSegmenter, AZeroThatMovesBetweenTheWindowsIsNoNoise) {
  // Every sensor reads 1 bit more from frame 215 on, between the second step's two windows: each
  // window is steady, so no step sees noise and each keeps the seed's threshold.
  const std::vector<Bump> bumps = walking(50, 3);
  const auto shift = [](std::int64_t k, std::size_t) { return k >= 215 ? 1 : 0; };
  const std::vector<Step> steps = segment(make_frames(360, bumps, shift));
  ASSERT_EQ(steps.size(), 3U);
  for (const Step& step : steps) {
    EXPECT_EQ(step.zero_noise_sd_bits, 0.0);
    EXPECT_DOUBLE_EQ(step.adaptive_threshold_bits, 0.2 * step.max_summed_bits / 100.0);
  }
}

TEST(StepSegmenter, TheBiasIsTheMeanOfThePreAndPostSwingBiases) {
  // Every sensor reads 1 bit more from frame 215 on, in the swing after the second step (toe off
  // 208, next heel strike 252): the second step's pre-swing bias is 54 and its post-swing 78.
  const std::vector<Bump> bumps = walking(50, 3);
  const auto shift = [](std::int64_t k, std::size_t) { return k >= 215 ? 1 : 0; };
  const std::vector<Step> steps = segment(make_frames(360, bumps, shift));
  ASSERT_EQ(steps.size(), 3U);
  EXPECT_EQ(steps[0].bias_bits, 54.0);
  EXPECT_EQ(steps[1].bias_bits, 66.0);
  EXPECT_EQ(steps[2].bias_bits, 78.0);
  for (std::size_t s = 0; s < kSensors; ++s) {
    EXPECT_EQ(steps[1].sensor_zero_bits[s], kBias[s] + 0.5);
  }
  // The windows are centred on the swings' middle frames: 130 (frames 109-151, between the
  // first toe off and the second heel strike) and 230 (209-251), 10 ms apart.
  EXPECT_NEAR(steps[1].pre_zero_t_s, 1.30, 1e-9);
  EXPECT_NEAR(steps[1].post_zero_t_s, 2.30, 1e-9);
  EXPECT_NEAR(steps[2].pre_zero_t_s, steps[1].post_zero_t_s, 1e-9);
  for (const Step& s : steps) {
    EXPECT_LT(s.pre_zero_t_s, s.t_heel_strike_s);
    EXPECT_GT(s.post_zero_t_s, s.t_toe_off_s);
  }
}

TEST(StepSegmenter, BoundariesUseTheSwingFloorWhenTheSwingMidpointIsLoaded) {
  // The middle of every swing carries 8 bits on each loaded sensor (128 summed, under the
  // 142-bit threshold), as when a foot shuffles: the seed's midpoint bias of the middle step is
  // 54 + 128 = 182 bits, while the unloaded insole reads 54.
  const std::vector<Bump> bumps = walking(50, 3);
  const auto shuffle = [](std::int64_t k, std::size_t s) {
    const bool loaded_swing =
        (k >= 118 && k <= 142) || (k >= 218 && k <= 242) || (k >= 318 && k <= 350);
    return loaded_swing && s < kLoaded ? 8 : 0;
  };
  const std::vector<Step> steps = segment(make_frames(360, bumps, shuffle));
  ASSERT_EQ(steps.size(), 3U);
  for (std::size_t i = 0; i < 3; ++i) {
    SCOPED_TRACE("step " + std::to_string(i));
    EXPECT_EQ(steps[i].status, StepStatus::Ok);
    EXPECT_EQ(steps[i].heel_strike_frame, analytic_heel_strike(bumps[i]));
    EXPECT_EQ(steps[i].toe_off_frame, analytic_toe_off(bumps[i]));
  }
  // Against 182 bits the middle step would start a frame later: at 152 the summed bits are
  // 54 + 16 x round(2000 sin(2 pi / 60) / 16) = 262, only 80 above 182.
  EXPECT_EQ(analytic_heel_strike(bumps[1]), 152);
  EXPECT_EQ(steps[0].bias_bits, 118.0);  // (54 + 182) / 2
  EXPECT_EQ(steps[1].bias_bits, 182.0);
  EXPECT_EQ(steps[1].max_summed_bits, 2000.0 - 128.0);
}

TEST(StepSegmenter, AWeightShiftWhileStandingAtTheStartIsNotASwing) {
  // Standing at 2000 bits on frames 0..99 with a dip to 1280 on frames 30..49, then walking.
  // Against the running minimum during the dip, the stance would split in two around a
  // "swing"; that dip does not fall to half the load before it, so it is not one.
  const std::vector<Bump> bumps{{150, 60, 2000.0}, {250, 60, 2000.0}};
  const auto standing = [](std::int64_t k, std::size_t s) {
    if (k > 99 || s >= kLoaded) return 0;
    return k >= 30 && k <= 49 ? 80 : 125;
  };
  const std::vector<Step> steps = segment(make_frames(360, bumps, standing));
  ASSERT_EQ(steps.size(), 3U);
  EXPECT_EQ(steps[0].status, StepStatus::Incomplete);
  EXPECT_EQ(steps[0].heel_strike_frame, 0);
  EXPECT_EQ(steps[0].toe_off_frame, 99);
  for (std::size_t i = 1; i < 3; ++i) {
    EXPECT_EQ(steps[i].status, StepStatus::Ok);
    EXPECT_EQ(steps[i].heel_strike_frame, analytic_heel_strike(bumps[i - 1]));
    EXPECT_EQ(steps[i].toe_off_frame, analytic_toe_off(bumps[i - 1]));
  }
}

// The segmenter has one algorithm, fed a frame at a time; what is tested here is when a step
// comes out and that the output does not depend on how the calls group the frames.
TEST(StepSegmenter, StepsComeOutAtTheNextConfirmedContactAndNeverChange) {
  const std::vector<Bump> bumps = walking(-30, 9);
  const std::vector<Frame> frames = make_frames(880, bumps, noise);
  const std::vector<Step> batch = segment(frames);
  ASSERT_EQ(batch.size(), 9U);
  // The reference is the bumps' own crossings; the first contact began before the recording.
  EXPECT_EQ(batch[0].status, StepStatus::Incomplete);
  for (std::size_t i = 1; i < batch.size(); ++i) {
    EXPECT_EQ(batch[i].status, StepStatus::Ok) << "step " << i;
    EXPECT_EQ(batch[i].heel_strike_frame, analytic_heel_strike(bumps[i])) << "step " << i;
    EXPECT_EQ(batch[i].toe_off_frame, analytic_toe_off(bumps[i])) << "step " << i;
  }

  // Frame by frame, noting when each step comes out.
  StepSegmenter live(Foot::Left, kSensors, seed_settings(), 0.2, kNewtonsPerBit);
  std::vector<Step> online;
  std::vector<std::int64_t> emitted_at;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    live.push(frames[k], online);
    emitted_at.resize(online.size(), static_cast<std::int64_t>(k));
  }
  const std::size_t before_finish = online.size();
  live.finish(online);
  ASSERT_EQ(online.size(), batch.size());
  for (std::size_t i = 0; i < batch.size(); ++i) expect_same(online[i], batch[i]);
  // Each step but the last comes out when the next contact is confirmed: debounce_frames - 1
  // frames after the next heel strike.
  ASSERT_EQ(before_finish, batch.size() - 1);
  for (std::size_t i = 0; i + 1 < batch.size(); ++i) {
    EXPECT_EQ(emitted_at[i], analytic_heel_strike(bumps[i + 1]) + 4) << "step " << i;
  }

  // Chunks of varying sizes, and a recording cut short: steps already out never change.
  StepSegmenter chunked(Foot::Left, kSensors, seed_settings(), 0.2, kNewtonsPerBit);
  std::vector<Step> out;
  std::size_t k = 0;
  for (std::size_t chunk = 1; k < frames.size(); chunk = chunk % 37 + 7) {
    std::vector<Step> got;
    for (std::size_t end = std::min(frames.size(), k + chunk); k < end; ++k) {
      chunked.push(frames[k], got);
    }
    out.insert(out.end(), got.begin(), got.end());
  }
  chunked.finish(out);
  ASSERT_EQ(out.size(), batch.size());
  for (std::size_t i = 0; i < batch.size(); ++i) expect_same(out[i], batch[i]);

  StepSegmenter cut(Foot::Left, kSensors, seed_settings(), 0.2, kNewtonsPerBit);
  std::vector<Step> partial;
  for (std::size_t j = 0; j < 500; ++j) cut.push(frames[j], partial);
  ASSERT_EQ(partial.size(), 5U);  // the 6th heel strike, 472, is confirmed at frame 476
  for (std::size_t i = 0; i < partial.size(); ++i) expect_same(partial[i], batch[i]);
}

TEST(StepSegmenter, AContactLongerThanTheLimitIsIncompleteAndTheNextStepsAreFine) {
  // Standing on frames 150..449 (2000 bits) between walking steps, with a 100-frame limit.
  const std::vector<Bump> bumps{{50, 60, 2000.0}, {490, 60, 2000.0}, {590, 60, 2000.0}};
  const auto standing = [](std::int64_t k, std::size_t s) {
    return noise(k, s) + (k >= 150 && k <= 449 && s < kLoaded ? 125 : 0);
  };
  SegmenterLimits limits;
  limits.max_stance_frames = 100;
  limits.max_swing_half_frames = 20;
  StepSegmenter segmenter(Foot::Left, kSensors, seed_settings(), 0.2, kNewtonsPerBit, limits);
  std::vector<Step> steps;
  std::size_t most_held = 0;
  for (const Frame& f : make_frames(700, bumps, standing)) {
    segmenter.push(f, steps);
    most_held = std::max(most_held, segmenter.buffered_frames());
  }
  segmenter.finish(steps);
  // At most H frames before a heel strike, the capped stance, 2 H + 1 swing frames and two
  // debounce runs: 20 + 100 + 41 + 10, well under the 300 frames of standing.
  EXPECT_LE(most_held, 171U);
  ASSERT_EQ(steps.size(), 4U);
  EXPECT_EQ(steps[0].status, StepStatus::Ok);
  EXPECT_EQ(steps[0].heel_strike_frame, analytic_heel_strike(bumps[0]));
  EXPECT_EQ(steps[0].toe_off_frame, analytic_toe_off(bumps[0]));
  EXPECT_EQ(steps[1].status, StepStatus::Incomplete);
  EXPECT_EQ(steps[1].heel_strike_frame, 150);
  EXPECT_EQ(steps[1].toe_off_frame, 249);
  EXPECT_EQ(steps[1].stance.size(), 100U);
  for (std::size_t i : {2U, 3U}) {
    SCOPED_TRACE("step " + std::to_string(i));
    EXPECT_EQ(steps[i].status, StepStatus::Ok);
    EXPECT_EQ(steps[i].index, static_cast<int>(i));
    EXPECT_EQ(steps[i].heel_strike_frame, analytic_heel_strike(bumps[i - 1]));
    EXPECT_EQ(steps[i].toe_off_frame, analytic_toe_off(bumps[i - 1]));
  }
}

TEST(StepSegmenter, ALongPauseFinalisesTheStepBeforeTheNextContact) {
  // 1000 swing frames between two steps; H = 150, so the step before the pause is final once
  // 2 H + 1 swing frames are seen: at frame toe_off + 1 + 300.
  const std::vector<Bump> bumps{{50, 60, 2000.0}, {1110, 60, 2000.0}};
  const std::vector<Frame> frames = make_frames(1250, bumps, noise);
  StepSegmenter segmenter(Foot::Left, kSensors, seed_settings(), 0.2, kNewtonsPerBit);
  std::vector<Step> steps;
  std::int64_t first_out = -1;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    segmenter.push(frames[k], steps);
    if (first_out < 0 && !steps.empty()) first_out = static_cast<std::int64_t>(k);
  }
  segmenter.finish(steps);
  ASSERT_EQ(steps.size(), 2U);
  EXPECT_EQ(first_out, analytic_toe_off(bumps[0]) + 1 + 300);
  for (std::size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(steps[i].status, StepStatus::Ok);
    EXPECT_EQ(steps[i].heel_strike_frame, analytic_heel_strike(bumps[i]));
    EXPECT_EQ(steps[i].toe_off_frame, analytic_toe_off(bumps[i]));
  }
}

TEST(StepSegmenter, ABaselineThatRisesFasterThanTheFloorFollowsIsFound) {
  // From frame 225, in the swing after the second step (toe off 208, next heel strike 252), every
  // loaded sensor reads 10 bits more: the swings read 54 + 160 summed bits, 160 above the floor
  // learnt so far and so above the 142-bit threshold. The floor follows only over ~10 swings, so
  // without the watch for missed swings every contact from frame 225 on would merge into one.
  const std::vector<Bump> bumps = walking(50, 6);
  const auto rise = [](std::int64_t k, std::size_t s) {
    return noise(k, s) + (k >= 225 && s < kLoaded ? 10 : 0);
  };
  const std::vector<Step> steps = segment(make_frames(700, bumps, rise));
  ASSERT_EQ(steps.size(), bumps.size());
  for (std::size_t i = 0; i < steps.size(); ++i) {
    SCOPED_TRACE("step " + std::to_string(i));
    // The frames 225..251, above the old floor, were no contact against the new one: the step
    // that starts at 252 takes their place and index.
    EXPECT_EQ(steps[i].index, static_cast<int>(i));
    EXPECT_EQ(steps[i].status, StepStatus::Ok);
    EXPECT_EQ(steps[i].heel_strike_frame, analytic_heel_strike(bumps[i]));
    EXPECT_EQ(steps[i].toe_off_frame, analytic_toe_off(bumps[i]));
    // The zero follows the baseline: 54 bits before the rise and 214 after it, each within the
    // 5-frame noise (at most 3.2 bits).
    EXPECT_NEAR(steps[i].bias_bits, i < 2 ? 54.0 : 214.0, 3.3);
    EXPECT_NEAR(steps[i].max_summed_bits, 2016.0, 3.3);
  }
}

TEST(StepSegmenter, AContactThatTheRaisedFloorDoesNotConfirmIsForgotten) {
  // The baseline rises by 160 summed bits at frame 225 as above, but the only load after it is a
  // 3-frame spike of 800 bits, then nothing for 475 frames. Against the old floor frames 225 on
  // are one contact; once the dip after the spike has lasted 2 H + 1 frames it raises the floor,
  // and against that floor the spike is shorter than the debounce: no contact, no step.
  const std::vector<Bump> bumps = walking(50, 2);
  const auto rise = [](std::int64_t k, std::size_t s) {
    if (s >= kLoaded || k < 225) return 0;
    return k >= 240 && k <= 242 ? 60 : 10;
  };
  const std::vector<Step> steps = segment(make_frames(700, bumps, rise));
  ASSERT_EQ(steps.size(), 2U);
  for (std::size_t i = 0; i < steps.size(); ++i) {
    EXPECT_EQ(steps[i].index, static_cast<int>(i));
    EXPECT_EQ(steps[i].status, StepStatus::Ok);
    EXPECT_EQ(steps[i].heel_strike_frame, analytic_heel_strike(bumps[i]));
    EXPECT_EQ(steps[i].toe_off_frame, analytic_toe_off(bumps[i]));
  }
}

TEST(StepSegmenter, ASensorThatCreepsUnderLoadDoesNotMergeTheSteps) {
  // A reading that creeps: each loaded sensor adds 40 % of its load low-passed with a 0.5-s time
  // constant, so the swings bottom out 152-168 summed bits above the quiet start of the
  // recording. Against the floor learnt there, the contacts would merge.
  std::vector<Bump> bumps;
  for (int i = 0; i < 10; ++i) bumps.push_back({60 + 110 * i, 68, 2000.0});
  std::vector<Frame> frames = make_frames(1200, bumps, noise);
  std::vector<double> lag(kLoaded, 0.0);
  const double keep = std::exp(-0.01 / 0.5);
  for (std::size_t k = 0; k < frames.size(); ++k) {
    for (std::size_t s = 0; s < kLoaded; ++s) {
      const double load = frames[k].bits[s] - kBias[s];
      lag[s] = lag[s] * keep + load * (1.0 - keep);
      frames[k].bits[s] = static_cast<std::uint8_t>(
          std::clamp(std::lround(frames[k].bits[s] + 0.4 * lag[s]), 0L, 255L));
    }
  }
  const std::vector<Step> steps = segment(frames);
  ASSERT_EQ(steps.size(), bumps.size());
  for (std::size_t i = 0; i < steps.size(); ++i) {
    SCOPED_TRACE("step " + std::to_string(i));
    EXPECT_EQ(steps[i].status, StepStatus::Ok);
    // The first contact, classified again against the raised floor, starts up to 2 frames after
    // the bump's crossing; the creep then rises with the load and the later ones start on it.
    EXPECT_GE(steps[i].heel_strike_frame, analytic_heel_strike(bumps[i]));
    EXPECT_LE(steps[i].heel_strike_frame, analytic_heel_strike(bumps[i]) + 2);
    // The creep's tail keeps the reading above the raised floor for up to 19 frames after the
    // bump has ended, inside the 42-frame swing.
    EXPECT_GE(steps[i].toe_off_frame, analytic_toe_off(bumps[i]));
    EXPECT_LE(steps[i].toe_off_frame, analytic_toe_off(bumps[i]) + 20);
  }
}

TEST(StepSegmenter, AMidStanceValleyAboveAQuarterOfThePeakIsNotASwing) {
  // Two humps of 2000 bits per stance joined by a plateau of 608 summed bits (30 % of the peak):
  // the load stays below half the peak for about 25 frames, longer than the shortest swing, but
  // does not fall to a quarter of it.
  std::vector<Bump> bumps;
  for (int i = 0; i < 4; ++i) {
    bumps.push_back({50 + 150 * i, 40, 2000.0});
    bumps.push_back({50 + 150 * i + 60, 40, 2000.0});
  }
  const auto plateau = [](std::int64_t k, std::size_t s) {
    const std::int64_t in_stride = (k - 50) % 150;
    return s < kLoaded && k >= 50 && k < 650 && in_stride >= 30 && in_stride < 70 ? 38 : 0;
  };
  const std::vector<Step> steps = segment(make_frames(700, bumps, plateau));
  ASSERT_EQ(steps.size(), 4U);
  for (std::size_t i = 0; i < steps.size(); ++i) {
    SCOPED_TRACE("step " + std::to_string(i));
    EXPECT_EQ(steps[i].status, StepStatus::Ok);
    EXPECT_EQ(steps[i].heel_strike_frame, analytic_heel_strike(bumps[2 * i]));
    EXPECT_EQ(steps[i].toe_off_frame, analytic_toe_off(bumps[2 * i + 1]));
  }
}

/// The frames from `from` on, `seconds` later: a gap before frame `from`.
std::vector<Frame> with_gap(std::vector<Frame> frames, std::size_t from, double seconds) {
  for (std::size_t k = from; k < frames.size(); ++k) frames[k].t_s += seconds;
  return frames;
}

TEST(StepSegmenter, AGapInsideAContactEndsItAsIncompleteAndNumbersOn) {
  // Bump 2's contact is frames 252..308; 100 s pass between frames 280 and 281.
  const std::vector<Bump> bumps = walking(50, 5);
  const std::vector<Frame> frames = with_gap(make_frames(560, bumps, noise), 281, 100.0);
  StepSegmenter segmenter(Foot::Left, kSensors, seed_settings(), 0.2, kNewtonsPerBit);
  std::vector<Step> steps;
  for (const Frame& f : frames) segmenter.push(f, steps);
  EXPECT_EQ(segmenter.gaps(), 1);
  segmenter.finish(steps);
  EXPECT_EQ(segmenter.frames(), 560);

  ASSERT_EQ(steps.size(), 6U);
  for (std::size_t i = 0; i < steps.size(); ++i) EXPECT_EQ(steps[i].index, static_cast<int>(i));
  // Before the gap: the steps of bumps 0 and 1, then bump 2's contact open at the gap.
  for (std::size_t i = 0; i < 2; ++i) {
    SCOPED_TRACE("step " + std::to_string(i));
    EXPECT_EQ(steps[i].status, StepStatus::Ok);
    EXPECT_EQ(steps[i].heel_strike_frame, analytic_heel_strike(bumps[i]));
    EXPECT_EQ(steps[i].toe_off_frame, analytic_toe_off(bumps[i]));
    EXPECT_NEAR(steps[i].bias_bits, 54.0, 3.3);
  }
  EXPECT_EQ(steps[2].status, StepStatus::Incomplete);
  EXPECT_EQ(steps[2].heel_strike_frame, 252);
  EXPECT_EQ(steps[2].toe_off_frame, 280);
  EXPECT_DOUBLE_EQ(steps[2].t_toe_off_s, 2.80);
  // After it: the rest of that contact, as at the start of a recording, then bumps 3 and 4.
  EXPECT_EQ(steps[3].status, StepStatus::Incomplete);
  EXPECT_EQ(steps[3].heel_strike_frame, 281);
  EXPECT_EQ(steps[3].toe_off_frame, 308);
  EXPECT_DOUBLE_EQ(steps[3].t_heel_strike_s, 102.81);
  for (std::size_t i = 4; i < 6; ++i) {
    SCOPED_TRACE("step " + std::to_string(i));
    const Bump& bump = bumps[i - 1];
    EXPECT_EQ(steps[i].status, StepStatus::Ok);
    EXPECT_EQ(steps[i].heel_strike_frame, analytic_heel_strike(bump));
    EXPECT_EQ(steps[i].toe_off_frame, analytic_toe_off(bump));
    EXPECT_DOUBLE_EQ(steps[i].t_heel_strike_s,
                     100.0 + 0.01 * static_cast<double>(analytic_heel_strike(bump)));
    EXPECT_NEAR(steps[i].bias_bits, 54.0, 3.3);
  }
}

TEST(StepSegmenter, AGapInsideASwingLosesNoStep) {
  // The swing between bumps 1 and 2 is frames 209..251; 30 s pass between frames 230 and 231.
  const std::vector<Bump> bumps = walking(50, 5);
  const std::vector<Frame> frames = with_gap(make_frames(560, bumps, noise), 231, 30.0);
  StepSegmenter segmenter(Foot::Left, kSensors, seed_settings(), 0.2, kNewtonsPerBit);
  std::vector<Step> steps;
  for (const Frame& f : frames) segmenter.push(f, steps);
  segmenter.finish(steps);
  EXPECT_EQ(segmenter.gaps(), 1);

  ASSERT_EQ(steps.size(), bumps.size());
  for (std::size_t i = 0; i < steps.size(); ++i) {
    SCOPED_TRACE("step " + std::to_string(i));
    EXPECT_EQ(steps[i].index, static_cast<int>(i));
    EXPECT_EQ(steps[i].status, StepStatus::Ok);
    EXPECT_EQ(steps[i].heel_strike_frame, analytic_heel_strike(bumps[i]));
    EXPECT_EQ(steps[i].toe_off_frame, analytic_toe_off(bumps[i]));
    EXPECT_NEAR(steps[i].bias_bits, 54.0, 3.3);
  }
  // Step 1's post-swing window and step 2's pre-swing one lie each on its own side of the gap.
  EXPECT_LT(steps[1].post_zero_t_s, 2.31);
  EXPECT_GT(steps[2].pre_zero_t_s, 32.30);
}

TEST(StepSegmenter, FourLostFramesAreBridgedAndFiveAreAGap) {
  // Frames lost inside bump 2's contact (frames 252..308), with the default max_gap_s.
  const std::vector<Bump> bumps = walking(50, 5);
  const std::vector<Frame> all = make_frames(560, bumps, noise);
  for (const std::ptrdiff_t lost : {4, 5}) {
    SCOPED_TRACE(std::to_string(lost) + " frames lost");
    std::vector<Frame> frames = all;
    frames.erase(frames.begin() + 281, frames.begin() + 281 + lost);
    StepSegmenter segmenter(Foot::Left, kSensors, seed_settings(), 0.2, kNewtonsPerBit);
    std::vector<Step> steps;
    for (const Frame& f : frames) segmenter.push(f, steps);
    segmenter.finish(steps);
    EXPECT_EQ(segmenter.gaps(), lost == 4 ? 0 : 1);
    EXPECT_EQ(steps.size(), lost == 4 ? 5U : 6U);
    const auto ok = std::count_if(steps.begin(), steps.end(),
                                  [](const Step& s) { return s.status == StepStatus::Ok; });
    // Cut, bump 2 gives two incomplete steps.
    EXPECT_EQ(ok, lost == 4 ? 5 : 4);
  }
}

TEST(StepSegmenter, NoContactsNoSteps) {
  EXPECT_TRUE(segment(make_frames(300, {}, noise)).empty());
  EXPECT_TRUE(segment({}).empty());
}

TEST(StepSegmenter, RejectsMisuse) {
  EXPECT_THROW(StepSegmenter(Foot::Left, 0, seed_settings(), 0.2, kNewtonsPerBit),
               std::invalid_argument);
  EXPECT_THROW(StepSegmenter(Foot::Left, kSensors, {142, 0, 5}, 0.2, kNewtonsPerBit),
               std::invalid_argument);
  EXPECT_THROW(StepSegmenter(Foot::Left, kSensors, seed_settings(), 120.0, kNewtonsPerBit),
               std::invalid_argument);
  EXPECT_THROW(StepSegmenter(Foot::Left, kSensors, {142, 5, 5, 0.0}, 0.2, kNewtonsPerBit),
               std::invalid_argument);
  for (double sds : {-0.5, 20.5, std::nan("")}) {
    EXPECT_THROW(StepSegmenter(Foot::Left, kSensors, {142, 5, 5, 0.055, sds}, 0.2, kNewtonsPerBit),
                 std::invalid_argument)
        << sds;
  }
  // Under 1.5 sample periods a steady stream would be cut at every frame: at 10 Hz, 0.15 s.
  SegmenterLimits slow;
  slow.sample_period_s = 0.1;
  EXPECT_THROW(StepSegmenter(Foot::Left, kSensors, {142, 5, 5, 0.149}, 0.2, kNewtonsPerBit, slow),
               std::invalid_argument);
  EXPECT_NO_THROW(
      StepSegmenter(Foot::Left, kSensors, {142, 5, 5, 0.151}, 0.2, kNewtonsPerBit, slow));
  StepSegmenter segmenter(Foot::Left, kSensors, seed_settings(), 0.2, kNewtonsPerBit);
  std::vector<Step> steps;
  Frame frame{0.0, Foot::Right, std::vector<std::uint8_t>(kSensors, 0)};
  EXPECT_THROW(segmenter.push(frame, steps), std::invalid_argument);
  frame.foot = Foot::Left;
  frame.bits.resize(3);
  EXPECT_THROW(segmenter.push(frame, steps), std::invalid_argument);
  frame.bits.resize(kSensors);
  segmenter.push(frame, steps);
  EXPECT_THROW(segmenter.push(frame, steps), std::invalid_argument);  // same time again
  segmenter.restart(steps);
  EXPECT_THROW(segmenter.push(frame, steps), std::invalid_argument);  // time still ordered
  segmenter.finish(steps);
  frame.t_s = 1.0;
  EXPECT_THROW(segmenter.push(frame, steps), std::logic_error);
  EXPECT_THROW(segmenter.restart(steps), std::logic_error);
}

// ---- Real walking (PhysioNet gaitpdb converted to session CSV, ground truth in the sidecar) ----

struct Contact {
  std::int64_t heel_strike = 0;
  std::int64_t toe_off = 0;
  bool partial = false;
  bool atypical = false;
};

void check_recording(const std::string& name) {
  const auto dir = test::shared_dir() / "real-data" / "gaitpdb";
  const auto csv = dir / ("gaitpdb_" + name + ".csv");
  const auto sidecar = dir / ("gaitpdb_" + name + ".json");
  if (!std::filesystem::exists(csv) || !std::filesystem::exists(sidecar)) {
    GTEST_SKIP() << "real recording not found: " << csv;
  }
  std::ifstream in(sidecar);
  const auto truth = nlohmann::json::parse(in);

  SessionReader reader(csv);
  ASSERT_EQ(reader.header().insole_size, InsoleSize::S41_42);
  std::array<std::optional<StepSegmenter>, 2> segmenters;
  std::array<std::vector<Step>, 2> found;
  for (Foot foot : kFeet) {
    segmenters[static_cast<std::size_t>(foot)].emplace(foot, reader.header().sensors,
                                                       seed_settings(), 0.1, 0.28235);
  }
  Frame frame;
  while (reader.next(frame)) {
    const auto f = static_cast<std::size_t>(frame.foot);
    segmenters[f]->push(frame, found[f]);
  }
  for (Foot foot : kFeet) {
    const auto f = static_cast<std::size_t>(foot);
    segmenters[f]->finish(found[f]);
    EXPECT_EQ(segmenters[f]->gaps(), 0) << "the default max_gap_s found a gap";
  }

  for (Foot foot : kFeet) {
    SCOPED_TRACE(name + " foot " + std::string(foot_name(foot)));
    const auto& steps = found[static_cast<std::size_t>(foot)];
    std::vector<Contact> contacts;
    for (const auto& c : truth["events"][std::string(foot_name(foot))]["contacts"]) {
      contacts.push_back({c["heel_strike_frame"].get<std::int64_t>(),
                          c["toe_off_frame"].get<std::int64_t>(), c["partial"].get<bool>(),
                          c["atypical"].get<bool>()});
    }
    int typical = 0;
    int matched = 0;
    std::int64_t max_hs_error = 0;
    std::int64_t max_to_error = 0;
    for (const Contact& c : contacts) {
      if (c.partial || c.atypical) continue;
      ++typical;
      const auto match = std::find_if(steps.begin(), steps.end(), [&](const Step& s) {
        return std::abs(s.heel_strike_frame - c.heel_strike) <= 2 &&
               std::abs(s.toe_off_frame - c.toe_off) <= 2;
      });
      if (match == steps.end()) {
        ADD_FAILURE() << "no step found for the contact " << c.heel_strike << ".." << c.toe_off;
        continue;
      }
      ++matched;
      EXPECT_EQ(match->status, StepStatus::Ok) << "contact " << c.heel_strike;
      max_hs_error = std::max(max_hs_error, std::abs(match->heel_strike_frame - c.heel_strike));
      max_to_error = std::max(max_to_error, std::abs(match->toe_off_frame - c.toe_off));
    }
    int invented = 0;
    for (const Step& s : steps) {
      const bool overlaps = std::any_of(contacts.begin(), contacts.end(), [&](const Contact& c) {
        return s.heel_strike_frame <= c.toe_off && s.toe_off_frame >= c.heel_strike;
      });
      if (!overlaps) {
        ++invented;
        ADD_FAILURE() << "step " << s.index << " (" << s.heel_strike_frame << ".."
                      << s.toe_off_frame << ") matches no ground-truth contact";
      }
    }
    // Beyond the brief: every contact, partial and atypical ones too, is found once, and a step
    // is Incomplete exactly when its contact touches an end of the recording.
    EXPECT_EQ(steps.size(), contacts.size());
    for (const Contact& c : contacts) {
      const auto match = std::find_if(steps.begin(), steps.end(), [&](const Step& s) {
        return std::abs(s.heel_strike_frame - c.heel_strike) <= 2 &&
               std::abs(s.toe_off_frame - c.toe_off) <= 2;
      });
      ASSERT_NE(match, steps.end()) << "contact " << c.heel_strike << ".." << c.toe_off;
      EXPECT_EQ(match->status, c.partial ? StepStatus::Incomplete : StepStatus::Ok)
          << "contact " << c.heel_strike;
    }
    // Zeroing recovers the converter's per-cell dc bias (listed in the sidecar) in a typical
    // step; loaded swings (shuffles, turns) make some steps' zeros higher, as in the seed.
    const auto dc = truth["dc_bias_bits"][std::string(foot_name(foot))].get<std::vector<int>>();
    ASSERT_EQ(dc.size(), reader.header().sensors);
    const double dc_sum = std::accumulate(dc.begin(), dc.end(), 0.0);
    std::vector<double> bias_error;
    std::vector<double> zero_error;
    for (const Step& s : steps) {
      if (s.status != StepStatus::Ok) continue;
      double worst = 0.0;
      for (std::size_t i = 0; i < dc.size(); ++i) {
        worst = std::max(worst, std::abs(s.sensor_zero_bits[i] - dc[i]));
      }
      zero_error.push_back(worst);
      bias_error.push_back(std::abs(s.bias_bits - dc_sum));
    }
    ASSERT_FALSE(zero_error.empty());
    std::sort(zero_error.begin(), zero_error.end());
    std::sort(bias_error.begin(), bias_error.end());
    const double median_zero_error = zero_error[zero_error.size() / 2];
    const double median_bias_error = bias_error[bias_error.size() / 2];
    EXPECT_LE(median_zero_error, 0.5);
    EXPECT_LE(median_bias_error, 1.0);

    const auto ok = std::count_if(steps.begin(), steps.end(),
                                  [](const Step& s) { return s.status == StepStatus::Ok; });
    std::printf(
        "[ gaitpdb  ] %s %s: %zu steps found (%td ok) for %zu contacts; %d/%d typical matched, "
        "max error heel strike %lld, toe off %lld frames; %d invented; median step: bias - dc "
        "%.1f bits, worst sensor zero - dc %.2f bits\n",
        name.c_str(), std::string(foot_name(foot)).c_str(), steps.size(), ok, contacts.size(),
        matched, typical, static_cast<long long>(max_hs_error),
        static_cast<long long>(max_to_error), invented, median_bias_error, median_zero_error);
    EXPECT_EQ(matched, typical);
    EXPECT_GT(typical, 50);
  }
}

TEST(StepSegmenterRealData, GaCo01MatchesTheGroundTruth) {
  check_recording("GaCo01_01");
}
TEST(StepSegmenterRealData, JuPt01MatchesTheGroundTruth) {
  check_recording("JuPt01_01");
}
TEST(StepSegmenterRealData, SiCo01MatchesTheGroundTruth) {
  check_recording("SiCo01_01");
}

}  // namespace
}  // namespace gaitmon
