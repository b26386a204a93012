// The model-data discrepancy workflow (issue 5): where the fitted tissue model and the
// measurements disagree, which missing physical effect explains it, and how much adding that
// effect helps on steps it was not fitted on. Free of I/O.
//
// Baseline. Each step's regions are fitted by analyse_step. The workflow keeps each fit's
// damping exponent m and declared geometry and writes the model as F = K E(n) + D V (E, V the
// elastic and damping shapes of the measured contact area, as in tissue_fit, over the frames
// the fit was given, and at the heel the stance frames before them in which it reads a load:
// a few cells give no area there and the model expects next to nothing, so their force is all
// residual; n is re-chosen from the fit's own value and a grid of nine, and K,
// D >= 0 are re-solved by least squares, per step and region, with every effect as without.
// Baseline and extended models are then nested: an effect of zero strength is the baseline.
//
// Candidates: named extensions with a few parameters SHARED by all the session's steps, while
// n, K, D stay per step and region (re-solved for every parameter value):
//   stress_relaxation  F_meas = F - g LP_tau(F)                (strength g, tau_s)
//   sensor_creep       F_meas = F + beta LP_tau(F); zeroed steps: the zeros (below)
//                                                              (gain beta, tau_s)
//   hysteresis         F_meas = F (1 + h z(d)), Dahl state z   (strength h, transition_mm)
//   impact_transient   heel F_meas = F + a sin(pi (t - t0) / T) (amplitude_n, duration_s;
//                      t0, 0 to 2 frames before the heel's first frame with a load, is
//                      each step's own, chosen by its fit as n is)
//   sensor_saturation  F_meas = F phi^-(2 + n) (1 - L^2), L = 1 - c phi^(1 + n) / p, where
//                      p = 2 F / cells / N-per-bit is the peak reading of a paraboloid pressure
//                      over the measured contact and phi(L) = (1 + L + L^2) / (1 + L) how much
//                      wider the footprint fitted to capped cells is (ceiling_bits c; n = 0.3)
//   thermal_drift      the zeros only: a region's zero moves by its cells x r x the time between
//                      the steps' zero windows (rate_bits_per_min r)
//   crosstalk          the model driven by the area of readings corrected for a coupling k to
//                      the cells' edge neighbours, F_meas = g F(A_k) + s: g = (measured - s) /
//                      corrected, the region's own load as mixing raised it (held to
//                      [0, 1 + 4 k]), s what its cells read of other regions' cells (coupling
//                      k; the steps measured again at 8 couplings from 0.01 to 0.2,
//                      measure_crosstalk_views, and interpolated between them)
// LP_tau is a first-order lag running through the foot's steps in time order (the lag carried
// into a step is that of the measured force of the foot's earlier steps, decayed over the
// swing).
//
// The zero channel. The segmenter zeroes each step with its cells' mean reading in two swing
// windows around it (seed 3.3.1). A sensor that creeps reads its lagged load there too, so the
// zeroing takes the creep's level off the stance and the zeros rise with it instead. The
// workflow observes the change of each step-region's zero from the foot's step before: 0 for
// the baseline (an unloaded sensor reads its dc bias), beta times the change of the region's lag
// averaged over the two windows for sensor_creep. Where a chain of consecutive steps does not
// start at the foot's first contact (the recording began in stance), the lag it starts with is
// unknown and is solved for (>= 0, least squares, one per chain, counted in BIC). On a zeroed
// step the creep's stance force is left to the baseline: the rise within one stance that the
// zeroing leaves is about proportional to the load, and the step's own K takes it up.
//
// Fitting. Each candidate is fitted on a grid of its parameters (profiled over every step's K,
// D) and refined by a pattern search, minimising the deviance N_eff ln SSE_force + N_zero ln
// SSE_zero: each channel with its own residual variance (the zeros' residuals are some hundred
// times smaller than the force's, and a plain sum of squares would let the force decide alone).
// N_eff = N (1 - r1) / (1 + r1), r1 the lag-1 autocorrelation of the baseline's force residuals;
// N_zero the observed changes. Standard errors come from the curvature of the profiled deviance
// (none for a parameter at a bound of its range); beside them the step-clustered sandwich's,
// which hold where the residuals of a step's regions are correlated or the model is not the
// data's (ParamEstimate::robust_se).
//
// Choice. Steps are split into k folds (by time order, step i in fold i mod k); a candidate's
// held-out error is that of each fold's steps under the parameters fitted on the other folds.
// A candidate passes when its held-out NRMSE of the force is at least min_shrink_pct below the
// baseline's, or that of the zero changes at least min_zero_shrink_pct, its BIC (both channels)
// is at least min_delta_bic below, every parameter has a finite standard error (an optimum on a
// bound or along a flat direction is not an effect the data show), and, for sensor_saturation and
// crosstalk, the readings show a ceiling or cells beside a contact reading a share of their
// neighbours'. Of those that pass, the one whose held-out deviance falls most below the
// baseline's is named. A second effect is named on top of the first by the same rules against
// the first at its all-steps parameters (which it runs on).
//
// Region-steps fitted on the contact ellipse (a toe whose cells never determine its footprint)
// are left out when the session has footprints: the ellipse moves in whole cells, and its misfit
// would swamp the effects sought.
//
// Zero levels. zero_level_drift reports each foot's summed zero over the session as a
// diagnostic: a creeping or thermally drifting insole shows there whatever the candidates say.
//
// NRMSE here is pooled eq 58: 100 sqrt(sum of squared residuals / sum over step-regions of
// frames x (max measured force)^2), so regions weigh by their force.
#pragma once

