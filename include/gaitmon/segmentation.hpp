// Step segmentation per foot, zeroing and the adaptive threshold (seed 3.3.1, 3.3.2).
//
// One incremental algorithm serves both the live monitor and batch analysis: batch segmentation
// feeds every frame of a foot to a StepSegmenter and then calls finish(), so both produce exactly
// the same steps, and a step once emitted never changes.
//
// Algorithm, per foot, on the summed bits S of each frame (H = max_swing_half_frames):
// - Contacts. A frame is "above" when S - floor > event_threshold_bits. A contact starts at the
//   first frame of a run of debounce_frames frames above and ends at the last frame above before
//   a run of debounce_frames frames at or below: the rule of the real data's ground truth.
// - Swing midpoints and the seed's bias. The swing between a toe off and the next heel strike,
//   frames g0..g1, has its midpoint at its middle frame g0 + (g1 - g0) / 2, but never more than H
//   frames from the contact it belongs to (a long pause still bounds memory and latency: the
//   post-swing midpoint is min(middle, g0 + H), the pre-swing one max(middle, g1 - H)). The seed
//   reads S at single instants; here a swing's bias is the mean of S over swing_window_frames
//   frames centred on the midpoint (clipped to the swing), which averages out the swing noise. A
//   step's bias_bits is the mean of its pre- and post-swing biases and its per-sensor zero the
//   same average per sensor (the zeros sum to the bias); zeroing and force use them, as the seed.
// - The floor used to find contacts. A swing in which the foot is not fully unloaded (shuffling,
//   turning) has a midpoint bias well above the unloaded insole, and subtracting it moves heel
//   strike and toe off by up to 10 frames against the 40 N ground truth of the real recordings. So
//   contacts are found against a floor: each swing side's floor is the lowest mean of as many
//   consecutive frames as the bias window, between the midpoint window and the step; the floor in
//   use is the lowest of the last kFloorHistory (20) of them, i.e. of the last ~10 swings: a few
//   loaded swings in a row do not raise it, and a drifting dc bias is followed within 10 swings.
//   A baseline that rises faster than that (a sensor that creeps under load) would leave the
//   next swings above floor + threshold, and the foot's contacts would merge. So an open contact
//   is watched for a swing the floor missed: a dip of at least min_first_swing_frames frames in
//   which the load above the floor stays at most half the contact's peak before it, whose
//   quietest window is at most a quarter of that peak and at most twice the event threshold
//   above the floor, and which holds debounce_frames frames within the event threshold of that
//   window. The dip is judged when the load rises above half the peak again, or once it has
//   lasted 2 H + 1 frames. Such a dip becomes the floor (the history restarts from it) and the
//   contact is classified again from its start: the dip ends it as a swing, and it starts where
//   the load first exceeds the new floor by the threshold (if it never does before the dip, it
//   was no contact and is forgotten). A mid-stance valley does not fall to a quarter of the
//   peak, nor does a weight shift while standing; the two contacts of the real recordings that
//   dip deeper (to 10 and 15 % of their peaks, for 0.6-0.7 s) still carry about 410 and 580
//   bits there (115 and 165 N).
//   Heel strike and toe off are final once the swing after the step is known: the contact rule
//   runs again over the frames between the two midpoints against the floor then in use, and the
//   step spans the contacts found there that overlap it (on the real recordings this moved one
//   toe off of 521 steps, by one frame).
// - Start-up. Until the first swing is known the floor is the minimum of S over the frames seen
//   so far, applied retroactively: the frames are kept and classified again whenever the minimum
//   falls, so a recording that starts in stance shows that contact from frame 0 rather than from
//   wherever S first rose 142 bits above an in-stance minimum. Start-up ends at the first swing
//   between two contacts (or after a contact followed by more than 2 H + 1 swing frames) whose
//   lowest S is at most half the highest S before it and that lasts at least
//   min_first_swing_frames: a weight shift while standing is not a swing, and neither is the
//   short mid-stance dip of a recording that starts in stance (its running minimum is then the
//   dip itself). It also ends after max_stance_frames frames. The buffered frames then go through
//   the online path against the minimum of all of them.
// - Status. A step is Ok when it has a swing of at least debounce_frames frames on both sides.
//   Incomplete steps are a contact that starts fewer than debounce_frames frames after the start
//   of the recording (including at frame 0), a contact still open at the end of the recording,
//   and a contact that reaches max_stance_frames frames (standing). They are emitted with their
//   frames, their first boundaries and a best-effort bias (the swing windows that exist, or else
//   the frame of lowest S) so they can be reported, but they are not meant to be analysed.
// - Gaps. Frames further apart than max_gap_s (lost frames, a link drop-out, a device restart)
//   end the segmentation as the end of a recording would, and it starts afresh after them as at
//   a recording's start, frame and step indices continuing: a contact open at a gap is
//   Incomplete, and a stance and swings are never joined across time that was not seen.
//
// Latency: a step is final once its post-swing midpoint is known, i.e. when the next contact of
// the same foot is confirmed, debounce_frames - 1 frames after that heel strike (one swing plus
// 4 frames after toe off: ~0.45 s in walking at 100 Hz), or, after a long pause, 2 H + 1 frames
// after toe off; after a swing the floor missed, once the load of the next stance passes half
// the peak before the dip. A contact reaching max_stance_frames is emitted at once as Incomplete
// and the rest of it is skipped. At finish(), a step followed by at least debounce_frames swing
// frames is final with its post-swing midpoint at the middle of that remaining swing.
//
// Memory: the frames from the current step's pre-swing window on, at most max_stance_frames +
// 2 H + swing_window_frames frames; during start-up at most max_stance_frames frames.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <limits>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "gaitmon/config.hpp"
#include "gaitmon/frame.hpp"
#include "gaitmon/types.hpp"

