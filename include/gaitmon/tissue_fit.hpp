// Per-region fits of the ellipsoid tissue model to measured contact area and force (seed 5.2),
// restricted by default to what the data determine (shared/docs/model-notes.md section 2).
//
// Outcomes are values, never exceptions: a fit that fails is returned with its status and
// reason. Exceptions are only for misuse (inconsistent series lengths, bad settings).
#pragma once

#include <array>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "gaitmon/tissue_model.hpp"

namespace gaitmon {

/// How the measured series are prepared before fitting.
/// `None` (default): the raw series, gdot by central differences. `Seed`: the seed's 5.1.1/5.1.2
/// smoothing (3-point moving average then a 5th-order polynomial in normalised time for the area,
/// a 5th-order polynomial for the force), gdot from the polynomial. `None` is the default because
/// it recovers simulated truths better where the cells determine the contact area (heel, midfoot,
/// metatarsals; tests/tissue_fit_test.cpp prints both, README figures). `Seed` did better with the
/// contact ellipse's area, whose one-cell steps it smooths; the load-fitted footprint has none.
enum class Smoothing { None, Seed };
std::string_view smoothing_name(Smoothing smoothing);  ///< "none", "seed"
std::optional<Smoothing> parse_smoothing(std::string_view text);

/// gdot at the first and last frame of each run of contact (raw series only; inside a run it is
/// the central difference). `TwoFrame` (default): the difference to the one neighbour, which is
/// the rate half a frame inward, where the area curves most. `SecondOrder`: (-3 A0 + 4 A1 - A2) /
/// 2h, exact for a quadratic course. The second has no such bias but more noise, so it helps only
/// where many steps are pooled (README, "Per-step estimates pooled across steps").
enum class EndRate { TwoFrame, SecondOrder };
std::string_view end_rate_name(EndRate rate);  ///< "two-frame", "second-order"
std::optional<EndRate> parse_end_rate(std::string_view text);

/// Which parameters are free.
/// `Identifiable` (default): kbar, n, cbar, m; A/B from the measured ellipses, P = pi A B, C and
/// d0 declared (config). `Seed8`: the seed's 8-parameter fit, all of A, B, C, d0, kbar, n, cbar,
/// m free, started at the midpoint of the bounds.
enum class FitMode { Identifiable, Seed8 };
std::string_view fit_mode_name(FitMode mode);  ///< "identifiable", "seed8"
std::optional<FitMode> parse_fit_mode(std::string_view text);

struct Bounds {
  double lower = 0.0;
  double upper = 0.0;
};

/// Bounds per parameter (from config; derived from the seed's Appendix I).
struct FitBounds {
  Bounds A_mm, B_mm, C_mm, d0_mm;
  Bounds kbar_n_per_mm3, n, cbar_ns_per_mm3, m;
};

struct FitSettings {
  ModelVariant model = ModelVariant::Correct;
  FitMode mode = FitMode::Identifiable;
  Smoothing smoothing = Smoothing::None;
  EndRate end_rate = EndRate::TwoFrame;
  bool free_scale = false;  ///< also free P = pi A B (keeping A/B), Identifiable mode only
  /// Starts of the general solver (free P, seed8) around the principled initial guess. The
  /// default fit needs none: it searches the whole (n, m) box with K and D solved exactly.
  int starts = 4;
  int max_iterations = 100;
  /// m declared instead of fitted (the default fit only: Identifiable, P declared): kbar, n and
  /// cbar are fitted at this m. One step mostly leaves m at a bound of its range, and a region's
  /// m is better taken over all a session's steps (fit_shared_damping_exponent).
  std::optional<double> declared_m;
};

/// One region over one stance (or several stances for a session-level fit): the measured
/// contact-ellipse area and force per frame. Frames without contact have area 0.
struct RegionSeries {
  std::vector<double> t_s;
  std::vector<double> area_mm2;
  std::vector<double> force_n;
};

/// Half-open [begin, end) index ranges of the runs of frames with contact (area > 0), in order.
/// Rates are taken within a run, never across a frame without contact.
struct FrameRun {
  std::size_t begin = 0;
  std::size_t end = 0;
};
std::vector<FrameRun> contact_runs(std::span<const double> area_mm2);

enum class FitStatus { Ok, NoContact, Failed };
std::string_view fit_status_name(FitStatus status);  ///< "ok", "no_contact", "fit_failed"

struct Estimate {
  double value = 0.0;
  double se = 0.0;        ///< standard error from the Jacobian at the optimum
  bool at_bound = false;  ///< within a small tolerance of a bound
  bool free = false;      ///< fitted (false: declared)
};

using MaterialCovariance = std::array<std::array<double, 4>, 4>;

struct RegionFit {
  FitStatus status = FitStatus::NoContact;
  std::string reason;  ///< why it failed, for fit_failed:<reason>
  int frames = 0;      ///< frames with contact that were fitted
  Estimate A_mm, B_mm, C_mm, d0_mm, kbar_n_per_mm3, n, cbar_ns_per_mm3, m;
  std::string solver_message;
  int iterations = 0;
  double final_cost = 0.0;
  double nrmse_pct = 0.0;                 ///< eq 58: RMS error / max measured force x 100
  std::vector<double> model_force_n;      ///< per input frame (0 where no contact)
  std::vector<std::string> undetermined;  ///< parameters the data cannot determine (seed8)
  /// In the default mode (Identifiable, P declared) with all four determined: the covariance of
  /// (ln kbar, n, ln cbar, m), sigma^2 (J^T J)^-1 as for the standard errors.
  std::optional<MaterialCovariance> material_covariance;
  /// With m declared (FitSettings::declared_m) and the other three determined: how the fitted
  /// (ln kbar, n, ln cbar) move with the declared m, -(J^T J)^-1 J^T dr/dm at the optimum (to
  /// first order, as the covariance). An error in an m declared to many steps moves them all
  /// alike, which their covariance at that m does not hold; pool_steps carries it.
  std::optional<std::array<double, 3>> material_slope_on_m;