#include <array>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <span>
#include <stdexcept>
#include <stop_token>
#include <string>
#include <string_view>
#include <vector>

#include "gaitmon/analysis.hpp"
#include "gaitmon/config.hpp"
#include "gaitmon/creep.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/segmentation.hpp"
#include "gaitmon/stance.hpp"
#include "gaitmon/types.hpp"

namespace gaitmon {

/// The candidate effects, in the order they are tried.
std::vector<std::string_view> discrepancy_effect_names();

/// Throws std::invalid_argument naming the known effects unless `name` is one of them.
void check_discrepancy_effect(std::string_view name);

/// One analysed step and what the workflow needs beyond the fits.
/// One step measured again with its readings corrected for crosstalk of one coupling
/// (CrosstalkCorrection): per region and stance frame, the area the analysis's area source gives
/// (fit_areas_mm2) and the force; and per region which area that is.
struct CrosstalkView {
  double coupling = 0.0;
  /// Per region and stance frame: the corrected area and force, and RegionSample::spill_in_n.
  std::array<std::vector<double>, kRegionCount> area_mm2, force_n, spill_in_n;
  std::array<AreaSource, kRegionCount> source{};
};

struct DiscrepancyStep {
  StepAnalysis analysis;
  /// Per region and stance frame: cells within kSaturationBandBits of the session's highest
  /// zeroed reading (a reading that has stopped rising). Empty means unknown (all zero).
  std::array<std::vector<int>, kRegionCount> saturated_cells;
  /// At each coupling the crosstalk candidate interpolates between (measure_crosstalk_views);
  /// empty if the step was not measured again, and the candidate then leaves it alone.
  std::vector<CrosstalkView> crosstalk;
  double zero_bits = 0.0;         ///< the step's summed-bits zero (Step::bias_bits)
  double peak_summed_bits = 0.0;  ///< its highest zeroed summed bits (Step::max_summed_bits)
  /// Per region: its cells' zero summed (N), what the per-step zeroing took off the region.
  std::array<double, kRegionCount> region_zero_n{};
  /// When the zero's swing windows were read (Step::pre_zero_t_s, post_zero_t_s); NaN if not.
  double pre_zero_t_s = std::numeric_limits<double>::quiet_NaN();
  double post_zero_t_s = std::numeric_limits<double>::quiet_NaN();
};

/// A cell counts as saturated within this many bits of the session's highest zeroed reading.
inline constexpr double kSaturationBandBits = 3.0;

/// Cells count in NeighbourShare where their edge neighbours read this much together (zeroed):
/// a crosstalk of 1 % then gives them 0.6 bits, twice the noise of one reading's rounding.
inline constexpr double kNeighbourShareBits = 60.0;
/// Fewer such cell-frames, and the share is not judged: crosstalk is then not named.
inline constexpr long kMinNeighbourShareCellFrames = 1000;

/// What a cell reads of its edge neighbours' readings (InsoleLayout::neighbours, shares of the
/// edge as weights), where they read kNeighbourShareBits or more together: the 1st percentile
/// over every such cell and stance frame. A cell wholly outside a contact reads nothing (noise
/// about 0) without crosstalk, and its coupling's share of its neighbours' readings with it.
struct NeighbourShare {
  double floor = std::numeric_limits<double>::quiet_NaN();
  long cell_frames = 0;
};

/// The crosstalk coupling the cells' readings fit their caps best with undone
/// (CellReadingEvidence::coupling) and the region-frames that say so; frames -1 where not
/// measured, and crosstalk is then judged by the neighbour share alone.
struct CellCoupling {
  double coupling = 0.0;
  int frames = -1;
};

struct DiscrepancyInput {
  std::vector<DiscrepancyStep> steps;  ///< complete steps of both feet, any order
  double sample_rate_hz = 100.0;
  double cell_area_mm2 = 112.5;
  double newtons_per_bit = 0.2824;
  ModelVariant model = ModelVariant::Correct;  ///< the damping form of the steps' fits
  /// Cells of each region (both feet share the layout): a drift of every cell's unloaded
  /// reading moves a region's zero by that many times its own. 0 where unknown.
  std::array<int, kRegionCount> region_cells{};
  NeighbourShare neighbour_share;  ///< of every step's readings (measure_crosstalk_views)
  CellCoupling cell_coupling;      ///< of every step's readings (measure_crosstalk_views)
};

/// The analysis settings of the workflow's baseline: the raw series (Smoothing::None), because
/// the residuals it studies are those of the measured force itself, and a polynomial fitted to
/// the force first would smooth away the very structure (an impact spike, a flat saturated top)
/// the workflow looks for.
AnalysisSettings discrepancy_analysis_settings();

/// Segmented steps -> analysed steps with saturated-cell counts. Only Ok steps are analysed; they
/// are analysed on all cores and the result does not depend on it.
DiscrepancyInput prepare_discrepancy_input(std::span<const Step> steps, const InsoleLayout& layout,
                                           const Config& config, const AnalysisSettings& settings);

/// The same from steps already analysed: analyses[i] is analyse_step of steps[i]. Throws
/// std::invalid_argument if the counts differ or the analyses used different damping forms.
DiscrepancyInput make_discrepancy_input(std::span<const Step> steps,
                                        std::vector<StepAnalysis> analyses,
                                        const InsoleLayout& layout, const Config& config);

/// Measures each step of `input` (made from `steps`, in the same order) again at each coupling
/// the crosstalk candidate interpolates between, with the area source the steps were analysed
/// with, on all cores; and the readings' NeighbourShare and cell coupling, which the candidate is
/// named by. Only that candidate needs it: prepare_discrepancy_input calls it, and a caller of
/// make_discrepancy_input whose effects name crosstalk does. Throws std::invalid_argument if the
/// counts differ.
void measure_crosstalk_views(DiscrepancyInput& input, std::span<const Step> steps,
                             const InsoleLayout& layout, const Config& config, AreaSource area);

/// What fit_extended_model needs for `effects`: make_discrepancy_input, and
/// measure_crosstalk_views where the effects name crosstalk.
DiscrepancyInput extended_model_input(std::span<const Step> steps,
                                      std::vector<StepAnalysis> analyses,
                                      const InsoleLayout& layout, const Config& config,
                                      std::span<const std::string> effects, AreaSource area);

struct DiscrepancySettings {
  int folds = 5;                ///< k of the k-fold over steps, >= 2
  int phase_bins = 10;          ///< bins of normalised stance time, >= 10
  double min_shrink_pct = 5.0;  ///< held-out NRMSE must fall at least this much, %
  /// or the zero channel's at least this much, %: three times its largest false improvement
  /// (3.1 %) on 17 simulated sessions without an effect; 5 % is 2.6 times the force's (1.95 %).
  double min_zero_shrink_pct = 10.0;
  double min_delta_bic = 10.0;  ///< and BIC at least this much
  /// sensor_saturation is named only where its ceiling shows in the readings: in at least this
  /// many steps, and this share of them, two or more cells of one region read within
  /// kSaturationBandBits of the session's highest reading in one frame (a ceiling's flat top
  /// spans several cells). Without it the candidate's region-level form took up misfit at high
  /// loads in sessions that had no ceiling (5.3 and 7.6 % held-out, size 45-46, no such frame).
  int min_ceiling_steps = 3;
  double min_ceiling_steps_pct = 10.0;
  /// crosstalk is named only where the readings show it: NeighbourShare::floor at least this.
  /// Simulated sessions without crosstalk gave -0.012 to -0.003 (noise about 0: the cells
  /// outside a contact), with a coupling of 0.02 0.0085 to 0.0105, of 0.05 0.028. Without it
  /// the candidate took up misfit of the footprint in size 35-36 (5.4 and 9.8 % held-out) and
  /// in a creep session.
  double min_neighbour_share = 0.005;
  /// and where the cells' readings fit their caps best with at least this crosstalk undone
  /// (DiscrepancyInput::cell_coupling; with no region-frame to weigh, crosstalk is not named).
  /// On cells that average the pressure the share above shows their partly covered rim as well
  /// (0.000-0.061 in the matrix's 21 sessions without crosstalk on that raster, 0.051-0.061 with
  /// it) and the candidate took up the footprint's misfit there; the coupling was 0 in all 96
  /// simulated sessions without crosstalk on either raster and 0.045-0.104 with couplings of
  /// 0.05-0.1 (README, "How the cells read").
  double min_cell_coupling = CellReadingEvidence::kShownCoupling;
  bool second_effect = true;  ///< look for a second effect on top of the first
  int top_cells = 10;         ///< region x phase cells listed under `where`
};

struct ParamEstimate {
  std::string name;
  double value = 0.0;
  double se = 0.0;  ///< from the deviance's curvature: 2 H^-1
  /// The sandwich H^-1 B H^-1, B from the deviance's gradients summed over each step's units: on
  /// ten walks of one simulated pair with a fast creep (size 45-46, gain 0.4, tau 0.5 s) the gains
  /// and taus spread 1.6 and 2.1 times as wide as `se` said (README, "Are the standard errors
  /// right?"). NaN where `se` is, or where it cannot be taken. Where a unit's cost moves in steps
  /// finer than one `se` (a pulse's duration a fraction of a frame) it sees few of them and comes
  /// out small.
  double robust_se = std::numeric_limits<double>::quiet_NaN();
};

struct EffectEstimate {
  std::string name;
  std::vector<ParamEstimate> params;
};

struct CandidateResult {
  std::string name;
  std::vector<ParamEstimate> params;  ///< fitted on all steps
  double in_sample_nrmse_pct = 0.0;
  double heldout_nrmse_pct = 0.0;
  double shrink_pct = 0.0;  ///< held-out, against the model it extends
  /// The zero channel (see DiscrepancyResult::zero_changes): held-out NRMSE of the changes of
  /// the step-regions' zeros, and its shrink against the model it extends.
  double zero_heldout_nrmse_pct = 0.0;
  double zero_shrink_pct = 0.0;
  /// N_eff ln(force SSE) + N_zero ln(zero SSE), held out, of the model it extends less its own:
  /// twice the held-out log-likelihood the candidate gains over both channels. The best
  /// candidate has the largest.
  double heldout_deviance_drop = 0.0;
  double bic = 0.0;
  double delta_bic = 0.0;  ///< against the model it extends
};

/// One region x stance-phase cell of the residual map.
struct ResidualCell {
  Region region = Region::Heel;
  int bin = 0;
  int samples = 0;
  double rms_n = 0.0;          ///< residual RMS
  double bias_n = 0.0;         ///< mean residual (measured - model)
  double noise_floor_n = 0.0;  ///< RMS of the per-frame noise floor
};

struct ResidualMap {
  int bins = 0;
  std::vector<ResidualCell> cells;  ///< region-major, bins cells per region
};

struct RegionComparison {
  Region region = Region::Heel;
  int step_regions = 0;
  double baseline_heldout_nrmse_pct = 0.0;
  double extended_heldout_nrmse_pct = 0.0;
};

struct StepComparison {
  Foot foot = Foot::Left;
  int step = 0;
  double baseline_nrmse_pct = 0.0;
  double extended_nrmse_pct = 0.0;  ///< held-out
};

/// Pearson correlation of the residual (scaled by its step-region's peak force) with one state.
struct StateCorrelation {
  std::string state;
  double r = 0.0;
};

struct ResidualDiagnostics {
  std::vector<double> bias_per_phase_pct;  ///< mean residual / peak force per phase bin, %
  double lag1_autocorrelation = 0.0;       ///< within step-regions
  double runs_z = 0.0;                     ///< Wald-Wolfowitz runs test, pooled
  double effective_sample_fraction = 1.0;  ///< (1 - r1) / (1 + r1)
  std::vector<StateCorrelation> correlations;
};

/// The zero level of one foot's steps over the session. The segmenter zeroes each step at the
/// swings around it (seed 3.3.1), which takes a reading's slow drift out of the force: a sensor
/// that creeps under load, or a thermal drift, shows here instead, as a zero that moves by more
/// than it scatters from step to step. A diagnostic: it names no effect.
struct ZeroLevelDrift {
  Foot foot = Foot::Left;
  int steps = 0;
  double first_bits = 0.0;  ///< the zero of the foot's first complete step
  double last_bits = 0.0;
  double lowest_bits = 0.0;
  double highest_bits = 0.0;
  /// Robust SD of one zero level about the next: 1.4826 x the median absolute difference of
  /// successive zeros / sqrt 2.
  double scatter_bits = 0.0;
  double range_pct_of_peak = 0.0;  ///< 100 (highest - lowest) / the median step's peak
  /// highest - lowest is more than kZeroDriftScatters x max(scatter, 1 bit) and at least
  /// kZeroDriftPctOfPeak % of the peak.
  bool drifting = false;
  /// Each step's heel strike time and zero, in time order: the course the report plots.
  std::vector<double> t_s, zero_bits;
};

/// A drift must stand out of the step-to-step scatter of the zero...
inline constexpr double kZeroDriftScatters = 10.0;
/// ...and be large enough to matter to the force. On 16 simulated sessions without an effect
/// (12 and 60 s, sizes 37-38 to 45-46) the range stayed within 0.7 % of the peak; on 5 with
/// sensor creep (gain 0.15-0.4, tau 0.5-2 s) it reached 3.9-6.5 % on the more drifting foot.
inline constexpr double kZeroDriftPctOfPeak = 2.0;

/// The zero levels of each foot with at least 3 steps, in time order of heel strike.
std::vector<ZeroLevelDrift> zero_level_drift(const DiscrepancyInput& input);

/// What the workflow found on a session read again with the sensor creep that its zeros name undone
/// in every frame (find_discrepancy_undoing_creep).
struct CreepUndoneInReadings {
  EffectEstimate creep;  ///< as named on the readings as read
  int steps = 0;         ///< complete steps of the readings with it undone
  /// The baseline's held-out NRMSE there: how much of the gap undoing the creep closes by itself.
  double baseline_heldout_nrmse_pct = 0.0;
  /// The most likely candidate there (on top of the creep), and why it was not named; empty
  /// where it was.
  std::string most_likely_candidate;
  std::string not_named_reason;
};

struct DiscrepancyResult {
  int steps = 0;
  int step_regions = 0;
  /// Fitted on the contact ellipse (AreaSource) while other region-steps had a footprint: left
  /// out of the comparison.
  int step_regions_left_out = 0;
  long frames = 0;
  double noise_floor_nrmse_pct = 0.0;  ///< the pooled noise floor on the NRMSE scale
  /// The NRMSE's scale, sqrt(sum of frames x peak^2 / frames) over the compared step-regions:
  /// an NRMSE of x % is an RMS residual of x / 100 times this. Sessions whose peaks differ (an
  /// effect that lowers the force) compare in newtons through it.
  double nrmse_scale_n = 0.0;
  double baseline_in_sample_nrmse_pct = 0.0;
  double baseline_heldout_nrmse_pct = 0.0;  ///< the baseline has no shared parameters
  double extended_heldout_nrmse_pct = 0.0;
  double gap_shrink_pct = 0.0;  ///< 100 (1 - extended / baseline)
  /// The zero channel: the change of each step-region's zero from the foot's step just before
  /// (a zero is the region's mean reading in the two swing windows around its step). The
  /// baseline reads nothing without a load, so the zero should not change; a sensor that creeps
  /// reads its lagged load in the swing too, and the zero rises with it. NRMSE over the changes,
  /// each scaled by its step-region's peak force. 0 changes (no channel) when the input has no
  /// zero windows or every zero is the same.
  long zero_changes = 0;
  double zero_baseline_heldout_nrmse_pct = 0.0;
  double zero_extended_heldout_nrmse_pct = 0.0;
  double zero_gap_shrink_pct = 0.0;
  double baseline_bic = 0.0;
  /// Steps with a frame in which two or more cells of one region read at the session's top
  /// (DiscrepancySettings::min_ceiling_steps); -1 where the input has no cell counts.
  int ceiling_plateau_steps = -1;
  NeighbourShare neighbour_share;  ///< the input's (DiscrepancySettings::min_neighbour_share)
  CellCoupling cell_coupling;      ///< the input's (DiscrepancySettings::min_cell_coupling)
  /// With a second, both as fitted once more with the other in place where that predicts the
  /// held-out steps better and leaves every parameter its standard error (as fit_extended_model);
  /// second_candidates have the first as named alone.
  std::vector<EffectEstimate> named_effects;
  /// The candidate whose held-out deviance falls most below the baseline's, and why it was not
  /// named, in words (empty where it was): a clear gain can still leave a parameter
  /// undetermined, and "no missing effect" would hide it. The first named effect is the most
  /// likely of the candidates that pass, which is another one where this one does not.
  std::string most_likely_candidate;
  std::string not_named_reason;
  std::vector<CandidateResult> candidates;  ///< each on top of the baseline
  /// Each on top of the first named effect, or of the creep undone in the readings (creep_undone).
  std::vector<CandidateResult> second_candidates;
  std::vector<ResidualCell> where;  ///< top cells by excess over the noise floor, none under it
  ResidualMap map_before;
  ResidualMap map_after;
  std::vector<RegionComparison> regions;
  std::vector<StepComparison> per_step;
  ResidualDiagnostics diagnostics;
  std::vector<ZeroLevelDrift> zero_levels;  ///< per foot with at least 3 complete steps
  /// Set by find_discrepancy_undoing_creep where it read the session again with the creep undone.
  std::optional<CreepUndoneInReadings> creep_undone;
};

/// Runs the workflow. Deterministic. Throws std::invalid_argument for bad settings or fewer
/// steps than folds. `on_progress`, if set, receives the fraction of the candidate fits done
/// (their k-fold fits are nearly all of the time) after each candidate, on the calling thread;
/// the second round keeps two of its shares for fitting the two named effects once more, and
/// reports them at its end (1), whether or not a second was named.
DiscrepancyResult find_discrepancy(const DiscrepancyInput& input,
                                   const DiscrepancySettings& settings = {},
                                   const std::function<void(double)>& on_progress = {});

/// Reads the session again with `creep` undoing the creep in every frame as it is read, and
/// prepares those steps as the workflow's input was prepared (the same area source).
using ReadWithCreepUndone = std::function<DiscrepancyInput(CreepCorrection creep)>;

/// find_discrepancy on the readings as read, and where it names sensor_creep and
/// effect_undone_in_readings admits it (its zero channel shows it, gain and tau are determined),
/// the workflow once more on the session read again with that creep undone, which looks for one
/// effect on top of it. Why: creep changes the shape of the readings over a region and so each
/// step's footprint, which no map of the force gives back; the baseline then misfits and another
/// candidate takes up the misfit (stress_relaxation on cells that average, seed 116; README,
/// "Sensor creep undone in the readings"). The result is then:
///   - named_effects: sensor_creep as named, then what the readings with it undone name;
///   - baseline held-out NRMSE, where, map_before, candidates, the zero channel and the diagnostics
///     as read; the extended held-out NRMSE, map_after and each region's and step's extended
///     figure from the readings with the creep undone (against their own peaks; a step found in
///     only one of the two readings has NaN there), the creep's gain and tau fitted on all steps;
///   - second_candidates: those of the readings with the creep undone, where sensor_creep is no
///     candidate (its fit there ran to a gain on every reading at a tau of a frame or two on a real
///     recording, and a creep too small to move a reading by a bit is named again as it was);
///   - most_likely_candidate as read, and where that is not named, why, from the readings with
///     the creep undone;
///   - creep_undone set.
/// Otherwise the result of find_discrepancy. `on_progress` as find_discrepancy's, over both.
/// Throws as find_discrepancy, and what `read_with_creep_undone` throws.
DiscrepancyResult find_discrepancy_undoing_creep(
    const DiscrepancyInput& input, const ReadWithCreepUndone& read_with_creep_undone,
    const DiscrepancySettings& settings = {}, const std::function<void(double)>& on_progress = {});

/// The extended model with the named effects (in the given order, each fitted on top of the
/// previous, then each once more with all the others in place where that is kept:
/// fit_extended_model), fitted on all steps: what `gaitmon analyze --effects` reports.
struct ExtendedModelFit {
  std::vector<EffectEstimate> effects;
  double baseline_nrmse_pct = 0.0;  ///< pooled, in sample
  double extended_nrmse_pct = 0.0;  ///< pooled, in sample
  double baseline_heldout_nrmse_pct = 0.0;
  double extended_heldout_nrmse_pct = 0.0;
  long zero_changes = 0;  ///< as DiscrepancyResult
  double zero_baseline_heldout_nrmse_pct = 0.0;
  double zero_extended_heldout_nrmse_pct = 0.0;
  std::vector<RegionComparison> regions;
};

/// Thrown by fit_extended_model when its stop token is triggered.
class FitStopped : public std::runtime_error {
 public:
  FitStopped() : std::runtime_error("the fit was stopped") {}
};

/// Throws std::invalid_argument for an unknown or repeated name, fewer steps than folds, or
/// crosstalk named for steps not measured again for it (extended_model_input does) or where no
/// region-step has a series corrected for it (the views measured from another area source than
/// the analyses), and FitStopped soon after `stop` is requested (the live monitor's shutdown on
/// a signal). The effects are fitted one after another in the order given, each on top of those
/// before it; with two or more, each is then fitted once more with all the others in place, and
/// that round is kept where it predicts the held-out steps better and no parameter loses the
/// standard error it had. `on_progress`, if set, receives the fraction of those fits done after
/// each of the first round and at the end, on the calling thread.
ExtendedModelFit fit_extended_model(const DiscrepancyInput& input,
                                    std::span<const std::string> effects,
                                    const DiscrepancySettings& settings = {},
                                    const std::stop_token& stop = {},
                                    const std::function<void(double)>& on_progress = {});

/// Whether `analyze` undoes the fitted `effect` in the readings before it measures and fits each
/// step again (and find_discrepancy_undoing_creep before it looks for further effects):
/// sensor_creep (creep.hpp), which changes the shape of the readings over a region and so the
/// footprint, which no map of the force can give back. Only where the data show it and determine
/// it: the zero channel, where creep shows, predicts the held-out steps at least
/// `min_zero_shrink_pct` better with the effects (`zero_shrink_pct`, the workflow's rule for
/// naming an effect from it), and gain and tau both have a standard error. On sessions without
/// creep its fit ran to gains of 0.14 and 1.16 at taus of 0.06 and 0.03 s (the first with
/// standard errors), with the zero channel 20 % worse: a gain on every reading, which undone would
/// take a share of each.
bool effect_undone_in_readings(
    const EffectEstimate& effect, double zero_shrink_pct,
    double min_zero_shrink_pct = DiscrepancySettings{}.min_zero_shrink_pct);

/// effect_undone_in_readings for an effect of `fit`, with its zero channel's held-out shrink.
bool effect_undone_in_readings(
    const ExtendedModelFit& fit, const EffectEstimate& effect,
    double min_zero_shrink_pct = DiscrepancySettings{}.min_zero_shrink_pct);

/// The correction of the effect of `fit` that effect_undone_in_readings admits, at its fitted
/// parameters; nullopt where there is none.
std::optional<CreepCorrection> creep_to_undo(
    const ExtendedModelFit& fit,
    double min_zero_shrink_pct = DiscrepancySettings{}.min_zero_shrink_pct);

/// The correction of a fitted sensor_creep at its gain and tau. Throws std::invalid_argument for
/// an estimate without them or outside CreepCorrection's range.
CreepCorrection creep_correction(const EffectEstimate& sensor_creep);

/// `analyze`'s extended model where creep_to_undo(as_read) undid the creep in the readings:
/// `undone` is fit_extended_model of the other effects of as_read (all but sensor_creep, in its
/// order; none gives the baseline) on the session read again with the creep undone. The result
/// keeps as_read's sensor_creep, baseline and zero channel and takes the other effects' estimates
/// and the extended NRMSEs, overall and per region, from `undone`: as
/// find_discrepancy_undoing_creep composes its result, the effects on top of a creep are those of
/// the readings without it (fitted as read, a relaxation took up what the creep did to the
/// footprints). Throws std::invalid_argument where as_read has no sensor_creep or undone's effects
/// are not as_read's others.
ExtendedModelFit with_creep_undone(const ExtendedModelFit& as_read, const ExtendedModelFit& undone);

/// The effects that sit between the tissue and the cells and are affine in the tissue's force:
/// fit_steps_with_effects puts these inside each step's tissue fit.
bool effect_inside_tissue_fit(std::string_view name);

/// Whether the cells show crosstalk (CellReadingEvidence::shows_crosstalk) that `effects` leaves
/// out, so that the fits take it up as tissue: `analyze` and the live monitor then say so.
bool crosstalk_left_out(const CellReadingEvidence& cells, std::span<const std::string> effects);

/// The steps of `input` (in its order) with each region that the workflow compares fitted again
/// (fit_region) with the named effects that effect_inside_tissue_fit admits in its model, at
/// their fitted parameters (`effects`, as fit_extended_model gives them), as a ForceTransform:
/// stress_relaxation (with the lag its region's earlier steps carry in), hysteresis and
/// impact_transient (its onset between two frames chosen per step, as the workflow chooses it:
/// the best fit). Each step's kbar, n, cbar and m are then the tissue's under those effects, and
/// each region's model force is what its cells report. The other effects change nothing here,
/// nor do the regions the workflow leaves out. Throws std::invalid_argument for an unknown
/// effect, a parameter missing from an estimate, or fit settings other than the default fit
/// (Identifiable, P declared).
std::vector<StepAnalysis> fit_steps_with_effects(const DiscrepancyInput& input,
                                                 std::span<const EffectEstimate> effects,
                                                 const Config& config,
                                                 const AnalysisSettings& settings);

/// input.steps[index] as fit_steps_with_effects fits it, without fitting the others: they only
/// give it what they carry in (stress_relaxation's lag of its region's earlier steps). The live
/// monitor fits each new step so, with its window's earlier steps of that foot. Throws as
/// fit_steps_with_effects does, and std::invalid_argument for an index out of range.
StepAnalysis fit_step_with_effects(const DiscrepancyInput& input, std::size_t index,
                                   std::span<const EffectEstimate> effects, const Config& config,
                                   const AnalysisSettings& settings);

/// One effect at given parameters on top of the baseline, nothing fitted but each step's n, K
/// and D (and each step's own choices: sensor_creep's unknown start lags, impact_transient's
/// onset): what the effect itself can explain of a session whose truth is known, a simulated
/// one. Against the fitted candidate it tells the fit of the shared parameters from what the
/// baseline chain leaves. A parameter missing from `params` takes the value of its grid that
/// fits best. Nothing is held out: the parameters come from outside the data.
struct FixedEffectEvaluation {
  std::vector<ParamEstimate> params;  ///< as evaluated (se 0)
  double baseline_nrmse_pct = 0.0;
  double extended_nrmse_pct = 0.0;
  double zero_baseline_nrmse_pct = 0.0;
  double zero_extended_nrmse_pct = 0.0;
};

/// Throws std::invalid_argument for an unknown effect, a parameter it does not have, or a value
/// outside the parameter's bounds.
FixedEffectEvaluation evaluate_effect_at(const DiscrepancyInput& input, std::string_view effect,
                                         const std::map<std::string, double>& params,
                                         const DiscrepancySettings& settings = {});

}  // namespace gaitmon