namespace gaitmon {

enum class StepStatus : std::uint8_t { Ok, Incomplete };

/// "ok" or "incomplete".
std::string_view step_status_name(StepStatus status);

struct Step {
  Foot foot = Foot::Left;
  int index = 0;  ///< per foot, 0-based, in time order, counting incomplete steps too
  StepStatus status = StepStatus::Ok;
  std::int64_t heel_strike_frame = 0;    ///< 0-based index among this foot's frames
  std::int64_t toe_off_frame = 0;        ///< inclusive
  double t_heel_strike_s = 0.0;          ///< t_s of the heel strike frame
  double t_toe_off_s = 0.0;              ///< t_s of the toe off frame
  double bias_bits = 0.0;                ///< summed-bits dc bias (mean of the two swing biases)
  std::vector<double> sensor_zero_bits;  ///< per sensor, mean over the swing-midpoint windows
  /// Mean times of the frames of the windows before and after the step that the zero averages
  /// (NaN where the step has no such window): when the insole read its zero.
  double pre_zero_t_s = std::numeric_limits<double>::quiet_NaN();
  double post_zero_t_s = std::numeric_limits<double>::quiet_NaN();
  double max_summed_bits = 0.0;  ///< max over the stance of the zeroed summed bits
  /// The SD of one sensor's reading about its mean within a swing window, pooled over the
  /// sensors, in the quieter of the step's windows: how much an unloaded sensor reads by noise.
  /// 0 where no window had two frames.
  double zero_noise_sd_bits = 0.0;
  /// [segmentation] threshold_noise_sds x zero_noise_sd_bits: the least the threshold may be.
  double threshold_floor_bits = 0.0;
  /// adaptive_threshold_bits(max_summed_bits, pct, threshold_floor_bits).
  double adaptive_threshold_bits = 0.0;
  double peak_force_n = 0.0;  ///< max over the stance of (S - bias) * newtons_per_bit
  std::vector<Frame> stance;  ///< raw frames heel strike..toe off inclusive
};

/// Bounds that keep a live segmenter's memory finite; the defaults are 60 s and 1.5 s at 100 Hz.
struct SegmenterLimits {
  std::int64_t max_stance_frames = 6000;     ///< longer contacts become Incomplete steps
  std::int64_t max_swing_half_frames = 150;  ///< H: farthest a swing midpoint sits from its step
  std::int64_t min_first_swing_frames = 20;  ///< shortest swing that ends start-up (0.2 s)
  double sample_period_s = 0.01;             ///< max_gap_s must be at least 1.5 of these
};

/// Segmenter memory bounds for a sample rate: contacts longer than 60 s are cut as incomplete,
/// a swing midpoint sits at most 1.5 s from its step, and start-up ends only at a swing of at
/// least 0.2 s.
SegmenterLimits segmenter_limits(double sample_rate_hz);

/// Segments the frames of one foot into steps. Not thread-safe; frames must come in time order.
class StepSegmenter {
 public:
  /// Throws std::invalid_argument for a zero sensor count, a debounce or window below 1, a
  /// negative event threshold, max_gap_s under 1.5 sample periods, pct outside 0..100,
  /// newtons_per_bit <= 0, or limits that cannot hold a contact (max_stance_frames <= debounce)
  /// or a window (H < swing_window_frames).
  StepSegmenter(Foot foot, std::size_t sensors, const SegmentationSettings& settings,
                double adaptive_threshold_pct, double newtons_per_bit,
                const SegmenterLimits& limits = {});