  EllipsoidParams params() const {
    return {A_mm.value,
            B_mm.value,
            C_mm.value,
            d0_mm.value,
            kbar_n_per_mm3.value,
            n.value,
            cbar_ns_per_mm3.value,
            m.value};
  }
};

/// A known map from a region's tissue force to the force its cells report, for a fit with effects
/// in the model (`gaitmon analyze --effects`): reported = offset_n + linear(tissue force), per
/// frame of the series. `linear` must be linear; it is given the tissue force in every frame of
/// the series, 0 in the frames the fit leaves out. The fit then finds the tissue under the
/// effects, and RegionFit::model_force_n is the reported force. The default fit only
/// (Identifiable, P declared): the others throw std::invalid_argument given one.
struct ForceTransform {
  std::vector<double> offset_n;
  std::function<void(std::span<const double> tissue_n, std::span<double> reported_n)> linear;
};

/// Fits one region. `declared` supplies A, B, C, d0 (A/B is usually the step's median contact
/// ellipse aspect, P and C, d0 from config) and, in Seed8 mode, nothing (the bounds' midpoints are
/// used). Deterministic. Throws std::invalid_argument if the series lengths differ.
/// `transform`, if given, sits between the tissue and the cells (ForceTransform).
RegionFit fit_region(const RegionSeries& series, const EllipsoidParams& declared,
                     const FitBounds& bounds, const FitSettings& settings,
                     const ForceTransform* transform = nullptr);

/// One parameter set shared by several stances of the same region (each series is one stance;
/// gdot never crosses from one stance to the next). `transforms` is empty or holds one per stance
/// (nullptr: none for that stance); a size that differs throws std::invalid_argument.
RegionFit fit_region_session(std::span<const RegionSeries> stances, const EllipsoidParams& declared,
                             const FitBounds& bounds, const FitSettings& settings,
                             std::span<const ForceTransform* const> transforms = {});

/// One damping exponent m for a region over several stances, each with its own kbar, n and cbar.
struct SharedExponent {
  double m = 0.0;
  /// From the curvature of the summed cost over m (the others fitted again at each m), scaled by
  /// the residuals' variance; like every standard error from the fit's residuals, it does not
  /// hold the error the measurement chain gives every stance alike.
  double se = 0.0;
  bool at_bound = false;
  int stances = 0;  ///< stances in the sum: those fitted Ok at every m tried
};

/// The m at which the stances' fits at a declared m (FitSettings::declared_m) have the least
/// summed cost: a grid over the bounds of m, then a golden-section search between the best grid
/// point's neighbours. A stance whose fit fails at a grid point is left out of the sum. Returns
/// nothing if no stance is fitted at every grid point. Throws std::invalid_argument if the spans
/// differ in length, or as fit_region does (the default fit only).
std::optional<SharedExponent> fit_shared_damping_exponent(std::span<const RegionSeries> stances,
                                                          std::span<const EllipsoidParams> declared,
                                                          const FitBounds& bounds,
                                                          const FitSettings& settings);

/// eq 58 for one series: RMS(measured - model) / max(measured) x 100.
double nrmse_pct(std::span<const double> measured, std::span<const double> model);

namespace detail {

/// The default fit's residuals and their analytic Jacobian, so that tests can check the
/// derivatives the Levenberg-Marquardt step relies on against finite differences. Internal.
struct SeparableResiduals {
  std::vector<double> residual;                 ///< N data rows, then N penalty rows
  std::vector<std::array<double, 4>> jacobian;  ///< d residual / d (ln kbar, n, ln cbar, m)
};

/// At theta = (ln kbar, n, ln cbar, m), for `series` prepared as fit_region prepares it under
/// `settings` (P, C and d0 from `declared`). Throws std::invalid_argument as fit_region does.
SeparableResiduals separable_residuals(const RegionSeries& series, const EllipsoidParams& declared,
                                       const FitSettings& settings,
                                       const std::array<double, 4>& theta);

}  // namespace detail

}  // namespace gaitmon
