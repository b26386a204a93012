// Step segmentation per foot and per-sensor zeroing with the adaptive threshold (seed 3.3.1-3.3.2).
#include "gaitmon/segmentation.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

namespace gaitmon {
namespace {

// A swing window's sensors that vary more than this times the median sensor's squared
// deviations (5 times its SD) are left out of the noise estimate; the median taken as at least
// the rounding's 1/12 bit^2 a frame, as where most sensors read a steady 0 it is 0.
constexpr double kMaxNoiseVarianceOfMedian = 25.0;
constexpr double kRoundingVarianceBits2 = 1.0 / 12.0;

}  // namespace

SegmenterLimits segmenter_limits(double sample_rate_hz) {
  SegmenterLimits limits;
  limits.max_stance_frames = static_cast<std::int64_t>(60.0 * sample_rate_hz);
  limits.max_swing_half_frames = static_cast<std::int64_t>(1.5 * sample_rate_hz);
  limits.min_first_swing_frames = static_cast<std::int64_t>(0.2 * sample_rate_hz);
  limits.sample_period_s = 1.0 / sample_rate_hz;
  return limits;
}

std::string_view step_status_name(StepStatus status) {
  return status == StepStatus::Ok ? "ok" : "incomplete";
}

StepSegmenter::ContactDetector::Event StepSegmenter::ContactDetector::step(std::int64_t index,
                                                                           bool above) {
  if (!in_contact) {
    if (!above) {
      run = 0;
      return Event::None;
    }
    if (run == 0) run_start = index;
    if (++run < debounce) return Event::None;
    in_contact = true;
    contact_start = run_start;
    last_above = index;
    run = 0;
    return Event::Start;
  }
  if (above) {
    last_above = index;
    run = 0;
    return Event::None;
  }
  if (++run < debounce) return Event::None;
  in_contact = false;
  run = 0;
  return Event::End;
}

std::int64_t StepSegmenter::ContactDetector::earliest_start(std::int64_t next) const {
  return !in_contact && run > 0 ? run_start : next;
}

StepSegmenter::StepSegmenter(Foot foot, std::size_t sensors, const SegmentationSettings& settings,
                             double adaptive_threshold_pct, double newtons_per_bit,
                             const SegmenterLimits& limits)
    : foot_(foot),
      sensors_(sensors),
      settings_(settings),
      pct_(adaptive_threshold_pct),
      newtons_per_bit_(newtons_per_bit),
      limits_(limits) {
  if (sensors == 0) throw std::invalid_argument("StepSegmenter: sensor count must be positive");
  if (settings.debounce_frames < 1)
    throw std::invalid_argument("StepSegmenter: debounce_frames must be at least 1");
  if (settings.swing_window_frames < 1)
    throw std::invalid_argument("StepSegmenter: swing_window_frames must be at least 1");
  if (!(settings.threshold_noise_sds >= 0.0 && settings.threshold_noise_sds <= 20.0))
    throw std::invalid_argument("StepSegmenter: threshold_noise_sds must be in [0, 20]");
  if (settings.event_threshold_bits < 0)
    throw std::invalid_argument("StepSegmenter: event_threshold_bits must not be negative");
  // Frame intervals jitter around one period: a limit within half a period of it would cut a
  // steady stream at every frame.
  if (!(settings.max_gap_s >= 1.5 * limits.sample_period_s)) {
    throw std::invalid_argument(
        fmt::format("StepSegmenter: max_gap_s {:g} s is under 1.5 sample periods ({:g} s)",
                    settings.max_gap_s, 1.5 * limits.sample_period_s));
  }
  if (!(adaptive_threshold_pct >= 0.0 && adaptive_threshold_pct <= 100.0))
    throw std::invalid_argument("StepSegmenter: adaptive threshold must be 0..100 %");
  if (!(newtons_per_bit > 0.0))
    throw std::invalid_argument("StepSegmenter: newtons_per_bit must be positive");
  if (limits.max_stance_frames <= settings.debounce_frames)
    throw std::invalid_argument("StepSegmenter: max_stance_frames must exceed debounce_frames");
  if (limits.max_swing_half_frames < settings.swing_window_frames)
    throw std::invalid_argument(
        "StepSegmenter: max_swing_half_frames must be at least swing_window_frames");
  detector_.debounce = settings.debounce_frames;
}

const StepSegmenter::Entry& StepSegmenter::at(std::int64_t index) const {
  return buffer_[static_cast<std::size_t>(index - first_)];
}

double StepSegmenter::baseline() const {
  if (recent_floors_.empty()) return static_cast<double>(min_sum_);
  return *std::min_element(recent_floors_.begin(), recent_floors_.end());
}

bool StepSegmenter::above(std::int64_t index, double baseline) const {
  return static_cast<double>(at(index).sum) - baseline > settings_.event_threshold_bits;
}

void StepSegmenter::push(const Frame& frame, std::vector<Step>& finalised) {
  if (finished_) throw std::logic_error("StepSegmenter::push after finish()");
  if (frame.foot != foot_) {
    throw std::invalid_argument("StepSegmenter of foot " + std::string(foot_name(foot_)) +
                                " given a frame of foot " + std::string(foot_name(frame.foot)));
  }
  if (frame.bits.size() != sensors_) {
    throw std::invalid_argument("StepSegmenter: frame has " + std::to_string(frame.bits.size()) +
                                " sensors, expected " + std::to_string(sensors_));
  }
  if (frames() > 0 && !(frame.t_s > last_t_s_)) {
    throw std::invalid_argument("StepSegmenter: frame time " + std::to_string(frame.t_s) +
                                " s does not increase after " + std::to_string(last_t_s_) + " s");
  }
  if (next_ > 0 && frame.t_s - last_t_s_ > settings_.max_gap_s) {
    restart(finalised);
    ++gaps_;
  }
  last_t_s_ = frame.t_s;
  const std::int64_t sum = std::accumulate(frame.bits.begin(), frame.bits.end(), std::int64_t{0});
  buffer_.push_back({frame, sum});
  const std::int64_t index = next_++;
  const bool new_minimum = index == 0 || sum < min_sum_;
  if (new_minimum) {
    min_sum_ = sum;
    min_bits_ = frame.bits;
  }
  if (starting_up_) {
    // A lower minimum can turn earlier frames into contact frames, so they are classified again.
    const bool swing_seen = start_up_classify(new_minimum ? first_ : index);
    if (swing_seen || static_cast<std::int64_t>(buffer_.size()) >= limits_.max_stance_frames) {
      end_start_up(finalised);
    }
    return;
  }
  process(index, finalised);
  trim();
}

bool StepSegmenter::start_up_classify(std::int64_t from) {
  StartUp& st = start_up_;
  if (from == first_) {
    st = StartUp{};
    st.detector.debounce = settings_.debounce_frames;
  }
  const auto floor = static_cast<double>(min_sum_);
  // A weight shift while standing can dip below the running minimum plus the threshold; a swing
  // unloads the foot, so it must fall to half the highest load seen before it.
  const auto is_swing = [&st] { return 2 * st.swing_floor <= st.peak_sum; };
  const auto long_enough = [&st, this](std::int64_t swing_end) {
    return swing_end - st.swing_begin >= limits_.min_first_swing_frames;
  };
  for (std::int64_t i = from; i < next_; ++i) {
    const std::int64_t sum = at(i).sum;
    st.max_sum = i == first_ ? sum : std::max(st.max_sum, sum);
    if (st.seen_end && !st.detector.in_contact) st.swing_floor = std::min(st.swing_floor, sum);
    switch (st.detector.step(i, above(i, floor))) {
      case ContactDetector::Event::End:
        st.seen_end = true;
        st.peak_sum = st.max_sum;
        st.swing_floor = sum;
        st.swing_begin = st.detector.last_above + 1;
        for (std::int64_t j = st.detector.last_above + 1; j < i; ++j) {
          st.swing_floor = std::min(st.swing_floor, at(j).sum);
        }
        break;
      case ContactDetector::Event::Start:
        if (st.seen_end && is_swing() && long_enough(st.detector.contact_start)) return true;
        break;
      case ContactDetector::Event::None:
        break;
    }
    // A swing of more than 2 H + 1 frames settles the step before it as well.
    if (st.seen_end && !st.detector.in_contact &&
        st.detector.earliest_start(i + 1) >
            st.detector.last_above + 1 + 2 * limits_.max_swing_half_frames &&
        is_swing()) {
      return true;
    }
  }
  return false;
}

void StepSegmenter::end_start_up(std::vector<Step>& out) {
  // The buffered frames go through the online path, against the minimum of all of them.
  starting_up_ = false;
  for (std::int64_t i = first_; i < next_; ++i) process(i, out);
  trim();
}

void StepSegmenter::process(std::int64_t index, std::vector<Step>& out) {
  // A raise restarts from the open contact's start, which the raised floor ends at the dip
  // (floors added later are not below it until a later swing), so the next raise restarts from
  // a later contact: this ends.
  std::int64_t i = index;
  while (i <= index) {
    const std::optional<std::int64_t> again = classify(i, out);
    i = again ? *again : i + 1;
  }
}

std::optional<std::int64_t> StepSegmenter::classify(std::int64_t index, std::vector<Step>& out) {
  switch (detector_.step(index, above(index, baseline()))) {
    case ContactDetector::Event::Start:
      on_contact_start(detector_.contact_start, out);
      watch_contact(index);
      break;
    case ContactDetector::Event::End:
      on_contact_end(detector_.last_above);
      watch_.active = false;
      break;
    case ContactDetector::Event::None:
      break;
  }
  const std::int64_t half = limits_.max_swing_half_frames;
  if (detector_.in_contact) {
    if (!skipping_ && index - detector_.contact_start + 1 >= limits_.max_stance_frames) {
      out.push_back(
          make_step(*pending_, detector_.last_above, std::nullopt, StepStatus::Incomplete));
      pending_.reset();
      skipping_ = true;
      watch_.active = false;
    }
  } else if (pending_ && detector_.earliest_start(index + 1) > swing_start_ + 2 * half) {
    if (restarting_) {
      drop_restarted_contact();
    } else {
      // The swing is certainly longer than 2 H + 1 frames: the post-swing midpoint is g0 + H.
      finalise(window(swing_start_ + half, swing_start_, index, Side::AfterStep), out);
    }
  }
  if (!watch_.active) return std::nullopt;

  const double load = static_cast<double>(at(index).sum) - baseline();
  std::optional<double> missed;
  if (2.0 * load > watch_.peak) {
    if (watch_.dip_begin >= 0 && index - watch_.dip_begin >= limits_.min_first_swing_frames) {
      missed = missed_swing_floor(watch_.dip_begin, index - 1);
    }
    watch_.dip_begin = -1;
    watch_.peak = std::max(watch_.peak, load);
  } else {
    if (watch_.dip_begin < 0) watch_.dip_begin = index;
    if (index - watch_.dip_begin == 2 * half) missed = missed_swing_floor(watch_.dip_begin, index);
  }
  if (!missed) return std::nullopt;
  recent_floors_.assign(1, *missed);
  detector_ = ContactDetector{};
  detector_.debounce = settings_.debounce_frames;
  watch_.active = false;
  restarting_ = true;
  return pending_->heel_strike;
}

void StepSegmenter::watch_contact(std::int64_t confirmed) {
  watch_.active = true;
  watch_.dip_begin = -1;
  watch_.peak = 0.0;
  for (std::int64_t i = detector_.contact_start; i <= confirmed; ++i) {
    watch_.peak = std::max(watch_.peak, static_cast<double>(at(i).sum) - baseline());
  }
}

std::optional<double> StepSegmenter::missed_swing_floor(std::int64_t first,
                                                        std::int64_t last) const {
  const double floor = quietest_mean(
      first, last, std::min<std::int64_t>(settings_.swing_window_frames, last - first + 1));
  // A foot still carrying more than twice the contact threshold is in contact, whatever it did
  // before: the real recordings' deep dips inside a contact are 410 and 580 bits above it.
  if (floor - baseline() > std::min(watch_.peak / 4.0, 2.0 * settings_.event_threshold_bits)) {
    return std::nullopt;
  }
  int quiet = 0;
  for (std::int64_t i = first; i <= last; ++i) {
    quiet = above(i, floor) ? 0 : quiet + 1;
    if (quiet >= settings_.debounce_frames) return floor;
  }
  return std::nullopt;
}

void StepSegmenter::drop_restarted_contact() {
  next_index_ = pending_->index;
  pending_.reset();
  restarting_ = false;
}

void StepSegmenter::on_contact_start(std::int64_t heel_strike, std::vector<Step>& out) {
  const std::int64_t g0 = swing_start_;
  const std::int64_t g1 = heel_strike - 1;
  const std::int64_t swing = heel_strike - g0;
  const std::int64_t half = limits_.max_swing_half_frames;
  Pending next;
  next.index = restarting_ ? pending_->index : next_index_++;
  next.heel_strike = heel_strike;
  next.complete_start = swing >= settings_.debounce_frames;
  if (swing > 0) {
    const std::int64_t middle = g0 + (swing - 1) / 2;
    if (pending_ && !restarting_) {
      finalise(window(std::min(middle, g0 + half), g0, g1, Side::AfterStep), out);
    }
    next.pre = window(std::max(middle, g1 - half), g0, g1, Side::BeforeStep);
    // A restarted contact's swing was counted before the floor was raised past it.
    if (next.complete_start && !restarting_) add_floor(next.pre->floor_bits);
  }
  pending_ = std::move(next);
  restarting_ = false;
}

void StepSegmenter::on_contact_end(std::int64_t toe_off) {
  swing_start_ = toe_off + 1;
  if (skipping_) {
    skipping_ = false;
    return;
  }
  pending_->toe_off = toe_off;
}

void StepSegmenter::add_floor(double floor_bits) {
  recent_floors_.push_back(floor_bits);
  if (recent_floors_.size() > kFloorHistory) recent_floors_.pop_front();
}

void StepSegmenter::finalise(const Window& post, std::vector<Step>& out) {
  add_floor(post.floor_bits);
  out.push_back(make_step(*pending_, pending_->toe_off, post,
                          pending_->complete_start ? StepStatus::Ok : StepStatus::Incomplete));
  pending_.reset();
}

StepSegmenter::Window StepSegmenter::window(std::int64_t midpoint, std::int64_t g0, std::int64_t g1,
                                            Side side) const {
  const std::int64_t width = settings_.swing_window_frames;
  const std::int64_t lo = std::max(g0, midpoint - (width - 1) / 2);
  const std::int64_t hi = std::min(g1, midpoint - (width - 1) / 2 + width - 1);
  Window w;
  w.midpoint = midpoint;
  w.zero_bits.assign(sensors_, 0.0);
  std::int64_t sum = 0;
  for (std::int64_t i = lo; i <= hi; ++i) {
    const Entry& e = at(i);
    sum += e.sum;
    w.t_s += e.frame.t_s;
    for (std::size_t s = 0; s < sensors_; ++s) w.zero_bits[s] += e.frame.bits[s];
  }
  const std::int64_t count = hi - lo + 1;
  w.bias_bits = static_cast<double>(sum) / static_cast<double>(count);
  w.t_s /= static_cast<double>(count);
  for (double& z : w.zero_bits) z /= static_cast<double>(count);
  // Pooled over the sensors but those that vary over 5 times as much as the median sensor: a
  // sensor that flickers, or a little load in the swing, would otherwise raise every sensor's
  // threshold. Over 5 frames a sensor of Gaussian noise is left out with a chance under 1e-15.
  std::vector<double> squared(sensors_, 0.0);
  for (std::int64_t i = lo; i <= hi; ++i) {
    const Entry& e = at(i);
    for (std::size_t s = 0; s < sensors_; ++s) {
      const double deviation = e.frame.bits[s] - w.zero_bits[s];
      squared[s] += deviation * deviation;
    }
  }
  std::vector<double> sorted = squared;
  const auto middle = sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2);
  std::nth_element(sorted.begin(), middle, sorted.end());
  const double limit = kMaxNoiseVarianceOfMedian *
                       std::max(*middle, kRoundingVarianceBits2 * static_cast<double>(count - 1));
  std::int64_t kept = 0;
  for (double q : squared) {
    if (q > limit) continue;
    w.squared_deviation_bits2 += q;
    ++kept;
  }
  w.degrees_of_freedom = kept * (count - 1);

