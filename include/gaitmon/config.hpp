// Settings people edit, loaded from TOML files in config/ and validated on load.
//
// The main file (config/gaitmon.toml) names two more files relative to itself: the insole
// layouts (insoles_file) and the seed's Appendix I tissue parameters (tissue_file). Loading
// refuses unknown keys, missing keys, out-of-range numbers, a sensor in two regions, a sensor
// in no region and an empty region, each with a ConfigError naming the file and the key.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "gaitmon/link_settings.hpp"
#include "gaitmon/tissue_fit.hpp"
#include "gaitmon/tissue_model.hpp"
#include "gaitmon/types.hpp"

namespace gaitmon {

/// Where the sensors of a row sit relative to the insole's midline when rows differ in length.
enum class RowAlignment { Centred, Lateral, Medial };

/// Sensor cell size and spacing. The sensing area of one cell is width x height whatever the
/// pitch; the pitch only places the cells on the foot.
struct SensorGeometry {
  double width_mm = 7.5;     ///< lateral-medial size of one sensor
  double height_mm = 15.0;   ///< anterior-posterior size of one sensor
  double pitch_x_mm = 7.5;   ///< centre-to-centre, lateral-medial
  double pitch_y_mm = 15.0;  ///< centre-to-centre, anterior-posterior
  RowAlignment alignment = RowAlignment::Centred;
  double area_mm2() const { return width_mm * height_mm; }
};

/// The manufacturer's linear calibration: full_scale_bits correspond to full_scale_n_per_cm2.
struct Calibration {
  double full_scale_bits = 255.0;
  double full_scale_n_per_cm2 = 64.0;
  /// Newtons that one bit on one sensor of the given area stands for (eq 42): 0.2824 N by default.
  double newtons_per_bit(double sensor_area_mm2) const {
    return full_scale_n_per_cm2 / full_scale_bits * sensor_area_mm2 / 100.0;
  }
};

/// Sensor creep of the insoles: a cell reads its load plus gain times its load low-passed with
/// time constant tau_s (creep.hpp). Every reader of frames undoes it before segmenting them
/// (segment_session, the live monitor), and simulate_session gives it to the cells it simulates,
/// so that the config describes one kind of insole throughout. gain 0 undoes nothing.
struct SensorCreepSettings {
  double gain = 0.0;
  double tau_s = 1.0;
};

/// Step segmentation (seed 3.3.1) settings.
struct SegmentationSettings {
  int event_threshold_bits = 142;  ///< summed bits above the dc bias that mean contact (40 N)
  int debounce_frames = 5;         ///< a contact starts/ends only after this many frames agree
  int swing_window_frames = 5;     ///< frames averaged around each swing midpoint for the bias
  /// Consecutive frames of a foot further apart than this end its segmentation as a recording's
  /// end would, and it starts afresh after them. At 100 Hz up to 4 lost frames are bridged,
  /// fewer than a debounce, so no contact or swing the segmenter could find fits in them; the
  /// half period to spare keeps jitter and the rounding of t_s from deciding.
  double max_gap_s = 0.055;
  /// The adaptive threshold is at least this many SDs of the noise an unloaded sensor reads in
  /// the swing windows (Step::zero_noise_sd_bits); 0 keeps the seed's threshold alone.
  double threshold_noise_sds = 4.0;
};

/// Bounds on row and sensor numbers, far above any real insole (18 rows, 11 per row): they keep
/// a typo such as "1:1-10000" from building a huge grid.
inline constexpr int kMaxInsoleRows = 100;
inline constexpr int kMaxSensorsPerRow = 100;

/// One run of sensors within a row: sensors first..last (1-based, lateral to medial) of row.
struct RowSpan {
  int row = 0;  ///< 1 = most anterior (toe) row
  int first = 0;
  int last = 0;
};

/// One insole size as Appendix B gives it: which sensors of which rows form each region.
struct InsoleSpec {
  InsoleSize size = InsoleSize::S35_36;
  double adaptive_threshold_pct = 0.2;  ///< the seed's Table 2, % of the step's max summed bits
  std::array<std::vector<RowSpan>, kRegionCount> regions;
};

/// The seed's Appendix I result for one size and region: mean and SD across participants.
struct SeedTissueStats {
  EllipsoidParams mean;
  EllipsoidParams sd;
  double nrmse_pct_mean = 0.0;
  double nrmse_pct_sd = 0.0;
};

/// [model] of the main file: what the tissue model includes beyond the ellipsoid.
struct ModelSettings {
  /// Named effects (discrepancy_effect_names()) that `gaitmon analyze` and the live monitor add
  /// to the model, in order; empty is the ellipsoid alone.
  std::vector<std::string> effects;
  /// The live monitor fits them to this many of the latest complete steps (both feet); analyze
  /// fits them to the whole session.
  int effects_window_steps = 100;
  /// One damping exponent m per region over the steps, each step's kbar, n and cbar fitted at it
  /// (`analyze --m-per-session`); the live monitor takes it over the latest m_window_steps
  /// complete steps (both feet), from kFirstSharedMSteps of them on. Not with effects.
  bool m_per_session = false;
  int m_window_steps = 200;
  /// The contact area the fits are given: "auto" (how the session's cells read decides, for
  /// `analyze`; the footprint for the live monitor, which names the footprint the cells call
  /// for once it is clear) or an area_source_name() (analysis.hpp).
  std::string area = "auto";
};

/// The live monitor's first running m ([model] m_per_session) waits for this many complete steps.
inline constexpr int kFirstSharedMSteps = 10;

/// How differently the pair of insoles alone makes the same tissue read under the two feet, per
/// region (indexed by index_of(Region)), as the SD of 100 ln(right / left) of kbar and of cbar.
/// foot_asymmetry (asymmetry.hpp) adds it to the steps' own standard error.
struct PairSds {
  std::array<double, kRegionCount> kbar_pair_sd_pct{};
  std::array<double, kRegionCount> cbar_pair_sd_pct{};
};

/// [asymmetry] for steps fitted each at its own m, [asymmetry.m_per_session] for steps fitted at
/// one m per region over the session: both feet's cbar are then at the same m, and the pair's
/// differ by much less (README, "Left against right").
struct AsymmetrySettings {
  PairSds per_step;
  PairSds m_per_session;
};

/// The error the measurement chain gives every step of a region alike, per region (indexed by
/// index_of(Region)), as the SD of the pooled mean's error on the scale the fit pools on: 100 ln
/// for kbar and cbar, as it is for n and m. analyse_session adds it to the pooled mean's standard
/// error, which otherwise holds only how the steps scatter. The *_step_sd are the error each
/// step's own fit makes beyond its Jacobian's and the shared one, different at every step (the
/// footprint's, slow within a step, which the residuals do not show): with_chain_error adds them
/// to a step's standard errors against the tissue, pool_region_steps to its variances in the pool.
struct ChainSds {
  std::array<double, kRegionCount> kbar_chain_sd_pct{};
  std::array<double, kRegionCount> n_chain_sd{};
  std::array<double, kRegionCount> cbar_chain_sd_pct{};
  std::array<double, kRegionCount> m_chain_sd{};
  std::array<double, kRegionCount> kbar_step_sd_pct{};
  std::array<double, kRegionCount> n_step_sd{};
  std::array<double, kRegionCount> cbar_step_sd_pct{};
  std::array<double, kRegionCount> m_step_sd{};
};

/// [pooling] for steps fitted each at its own m, [pooling.m_per_session] for steps fitted at one
/// m per region over the session (fit_damping_exponent_per_session): that m errs by more than the
/// pool of the steps' own, which its range's bounds hold toward the Appendix I means (README, "How
/// honest the standard errors are").
struct PoolingSettings {
  ChainSds per_step;
  ChainSds m_per_session;
};

/// [ring]: the lock-free ring between the driver thread and the detector thread.
struct RingSettings {
  std::size_t capacity_frames = 4096;  ///< 20 s of two feet at 100 Hz
};

/// [monitor]: the live monitor's detector thread, step workers and status.
struct MonitorSettings {
  int workers = 2;               ///< threads fitting steps
  int max_step_backlog = 32;     ///< finalised steps waiting for a worker; beyond, oldest dropped
  double status_period_s = 1.0;  ///< between two status reports
  bool publish_frames = true;    ///< per-frame region reports (GAITMON_FRAME)
  /// The latest steps of both feet whose own fits are pooled into each region's tissue
  /// (GAITMON_TISSUE).
  int tissue_window_steps = 400;
};

/// [lcm]: where the live monitor publishes (include/gaitmon/lcm/*.lcm defines the messages).
struct LcmChannels {
  std::string frame = "GAITMON_FRAME";      ///< FrameReport, per foot and frame
  std::string step = "GAITMON_STEP";        ///< StepEvent
  std::string fit = "GAITMON_FIT";          ///< FitReport, per foot-step
  std::string status = "GAITMON_STATUS";    ///< StatusReport, 1 Hz
  std::string raw = "GAITMON_RAW";          ///< RawFrameReport, only when raw_enabled
  std::string effects = "GAITMON_EFFECTS";  ///< EffectsReport, only with [model] effects
  std::string tissue = "GAITMON_TISSUE";    ///< TissueReport, after every fitted step
};

struct LcmSettings {
  /// ttl=0 keeps the multicast on this machine, so the default needs no network.
  std::string url = "udpm://239.255.76.67:7667?ttl=0";
  LcmChannels channels;
  bool raw_enabled = false;  ///< GAITMON_RAW repeats what a recording holds: off unless asked
};

/// [log]: how much the commands log; --log-level overrides it.
struct LogSettings {
  std::string level = "info";  ///< one of log_level_names()
};

/// The levels of [log] level and --log-level, spdlog's names, from the most verbose to none.
std::vector<std::string> log_level_names();

struct Config {
  std::filesystem::path source;  ///< the main file this was loaded from
  double sample_rate_hz = 100.0;
  SensorGeometry sensor;
  Calibration calibration;
  SensorCreepSettings sensor_creep;  ///< [sensor_creep]
  SegmentationSettings segmentation;
  std::array<InsoleSpec, kInsoleSizeCount> insoles;  ///< indexed by index_of(InsoleSize)
  std::array<std::array<SeedTissueStats, kRegionCount>, kInsoleSizeCount> seed_tissue;
  FitBounds fit_bounds;         ///< [fit] of the main file: the tissue fit's parameter bounds
  ModelSettings model;          ///< [model] of the main file
  AsymmetrySettings asymmetry;  ///< [asymmetry] of the main file
  PoolingSettings pooling;      ///< [pooling] of the main file
  /// [asymmetry.footprint_mean] and [pooling.footprint_mean]: the same tables for fits on the
  /// footprint of cells that average the pressure over their area (footprint-mean), whose chain
  /// errs otherwise (README, "How the cells read"). pooling_tables() (analysis.hpp) chooses.
  AsymmetrySettings asymmetry_footprint_mean;
  PoolingSettings pooling_footprint_mean;
  WireSettings wire;      ///< [wire]: the insole frame layout
  SerialSettings serial;  ///< [serial]: the serial driver
  RingSettings ring;
  MonitorSettings monitor;
  LcmSettings lcm;  ///< [lcm] of the main file
  UsbSettings usb;  ///< [usb]: the USB driver
  LogSettings log;  ///< [log]

  const InsoleSpec& insole(InsoleSize size) const { return insoles[index_of(size)]; }
  const SeedTissueStats& tissue(InsoleSize size, Region region) const {
    return seed_tissue[index_of(size)][index_of(region)];
  }
};

/// Loads and validates the main config file and the files it names. Throws ConfigError whose
/// key is the dotted path of the offending key (array elements 0-based, e.g.
/// `sizes."37-38".regions.toe1[1]`), "(file)" when the main file cannot be read (a named file
/// that cannot be read is reported at insoles_file or tissue_file of the main file), or
/// "(syntax)" when a file is not valid TOML (the reason then starts with "line L, column C").
Config load_config(const std::filesystem::path& main_file);

/// The config shipped with the source tree (config/gaitmon.toml), used when --config is absent.
std::filesystem::path default_config_path();

}  // namespace gaitmon
