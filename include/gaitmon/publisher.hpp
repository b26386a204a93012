// What the live monitor tells the outside world, as plain structs, and the interface that sends
// them. The monitor knows only this interface; the LCM implementation (src/lcm/) maps each struct
// onto its generated message type, and tests record them in memory.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "gaitmon/types.hpp"

namespace gaitmon {

/// Microseconds since the Unix epoch, as LCM's utime.
std::int64_t now_utime();

struct RegionFrameReport {
  double force_n = 0.0;           ///< eq 42, bias removed
  double active_area_mm2 = 0.0;   ///< sensors above zero x sensor area
  std::uint8_t ellipse_case = 0;  ///< ContactEllipse kase as its integer value; 0 = none
  double centre_x_mm = 0.0, centre_y_mm = 0.0;
  double ra_mm = 0.0, rb_mm = 0.0;  ///< semi-axes (ra nearer the lateral-medial axis)
  double angle_rad = 0.0;
  double ellipse_area_mm2 = 0.0;
};

/// Per foot and frame (GAITMON_FRAME).
struct FrameReport {
  std::int64_t utime = 0;
  Foot foot = Foot::Left;
  std::int64_t frame = 0;  ///< 0-based index among this foot's frames
  double t_s = 0.0;        ///< session time of the frame
  std::array<RegionFrameReport, kRegionCount> regions{};
};

/// Heel strike and toe off events (GAITMON_STEP).
struct StepEvent {
  enum class Kind : std::uint8_t { HeelStrike, ToeOff };
  std::int64_t utime = 0;
  Foot foot = Foot::Left;
  int step = 0;
  Kind kind = Kind::HeelStrike;
  /// False for an incomplete step (StepStatus::Incomplete): one of its two events is where the
  /// data begin or end, not a foot event, so cadence must not count it.
  bool complete = true;
  std::int64_t frame = 0;
  double t_s = 0.0;
};

struct RegionFitReport {
  Region region = Region::Heel;
  std::string status;  ///< ok, no_contact, fit_failed:<reason>
  double kbar_n_per_mm3 = 0.0, n = 0.0, cbar_ns_per_mm3 = 0.0, m = 0.0;
  double se_kbar = 0.0, se_n = 0.0, se_cbar = 0.0, se_m = 0.0;
  /// The same with the measurement chain's shared error (with_chain_error in analysis.hpp):
  /// against the tissue, not the other steps; 0 where the fit has no material estimate.
  double se_kbar_total = 0.0, se_n_total = 0.0, se_cbar_total = 0.0, se_m_total = 0.0;
  double A_mm = 0.0, B_mm = 0.0, C_mm = 0.0, d0_mm = 0.0;
  double nrmse_pct = 0.0;
  /// Steps of the running m ([model] m_per_session) the region was fitted at; 0: its own m.
  int m_steps = 0;
};

/// Per foot-step fit results (GAITMON_FIT).
struct FitReport {
  std::int64_t utime = 0;
  Foot foot = Foot::Left;
  int step = 0;
  double t_heel_strike_s = 0.0;
  double t_toe_off_s = 0.0;
  double nrmse_total_pct = 0.0;
  double latency_ms = 0.0;  ///< from the step's finalisation (end of step known) to publication
  /// The tissue effects inside this step's fit, comma-separated, at the parameters of the
  /// effects estimate published at `effects_utime`; empty and 0 for the baseline model.
  std::string effects_inside;
  std::int64_t effects_utime = 0;
  std::array<RegionFitReport, kRegionCount> regions{};
};

struct RegionTissueReport {
  Region region = Region::Heel;
  std::string status;  ///< ok, not_pooled:<reason>
  int steps = 0;       ///< step fits pooled (those that determined the four parameters)
  double kbar_n_per_mm3 = 0.0, n = 0.0, cbar_ns_per_mm3 = 0.0, m = 0.0;
  /// Of the pooled mean with the measurement chain's shared error ([pooling]), as session.json's.
  double se_kbar = 0.0, se_n = 0.0, se_cbar = 0.0, se_m = 0.0;
};

/// Each region's tissue over the latest steps of both feet, their own fits pooled
/// (GAITMON_TISSUE): after every fitted step, and once more at the end of the run.
struct TissueReport {
  std::int64_t utime = 0;
  bool final_estimate = false;
  Foot foot = Foot::Left;  ///< the latest step taken in
  int step = 0;
  double t_first_heel_strike_s = 0.0;  ///< over the steps in the window
  double t_last_toe_off_s = 0.0;
  std::array<RegionTissueReport, kRegionCount> regions{};
};

/// 1 Hz health of the pipeline (GAITMON_STATUS). Counters are totals since start.
struct StatusReport {
  std::int64_t utime = 0;
  std::string connection;  ///< connecting, connected, disconnected, finished
  std::uint64_t bytes_received = 0;
  std::uint64_t frames_decoded = 0;
  std::uint64_t crc_errors = 0;
  std::uint64_t resyncs = 0;
  std::uint64_t frames_truncated = 0;
  std::uint64_t header_errors = 0;
  std::uint64_t frames_lost_sequence = 0;  ///< gaps in the device counter
  std::uint64_t sequence_restarts = 0;
  std::uint64_t reconnects = 0;
  std::uint64_t transfers_overflowed = 0;  ///< USB transfers whose excess bytes were lost
  std::uint64_t ring_depth = 0;
  std::uint64_t ring_drops = 0;
  std::uint64_t frames_processed = 0;   ///< taken from the ring and segmented
  std::uint64_t frames_rejected = 0;    ///< taken from the ring but unusable (see Monitor)
  std::uint64_t segmentation_gaps = 0;  ///< gaps over max_gap_s: a foot's segmentation restarted
  std::uint64_t steps_detected = 0;
  std::uint64_t step_backlog = 0;
  std::uint64_t step_drops = 0;  ///< steps no worker took (see MonitorCounters)
  std::uint64_t fits_published = 0;
  /// Published fits with a region (or the step) fit_failed, and steps lost after their analysis
  std::uint64_t fits_failed = 0;
  double fit_latency_p50_ms = 0.0;
  double fit_latency_p99_ms = 0.0;
};

/// Raw frames (GAITMON_RAW, off by default).
struct RawFrameReport {
  std::int64_t utime = 0;
  Foot foot = Foot::Left;
  std::uint32_t sequence = 0;
  std::uint32_t device_time_us = 0;
  std::vector<std::uint8_t> bits;
};

/// One shared parameter of one effect of the extended model.
struct EffectParamReport {
  std::string effect;  ///< discrepancy_effect_names()
  std::string name;    ///< the parameter, its unit in the name (tau_s, amplitude_n, ...)
  double value = 0.0;
  double se = 0.0;  ///< standard error; NaN where the data do not determine the parameter (an
                    ///< optimum on a bound or along a flat direction)
};

/// The extended tissue model ([model] effects) fitted to the latest complete steps of both feet
/// (of the first analysed step's insole size; another's are left out with a warning), as
/// `gaitmon analyze --effects` fits it to a whole session (GAITMON_EFFECTS).
struct EffectsReport {
  std::int64_t utime = 0;
  bool final_estimate = false;  ///< the last one of the run, published at shutdown
  int steps = 0;                ///< complete steps in the window the fit was given
  double t_first_heel_strike_s = 0.0;
  double t_last_toe_off_s = 0.0;
  double baseline_nrmse_pct = 0.0;  ///< pooled, in sample, without the effects
  double extended_nrmse_pct = 0.0;  ///< pooled, in sample, with them
  double baseline_heldout_nrmse_pct = 0.0;
  double extended_heldout_nrmse_pct = 0.0;  ///< k-fold over steps
  std::vector<EffectParamReport> params;    ///< effect by effect, in [model] effects order
};

/// Implementations must be safe to call from several threads at once.
class Publisher {
 public:
  virtual ~Publisher() = default;
  virtual void publish(const FrameReport& report) = 0;
  virtual void publish(const StepEvent& event) = 0;
  virtual void publish(const FitReport& report) = 0;
  virtual void publish(const StatusReport& report) = 0;
  virtual void publish(const RawFrameReport& report) = 0;
  virtual void publish(const EffectsReport& report) = 0;
  virtual void publish(const TissueReport& report) = 0;
};

}  // namespace gaitmon