  // The quietest run of `count` frames between this window and the step.
  w.floor_bits =
      side == Side::BeforeStep ? quietest_mean(lo, g1, count) : quietest_mean(g0, hi, count);
  return w;
}

double StepSegmenter::quietest_mean(std::int64_t first, std::int64_t last,
                                    std::int64_t width) const {
  std::int64_t run = 0;
  std::int64_t lowest = 0;
  for (std::int64_t i = first; i <= last; ++i) {
    run += at(i).sum;
    if (i - first >= width) run -= at(i - width).sum;
    if (i - first == width - 1 || (i - first >= width && run < lowest)) lowest = run;
  }
  return static_cast<double>(lowest) / static_cast<double>(width);
}

Step StepSegmenter::make_step(const Pending& pending, std::int64_t toe_off,
                              const std::optional<Window>& post, StepStatus status) const {
  Step step;
  step.foot = foot_;
  step.index = pending.index;
  step.status = status;
  if (pending.pre) step.pre_zero_t_s = pending.pre->t_s;
  if (post) step.post_zero_t_s = post->t_s;
  if (pending.pre && post) {
    step.bias_bits = (pending.pre->bias_bits + post->bias_bits) / 2.0;
    step.sensor_zero_bits.resize(sensors_);
    for (std::size_t s = 0; s < sensors_; ++s) {
      step.sensor_zero_bits[s] = (pending.pre->zero_bits[s] + post->zero_bits[s]) / 2.0;
    }
  } else if (pending.pre || post) {
    const Window& only = pending.pre ? *pending.pre : *post;
    step.bias_bits = only.bias_bits;
    step.sensor_zero_bits = only.zero_bits;
  } else {
    step.bias_bits = static_cast<double>(min_sum_);
    step.sensor_zero_bits.assign(min_bits_.begin(), min_bits_.end());
  }

  std::int64_t heel_strike = pending.heel_strike;
  if (status == StepStatus::Ok) {
    // The same contact rule, now that the floor of the swing after the step is known too, over
    // the frames between the step's two swing midpoints.
    const double floor = baseline();
    ContactDetector detector;
    detector.debounce = settings_.debounce_frames;
    std::int64_t found_start = -1;
    std::int64_t found_end = -1;
    const auto consider = [&](std::int64_t start, std::int64_t end) {
      if (start > toe_off || end < pending.heel_strike) return;
      found_start = found_start < 0 ? start : std::min(found_start, start);
      found_end = std::max(found_end, end);
    };
    for (std::int64_t i = pending.pre->midpoint + 1; i <= post->midpoint; ++i) {
      if (detector.step(i, above(i, floor)) == ContactDetector::Event::End) {
        consider(detector.contact_start, detector.last_above);
      }
    }
    if (detector.in_contact) consider(detector.contact_start, detector.last_above);
    if (found_start >= 0) {
      heel_strike = found_start;
      toe_off = found_end;
    }
  }

  step.heel_strike_frame = frame_base_ + heel_strike;
  step.toe_off_frame = frame_base_ + toe_off;
  step.t_heel_strike_s = at(heel_strike).frame.t_s;
  step.t_toe_off_s = at(toe_off).frame.t_s;
  step.stance.reserve(static_cast<std::size_t>(toe_off - heel_strike + 1));
  double max_summed = 0.0;
  for (std::int64_t i = heel_strike; i <= toe_off; ++i) {
    const Entry& e = at(i);
    const double zeroed = static_cast<double>(e.sum) - step.bias_bits;
    max_summed = i == heel_strike ? zeroed : std::max(max_summed, zeroed);
    step.stance.push_back(e.frame);
  }
  step.max_summed_bits = max_summed;
  // Within each window, not about the step's zero: a zero that drifts between the two windows
  // (creep, warming) is not noise. And the quieter window's: one at the recording's end can catch
  // the foot still unloading (a 20 kg session's last step read 1.19 bits there, 0.47-0.53 in
  // every other window).
  std::optional<double> variance;
  for (const std::optional<Window>* w : {&pending.pre, &post}) {
    if (!w->has_value() || (*w)->degrees_of_freedom == 0) continue;
    const double v = (*w)->squared_deviation_bits2 / static_cast<double>((*w)->degrees_of_freedom);
    variance = variance ? std::min(*variance, v) : v;
  }
  step.zero_noise_sd_bits = variance ? std::sqrt(*variance) : 0.0;
  step.threshold_floor_bits = settings_.threshold_noise_sds * step.zero_noise_sd_bits;
  step.adaptive_threshold_bits =
      adaptive_threshold_bits(max_summed, pct_, step.threshold_floor_bits);
  step.peak_force_n = max_summed * newtons_per_bit_;
  return step;
}

