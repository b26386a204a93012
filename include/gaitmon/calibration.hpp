// Measuring the measurement chain's shared error on simulated sessions: the SDs of [pooling] and
// [asymmetry] in the config. Each session is simulated with known tissue and analysed as
// `analyze` would (each step at its own m, and again at one m per region over the session); the
// SD per region and parameter is the one that brings the z of the pooled means against the truth,
// and of the feet's difference against none, to an RMS of 1 (README, "How honest the standard
// errors are"). A lab whose insoles differ from the simulated chain (noise, dc offsets) measures
// its own with the chain's options set to its own.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <vector>

#include "gaitmon/config.hpp"
#include "gaitmon/simulator.hpp"
#include "gaitmon/types.hpp"

namespace gaitmon {

/// The simulated sessions: every size with every seed, of one length, each walker's body mass
/// spread evenly over the seeds (to 0.1 kg), the rest of the simulator's options at its defaults
/// but for the chain's own below. Without drift, asymmetry or step-to-step variation: the truth is
/// one parameter set per region, under both feet.
struct CalibrationDesign {
  std::vector<InsoleSize> sizes;
  std::uint64_t first_seed = 1;
  std::uint64_t last_seed = 20;
  double duration_s = 30.0;
  double min_body_mass_kg = 50.0;  ///< at the first seed
  double max_body_mass_kg = 90.0;  ///< at the last
  double noise_sd_bits = 0.5;
  int max_bias_bits = 2;
  double placement_sd_mm = 0.0;
  /// How the simulated cells read; on the coverage raster (cells that average) the sessions are
  /// analysed with footprint-mean, the area `analyze --area auto` takes there.
  Rasterisation rasterisation = Rasterisation::CellCentre;

  std::size_t session_count() const;
  /// The i-th session's size, seed and mass (sizes outer, seeds inner).
  InsoleSize size_of(std::size_t session) const;
  std::uint64_t seed_of(std::size_t session) const;
  double body_mass_kg_of(std::size_t session) const;
  /// Throws std::invalid_argument naming the field for an empty or out-of-range design.
  void check() const;
};

/// A design of a designs file (config/calibration_designs.toml) and which of the config's tables
/// it measures: several designs measure a table together, each entry the largest they measure.
struct CalibrationDesignEntry {
  CalibrationDesign design;
  bool pooling = true;    ///< [pooling] and [pooling.m_per_session]
  bool asymmetry = true;  ///< [asymmetry] and [asymmetry.m_per_session]
};

/// Reads a designs file: an array of [[design]] tables, each with `tables` (["pooling"],
/// ["asymmetry"] or both), `sizes`, `seeds` = [first, last], `duration_s`, `body_mass_kg` = [min,
/// max] and optionally `noise_sd_bits`, `max_bias_bits`, `placement_sd_mm` and `rasterisation`
/// ("centre" or "coverage"; the simulator's defaults otherwise), in the ranges `gaitmon calibrate`
/// takes. Throws ConfigError naming the file, the key and its line.
std::vector<CalibrationDesignEntry> load_calibration_designs(const std::filesystem::path& path);

/// One pooled mean's (or one difference of the feet's) error against the truth, on the scale it
/// is pooled on (ln kbar, n, ln cbar, m), with its standard error from the steps alone, and, at a
/// shared m, how it moves with that m (through which m's own chain SD reaches it).
struct ChainSample {
  double error = 0.0;
  double se_steps = 0.0;
  double slope_on_shared_m = 0.0;
};

/// Both ways of fitting m, for the chain's four parameters ([pooling] and
/// [pooling.m_per_session]) and the feet's two ([asymmetry] and [asymmetry.m_per_session]).
struct ChainSamples {
  /// [region][parameter]: ln kbar, n, ln cbar, m.
  std::array<std::array<std::vector<ChainSample>, 4>, kRegionCount> pooled;
  /// The same for each step's own estimate (with_chain_error without the chain's SDs): its error,
  /// its standard error from its fit (at its own m held within m's range, within_m_range; at a
  /// shared m with that m's own variance through the slope), and the slope through which m's
  /// chain SD reaches it.
  std::array<std::array<std::vector<ChainSample>, 4>, kRegionCount> steps;
  /// [region][0 kbar, 1 cbar]: ln(right / left), whose truth is 0.
  std::array<std::array<std::vector<ChainSample>, 2>, kRegionCount> feet;
};

struct CalibrationSamples {
  ChainSamples per_step;       ///< each step fitted at its own m
  ChainSamples m_per_session;  ///< one m per region over the session
  std::size_t sessions = 0;
};

/// Simulates and analyses every session of `design` on every core (the result does not depend on
/// the threads). `on_progress`, if set, is called on the calling thread with the fraction done.
/// The sessions are written to and removed from a folder of their own under `scratch_dir`.
/// Throws std::invalid_argument for a bad design.
CalibrationSamples collect_chain_samples(const Config& config, const CalibrationDesign& design,
                                         const std::filesystem::path& scratch_dir,
                                         const std::function<void(double)>& on_progress = {});

/// The RMS over `samples` of error / sqrt(se_steps^2 + (slope_on_shared_m * m_sd)^2 + sd^2); NaN
/// when there are none.
double rms_z(const std::vector<ChainSample>& samples, double sd, double m_sd = 0.0);

/// The least SD >= 0 that brings rms_z to at most 1 (0 where the steps' own standard errors
/// already do), to a double's resolution, and at most 10 (1000 % on the ln scales, the most
/// [pooling] takes); nullopt when there are no samples.
std::optional<double> sd_for_unit_rms(const std::vector<ChainSample>& samples, double m_sd = 0.0);

/// `value` rounded up to a multiple of `step` (a value within 1e-9 steps of one stays there).
double round_up_to(double value, double step);

/// The config's tables as measured: per region and parameter, sd_for_unit_rms rounded up to
/// 0.5 (kbar and cbar, in 100 ln) or 0.005 (n and m). m's comes first: where the steps share an m
/// the others take its rounded SD through their slopes (samples without a shared m have none).
/// A step's own SD is what it takes, beside the rounded chain SD, to bring the steps' z to an
/// RMS of 1: sqrt(total^2 - chain^2) of the total sd_for_unit_rms finds, rounded up the same way.
/// Where a region has no samples the value is nullopt.
struct MeasuredChainSds {
  std::array<std::array<std::optional<double>, kRegionCount>, 4> chain;  ///< [parameter][region]
  std::array<std::array<std::optional<double>, kRegionCount>, 4> step;   ///< [parameter][region]
  std::array<std::array<std::optional<double>, kRegionCount>, 2> pair;   ///< [kbar, cbar][region]
};
MeasuredChainSds measure_chain_sds(const ChainSamples& samples);

}  // namespace gaitmon
