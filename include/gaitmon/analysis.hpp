// The per-step analysis pipeline: one stance -> per-region series -> tissue fits, and the
// session-level summary over many steps. Free of I/O so the live monitor can call it per step.
#pragma once

#include <array>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "gaitmon/asymmetry.hpp"
#include "gaitmon/config.hpp"
#include "gaitmon/contact_ellipse.hpp"
#include "gaitmon/drift.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/pooling.hpp"
#include "gaitmon/segmentation.hpp"
#include "gaitmon/stance.hpp"
#include "gaitmon/tissue_fit.hpp"
#include "gaitmon/types.hpp"

namespace gaitmon {

/// Which contact area Ae(t) the fit is given. `Ellipse` is the seed's contact ellipse of the
/// active cells (chapter 4). `Footprint` is the paraboloid fitted to the active cells' loads
/// (footprint.hpp): a region-step with at least kMinFootprintFrames frames whose cells determine
/// it is fitted on those frames alone, and one with fewer on its contact ellipse throughout. It
/// recovers simulated truths better (README, "How the fit works"), so it is the default.
///
/// `FootprintMean` is the footprint of cells that average the pressure over their area
/// (footprint_area_cell_mean_mm2), with the same rule for its frames and fallback: on such cells
/// (the simulator's coverage raster; real insoles) the footprint is biased and n comes out about
/// twice the truth (README); it costs a nonlinear fit per region and frame.
///
/// Why not the footprint where determined and the ellipse elsewhere: the two disagree by up to a
/// cell's area where they meet, early and late in the contact, and that step in the area is a
/// spike in its rate, which the fit took for damping and the discrepancy workflow for physics.
enum class AreaSource { Ellipse, Footprint, FootprintMean };
/// "ellipse", "footprint", "footprint-mean"
std::string_view area_source_name(AreaSource source);
std::optional<AreaSource> parse_area_source(std::string_view text);

/// The footprint a session's cells call for (`--area auto`): footprint-mean where the evidence
/// favours cells that average the pressure, else the footprint.
AreaSource footprint_for(const CellReadingEvidence& evidence);

/// Twice the four free parameters of the default fit.
inline constexpr int kMinFootprintFrames = 8;

/// The fit's bounds come from Config::fit_bounds.
struct AnalysisSettings {
  FitSettings fit;
  AreaSource area = AreaSource::Footprint;
};

/// One region of one step: what was measured, what was declared and what was fitted.
struct RegionAnalysis {
  Region region = Region::Heel;
  /// Per stance frame: time, contact area (AreaSource; 0 in a frame left out of the fit), force.
  RegionSeries series;
  AreaSource area = AreaSource::Ellipse;  ///< the area the fit was given
  EllipsoidParams declared;  ///< A, B from P and the step's aspect; C, d0 from Appendix I
  double aspect = 0.0;       ///< A/B used: median ra/rb over contact frames, else Appendix I's
  RegionFit fit;
  /// What sits between the tissue and the cells in `fit` (fit_steps_with_effects), which the
  /// session-level fit then takes in too; null for the baseline.
  std::shared_ptr<const ForceTransform> effects;
  double peak_force_n = 0.0;
  double peak_area_mm2 = 0.0;
  int frames = 0;            ///< stance frames in which the region has a contact ellipse
  double t_contact_s = 0.0;  ///< the first of those frames (0 if none)
};

struct StepAnalysis {
  Foot foot = Foot::Left;
  int step = 0;
  double t_heel_strike_s = 0.0;
  double t_toe_off_s = 0.0;
  std::array<RegionAnalysis, kRegionCount> regions;
  std::vector<double> t_s;
  std::vector<double> measured_total_force_n;  ///< per frame, the sum of the regions' forces
  std::vector<double> model_total_force_n;     ///< per frame, the sum of the regions' model forces
  double nrmse_total_pct = 0.0;                ///< eq 58 on the totals above
  ModelVariant model = ModelVariant::Correct;  ///< the damping form the regions were fitted with