void StepSegmenter::trim() {
  const std::int64_t keep = [&]() -> std::int64_t {
    if (pending_) {
      // A contact classified again keeps its swing, whose window may be taken again.
      return pending_->pre ? pending_->pre->midpoint - (settings_.swing_window_frames - 1) / 2
                           : pending_->heel_strike;
    }
    if (detector_.in_contact) return detector_.last_above + 1;
    // The next contact's pre-swing window lies at most H + half a window before its heel strike.
    const std::int64_t earliest = detector_.earliest_start(next_);
    return std::max(swing_start_, earliest - 1 - limits_.max_swing_half_frames -
                                      (settings_.swing_window_frames - 1) / 2);
  }();
  while (first_ < keep && !buffer_.empty()) {
    buffer_.pop_front();
    ++first_;
  }
}

void StepSegmenter::restart(std::vector<Step>& finalised) {
  if (finished_) throw std::logic_error("StepSegmenter::restart after finish()");
  end_frames(finalised);
  // A fresh segmenter is the start of a recording by construction; only the numbering and the
  // time order carry over.
  StepSegmenter fresh(foot_, sensors_, settings_, pct_, newtons_per_bit_, limits_);
  fresh.frame_base_ = frames();
  fresh.gaps_ = gaps_;
  fresh.next_index_ = next_index_;
  fresh.last_t_s_ = last_t_s_;
  *this = std::move(fresh);
}

