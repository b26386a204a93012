// What `gaitmon creep` found, as the table on stdout, DIR/creep.json and (with --report)
// DIR/creep.html, a forest plot of each recording's gain and tau against their weighted mean.
#pragma once

#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "gaitmon/config.hpp"
#include "gaitmon/creep.hpp"
#include "gaitmon/discrepancy.hpp"

namespace gaitmon::cli {

/// One recording's creep on top of the config's, and whether its zeros show it.
struct RecordingCreep {
  std::filesystem::path session;
  std::size_t steps = 0;
  /// Each standard error the larger of the fit's two: the curvature's and the step-clustered
  /// sandwich's (ParamEstimate::robust_se), so that walks of one pair are not called two.
  MeasuredCreep creep;
  MeasuredCreep curvature;       ///< the same with the curvature's standard errors
  MeasuredCreep sandwich;        ///< and with the sandwich's
  double zero_before_pct = 0.0;  ///< the zero channel's held-out NRMSE without and with it
  double zero_after_pct = 0.0;
  bool shown = false;  ///< effect_undone_in_readings: the zeros show it and the data determine it
  double cells_at_zero_pct = 0.0;  ///< loaded_cells_at_zero: where the zeros hide part of a creep
};

enum class CreepVerdict { NoneShows, OneShows, Disagree, Agree };

struct CreepFindings {
  std::vector<RecordingCreep> recordings;
  SensorCreepSettings config_creep;  ///< what every recording was read with undone
  double min_p = 0.01;
  /// Of the recordings that show a creep, where two or more do.
  std::optional<CreepAgreement> agreement;
  /// sensor_creep_advice's text where they agree, else empty.
  std::string advice;

  CreepVerdict verdict() const;
};

/// "none_shows", "one_shows", "disagree" or "agree".
std::string_view verdict_name(CreepVerdict v);

/// The creep of a fit's gain and tau, each standard error the larger of the two it has (NaN where
/// the curvature gives none).
MeasuredCreep larger_errors(const ParamEstimate& gain, const ParamEstimate& tau);

/// " on top of the config's [sensor_creep] (gain G, tau T s)" where it undoes a creep, else empty.
std::string on_top_of_config(const SensorCreepSettings& config_creep);

/// The weighted means of the recordings that show a creep and their spread against their errors.
std::string agreement_text(const CreepAgreement& a, std::span<const RecordingCreep> recordings);

/// Where loaded cells rest at 0 in the swing in some recording (kCellsAtZeroNotePct of them or
/// more), that the gain comes out low there and by how much on simulated walks; else empty.
std::string cells_at_zero_note(std::span<const RecordingCreep> recordings);
inline constexpr double kCellsAtZeroNotePct = 5.0;

/// What the recordings say, in one sentence: nothing to paste, or that they agree.
std::string verdict_text(const CreepFindings& f);

/// creep.json: the config's creep, each recording's, the agreement and the verdict, and the
/// [sensor_creep] to paste (null unless they agree). A standard error that is not finite is null.
std::string creep_json_text(const CreepFindings& f);

/// creep.html: self-contained (inline SVG and CSS, no script, no network).
std::string render_creep_html(const CreepFindings& f);

}  // namespace gaitmon::cli