  const RegionAnalysis& at(Region region) const { return regions[index_of(region)]; }
};

/// The declared parameters of one region: C and d0 are Appendix I's means, P = pi A B with
/// Appendix I's mean A and B, split by `aspect` = A/B (A = sqrt(P aspect / pi)); kbar, n, cbar,
/// m are Appendix I's means (the fit's starting point in Identifiable mode). Throws
/// std::invalid_argument unless aspect is positive and finite.
EllipsoidParams declared_params(const SeedTissueStats& seed, double aspect);

/// The contact area the fit is given for one region over a stance (0 in frames without a contact
/// ellipse and in frames it leaves out), and which area that is (see AreaSource).
std::pair<std::vector<double>, AreaSource> fit_areas_mm2(const StanceSeries& stance, Region region,
                                                         AreaSource source);

/// Measures the stance (measure_stance) and fits every region. Regions without contact come
/// back with status NoContact; a region whose fit fails or has no model force contributes zero
/// model force to the total. Deterministic; no I/O. Pass one cache for many steps.
StepAnalysis analyse_step(const Step& step, const InsoleLayout& layout, const Config& config,
                          const AnalysisSettings& settings, ContactEllipseCache* cache = nullptr);

/// analyse_step of every step, on every core (the steps are independent, and fits dominate), each
/// thread with an ellipse cache of its own; the result does not depend on the threads.
/// `on_progress`, if set, receives the fraction of the steps done, on the calling thread only.
std::vector<StepAnalysis> analyse_steps(std::span<const Step> steps, const InsoleLayout& layout,
                                        const Config& config, const AnalysisSettings& settings,
                                        const std::function<void(double)>& on_progress = {});

/// The step's model total per frame and its NRMSE from its regions' fits, as analyse_step sets
/// them: for a caller that fits regions again.
void set_model_totals(StepAnalysis& step);

/// One damping exponent m per region, nothing where there is none.
using SharedExponents = std::array<std::optional<SharedExponent>, kRegionCount>;

/// The m per region at which the steps whose fit of that region is Ok fit best together, each
/// with its own kbar, n and cbar (fit_shared_damping_exponent): one step mostly leaves m at a
/// bound of its range (README, "What one step can determine"). Nothing for a region where no step
/// was fitted at every m tried. The default fit only (throws std::invalid_argument otherwise).
/// The regions run in parallel on every core; the result does not depend on it.
SharedExponents shared_damping_exponents(std::span<const StepAnalysis> steps, const Config& config,
                                         const AnalysisSettings& settings);

/// Fits each region of the step whose fit is Ok again at its shared m, where it has one
/// (FitSettings::declared_m); its m then carries the shared m's standard error and bound flag
/// (m.free is false). A region whose fit at the shared m fails keeps its own. The model totals
/// follow.
void fit_at_shared_exponents(StepAnalysis& step, const SharedExponents& shared,
                             const Config& config, const AnalysisSettings& settings);

/// `analyze --m-per-session`: shared_damping_exponents over the steps, then each step fitted at
/// them (fit_at_shared_exponents). Returns the shared m per region.
SharedExponents fit_damping_exponent_per_session(std::span<StepAnalysis> steps,
                                                 const Config& config,
                                                 const AnalysisSettings& settings);

/// Median and interquartile range of one parameter across steps (linear interpolation between
/// order statistics, as numpy's default). All zero when there are no values.
struct Spread {
  int count = 0;
  double median = 0.0;
  double q1 = 0.0;
  double q3 = 0.0;
  double iqr() const { return q3 - q1; }
};

Spread spread_of(std::vector<double> values);

/// One region over a whole session.
struct RegionSessionAnalysis {
  Region region = Region::Heel;
  int steps_with_contact = 0;
  int steps_fitted = 0;  ///< per-step fits with status Ok
  /// Steps with contact given the contact ellipse although the settings ask for a footprint:
  /// the region's cells determined a footprint in fewer than kMinFootprintFrames frames (the toes'
  /// one to four active cells). Their fits rest on an area that moves in whole cells.
  int steps_on_ellipse = 0;
  double aspect = 0.0;  ///< median of the steps' aspects (Appendix I's if none)
  EllipsoidParams declared;
  RegionFit session_fit;  ///< one parameter set for every stance with contact
  /// The per-step fits pooled across the steps (pool_region_steps), over the steps fitted Ok whose
  /// four parameters the data determine; `pooling.steps` holds their posteriors in step order.
  PooledEstimates pooling;
  /// Aligned with analyse_session's `steps`: each step's pooled kbar, n, cbar, m, or nothing
  /// where the step was not pooled (no contact, a failed fit, or too few steps to pool). Their
  /// standard errors hold chain_sd, as pooled_mean's do: a posterior leans on the mean.
  std::vector<std::optional<MaterialParams>> pooled_per_step;
  /// [pooling]'s SDs of the error every step of this region shares, on the pooled scale (ln kbar,
  /// n, ln cbar, m); [pooling.m_per_session]'s where the steps were fitted at one m.
  MaterialVector chain_sd{};
  /// The pooled mean, its covariance mu's (the steps' scatter) with chain_sd added: the region's
  /// tissue over the session with the chain's shared error. Nothing where not pooled.
  std::optional<MaterialEstimate> pooled_mean;
  /// The per-step kbar's and cbar's trends over the session (drift.hpp), over the steps whose
  /// four parameters the data determine and which left that parameter off its bounds, and for cbar
  /// were fitted on a footprint (the contact ellipse's area does not determine the damping);
  /// nothing with fewer than kMinTrendSteps such steps or spanning less than kMinTrendSpan_s.
  std::optional<LogTrend> kbar_trend, cbar_trend;
  /// The right foot's kbar and cbar against the left's (asymmetry.hpp), over the same steps as
  /// the trends; nothing with fewer than kMinAsymmetryStepsPerFoot such steps of either foot.
  std::optional<FootAsymmetry> kbar_asymmetry, cbar_asymmetry;
  /// One m for the region's steps where the caller fitted them so
  /// (fit_damping_exponent_per_session); nothing otherwise.
  std::optional<SharedExponent> m_per_session;
  /// Across the steps fitted Ok.
  Spread A_mm, B_mm, C_mm, d0_mm, kbar_n_per_mm3, n, cbar_ns_per_mm3, m, nrmse_pct;
};

struct SessionAnalysis {
  std::array<RegionSessionAnalysis, kRegionCount> regions;
  Spread nrmse_total_pct;
};

/// The chain's tables for fits given `area`: [pooling.footprint_mean] and
/// [asymmetry.footprint_mean] for footprint-mean (cells that average the pressure, whose chain
/// errs otherwise), [pooling] and [asymmetry] for the footprint and the ellipse.
const PoolingSettings& pooling_tables(const Config& config, AreaSource area);
const AsymmetrySettings& asymmetry_tables(const Config& config, AreaSource area);

/// The config's name of the table pooling_tables() or asymmetry_tables() gives, `kind` "pooling"
/// or "asymmetry": "[pooling]", "[pooling.m_per_session]", "[pooling.footprint_mean]", ...
std::string chain_table_name(std::string_view kind, AreaSource area, bool shared_m);

/// The measurement chain's SDs of `region` on the pooled scale (ln kbar, n, ln cbar, m): those of
/// `pooling.m_per_session` for steps fitted at one m per region, else of `pooling.per_step`.
MaterialVector chain_sd(const PoolingSettings& pooling, Region region, bool shared_m);

/// The same for the error each step's own fit makes beyond its Jacobian's (ChainSds' *_step_sd).
MaterialVector step_sd(const PoolingSettings& pooling, Region region, bool shared_m);

/// A region's steps' own estimates (material_estimate) pooled across the steps (pool_steps within
/// the fit's bounds), each step's m first held within its range (within_m_range) and its
/// variances then taking its own error beyond its Jacobian's (step_sd): the pool weighs the steps
/// by their errors against the tissue, and a posterior leans
/// on its step no more than that error allows. At a shared m on kbar, n and cbar only: m's
/// variance there is the session's, one for every step.
PooledEstimates pool_region_steps(std::span<const MaterialEstimate> estimates, Region region,
                                  const PoolingSettings& pooling, const FitBounds& bounds);

/// The pooled mean of `pooling` with `chain_sd` added (with_shared_error): the region's tissue
/// over the pooled steps, carrying the error every step shares, which pooling cannot average
/// down. Nothing where the steps were not pooled.
std::optional<MaterialEstimate> pooled_mean_with_chain_error(const PooledEstimates& pooling,
                                                             const MaterialVector& chain_sd);

/// A region-step's own kbar, n, cbar and m with standard errors against the tissue rather than
/// against the session's other steps: its fit's covariance (material_estimate) with the
/// measurement chain's error that every step of the region shares (with_shared_error, chain_sd;
/// at a shared m that m's whole error reaches kbar, n and cbar through their slopes) and the
/// step's own beyond its Jacobian's (step_sd, on each parameter's variance). At the step's own m
/// its variance is first held within the range of m that `bounds` give (within_m_range). The
/// fit's own standard errors describe how the steps scatter and miss both (README, "How honest
/// the standard errors are"). Nothing where the fit has no material estimate.
std::optional<MaterialParams> with_chain_error(const RegionFit& fit, Region region,
                                               const PoolingSettings& pooling,
                                               const FitBounds& bounds);

/// The session-level fit per region (fit_region_session over the series of every step with
/// contact in that region), the spread of the per-step fits and their pooling across steps (both
/// feet together, as the session fit). `steps` are analysed Ok steps.
/// The regions are fitted in parallel on every core; the result does not depend on it.
SessionAnalysis analyse_session(std::span<const StepAnalysis> steps, const Config& config,
                                InsoleSize size, const AnalysisSettings& settings);

}  // namespace gaitmon