void StepSegmenter::finish(std::vector<Step>& finalised) {
  if (finished_) throw std::logic_error("StepSegmenter::finish called twice");
  finished_ = true;
  end_frames(finalised);
}

void StepSegmenter::end_frames(std::vector<Step>& finalised) {
  if (next_ == 0) return;
  if (starting_up_) end_start_up(finalised);
  if (detector_.in_contact) {
    if (!skipping_) {
      finalised.push_back(
          make_step(*pending_, detector_.last_above, std::nullopt, StepStatus::Incomplete));
    }
  } else if (pending_ && restarting_) {
    drop_restarted_contact();
  } else if (pending_) {
    // The swing after the last toe off ends with the recording (or a run too short to count).
    const std::int64_t g0 = swing_start_;
    const std::int64_t g1 = detector_.earliest_start(next_) - 1;
    const std::int64_t middle = g0 + (g1 - g0) / 2;
    finalise(window(std::min(middle, g0 + limits_.max_swing_half_frames), g0, g1, Side::AfterStep),
             finalised);
  }
  pending_.reset();
  buffer_.clear();
}

double adaptive_threshold_bits(double max_summed_bits, double pct, double floor_bits) {
  return std::max({0.0, floor_bits, pct * max_summed_bits / 100.0});
}

void zero_and_threshold(std::span<const std::uint8_t> raw, std::span<const double> zero,
                        double threshold_bits, std::span<double> out) {
  if (raw.size() != zero.size() || raw.size() != out.size()) {
    throw std::invalid_argument("zero_and_threshold: raw, zero and out differ in size");
  }
  if (!(threshold_bits >= 0.0)) {
    throw std::invalid_argument("zero_and_threshold: threshold must not be negative");
  }
  for (std::size_t i = 0; i < raw.size(); ++i) {
    const double zeroed = static_cast<double>(raw[i]) - zero[i];
    out[i] = zeroed < threshold_bits ? 0.0 : zeroed;
  }
}

}  // namespace gaitmon