  /// Consumes the next frame of this foot and appends the steps it finalises (0..n) to
  /// `finalised`, after a gap (see Gaps above) the steps its restart() finalises first. Throws
  /// std::invalid_argument for another foot, a wrong sensor count or a time that does not
  /// increase, std::logic_error after finish().
  void push(const Frame& frame, std::vector<Step>& finalised);

  /// Ends the segmentation as finish() does, appending the remaining steps, and starts afresh as
  /// at the start of a recording; frame and step indices continue. Throws std::logic_error after
  /// finish().
  void restart(std::vector<Step>& finalised);

  /// Marks the end of the recording and appends the remaining steps. Call once.
  void finish(std::vector<Step>& finalised);

  /// Frames consumed so far.
  std::int64_t frames() const { return frame_base_ + next_; }

  /// Gaps longer than max_gap_s found so far, each followed by a restart.
  std::int64_t gaps() const { return gaps_; }

  /// Frames held in memory now; bounded as described under Memory above.
  std::size_t buffered_frames() const { return buffer_.size(); }

 private:
  struct Entry {
    Frame frame;
    std::int64_t sum = 0;
  };

  /// The contact rule: debounced threshold crossings, fed one classification at a time.
  struct ContactDetector {
    enum class Event : std::uint8_t { None, Start, End };
    int debounce = 1;
    bool in_contact = false;
    int run = 0;  ///< length of the current run against the state (above in swing, not in contact)
    std::int64_t run_start = -1;
    std::int64_t contact_start = -1;
    std::int64_t last_above = -1;
    Event step(std::int64_t index, bool above);
    /// The earliest frame a contact not yet confirmed could start at, given frames up to next - 1.
    std::int64_t earliest_start(std::int64_t next) const;
  };

  /// A swing-midpoint window's means (summed bits and per sensor), and the swing's floor: the
  /// lowest mean of as many consecutive frames between the window and the step.
  struct Window {
    std::int64_t midpoint = 0;
    double t_s = 0.0;  ///< mean time of the frames averaged
    double bias_bits = 0.0;
    double floor_bits = 0.0;
    std::vector<double> zero_bits;
    double squared_deviation_bits2 = 0.0;  ///< of every sensor's frames from its window mean
    std::int64_t degrees_of_freedom = 0;   ///< sensors kept x (frames - 1)
  };
  enum class Side : std::uint8_t { BeforeStep, AfterStep };

  /// Start-up classification against the running minimum of S.
  struct StartUp {
    ContactDetector detector;
    bool seen_end = false;         ///< a contact has ended: a swing may follow
    std::int64_t max_sum = 0;      ///< highest S so far
    std::int64_t peak_sum = 0;     ///< highest S before the latest swing
    std::int64_t swing_floor = 0;  ///< lowest S in the latest swing
    std::int64_t swing_begin = 0;  ///< first frame of the latest swing
  };

  /// The watch over the open contact for a swing the floor missed.
  struct MissedSwingWatch {
    bool active = false;
    double peak = 0.0;            ///< highest S - floor of the contact before the current dip
    std::int64_t dip_begin = -1;  ///< first frame of the current dip, -1 outside one
  };

  /// The contact being tracked, from its confirmed start until it becomes a Step.
  struct Pending {
    int index = 0;
    std::int64_t heel_strike = 0;
    std::int64_t toe_off = -1;  ///< -1 while the contact is open
    bool complete_start = false;
    std::optional<Window> pre;
  };

  const Entry& at(std::int64_t index) const;
  /// The floor contacts are found against: the lowest recent swing floor, or the minimum of S.
  double baseline() const;
  bool above(std::int64_t index, double baseline) const;
  /// Classifies frame `index`, and again the frames of a contact the floor was too low for.
  void process(std::int64_t index, std::vector<Step>& out);
  /// Classifies one frame; returns the frame to continue from when the floor has been raised
  /// and the open contact must be classified again from its start.
  std::optional<std::int64_t> classify(std::int64_t index, std::vector<Step>& out);
  void watch_contact(std::int64_t confirmed);
  /// Forgets the contact being classified again when the raised floor finds none in it.
  void drop_restarted_contact();
  /// The floor of a dip over frames first..last if it is a swing the floor missed.
  std::optional<double> missed_swing_floor(std::int64_t first, std::int64_t last) const;
  /// Classifies frames from..next_ - 1 against the running minimum (from first_ = afresh);
  /// returns true once a swing (falling to half the peak before it) between two contacts, or
  /// longer than 2 H + 1 frames after a contact, is confirmed.
  bool start_up_classify(std::int64_t from);
  void end_start_up(std::vector<Step>& out);
  void on_contact_start(std::int64_t heel_strike, std::vector<Step>& out);
  void on_contact_end(std::int64_t toe_off);
  Window window(std::int64_t midpoint, std::int64_t g0, std::int64_t g1, Side side) const;
  /// The lowest mean S of `width` consecutive frames in first..last (at least `width` frames).
  double quietest_mean(std::int64_t first, std::int64_t last, std::int64_t width) const;
  void add_floor(double floor_bits);
  /// The end of the recording or of the frames before a gap: the open steps are finalised.
  void end_frames(std::vector<Step>& out);
  /// Turns pending_ into a Step with its post-swing window and clears it.
  void finalise(const Window& post, std::vector<Step>& out);
  Step make_step(const Pending& pending, std::int64_t toe_off, const std::optional<Window>& post,
                 StepStatus status) const;
  void trim();

  Foot foot_;
  std::size_t sensors_;
  SegmentationSettings settings_;
  double pct_;
  double newtons_per_bit_;
  SegmenterLimits limits_;

  std::int64_t frame_base_ = 0;  ///< frames before the latest restart; indices below are after it
  std::int64_t gaps_ = 0;
  std::deque<Entry> buffer_;  ///< frames first_ .. next_ - 1
  std::int64_t first_ = 0;
  std::int64_t next_ = 0;
  double last_t_s_ = 0.0;
  bool finished_ = false;

  bool starting_up_ = true;
  StartUp start_up_;
  std::int64_t min_sum_ = 0;
  std::vector<std::uint8_t> min_bits_;  ///< the frame of lowest S: last-resort zero

  ContactDetector detector_;
  /// Floors of the latest swings, each seen from the step before and the step after it.
  static constexpr std::size_t kFloorHistory = 20;
  std::deque<double> recent_floors_;
  std::int64_t swing_start_ = 0;  ///< first frame of the current or next swing
  std::optional<Pending> pending_;
  MissedSwingWatch watch_;
  /// The open contact is classified again against a raised floor: the next contact start takes
  /// its place (and index) instead of ending it.
  bool restarting_ = false;
  bool skipping_ = false;  ///< inside a contact already emitted for reaching max_stance_frames
  int next_index_ = 0;
};

/// The seed's adaptive threshold, pct % of the step's maximum zeroed summed bits, but never below
/// `floor_bits` (nor 0). adaptive_threshold_bits(2500, 0.2) == 5. Why the floor: the seed's
/// share gives an adult a few bits, but a 20 kg walker under one bit (0.77 at size 41-42), so
/// a sensor that reads one bit of noise counts as loaded: the heel's
/// contact went on through 30 frames of noise after heel-off, its footprint was undetermined in
/// every step, and its fitted n was 0.01 for 0.27 (README, "Light walkers").
double adaptive_threshold_bits(double max_summed_bits, double pct, double floor_bits = 0.0);

/// Zeroes one frame with the step's per-sensor zero and applies the adaptive threshold: values
/// below the threshold (after zeroing) become 0 (inactive). Output in bits. Throws
/// std::invalid_argument if the spans differ in size or the threshold is negative.
void zero_and_threshold(std::span<const std::uint8_t> raw, std::span<const double> zero,
                        double threshold_bits, std::span<double> out);

}  // namespace gaitmon
