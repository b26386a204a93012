// The session simulator: synthetic walking sessions (session CSV v1) from the ellipsoid model,
// with a ground-truth JSON of the parameters, the steps and their events.
//
// Pipeline, per frame and foot: contact-area trajectory per region -> tissue force per region
// (the shared model, then any tissue-stage effect) -> pressure field rasterised onto the
// region's cells, rescaled to the force -> sensor reading (bits, then any sensor-stage effect,
// then any frame-stage effect over the foot's cells together, then dc bias, Gaussian noise,
// rounding and clipping to 0..255).
//
// Gait: the right foot's stance starts half a stride after the left's; each stride and each
// stance duration is the nominal one times (1 + z jitter_pct/100), z standard normal truncated
// to [-3, 3]; a stance is shortened if needed to leave 0.2 x stride_s of swing before the same
// foot's next stance (never binds with the defaults). The recording starts at a uniformly random
// phase, so the first and last steps may be cut.
//
// Within a stance each region's contact area is a C1 bump (rising and falling half-cosines)
// over a window fixed as fractions of the stance's contact (heel first, then midfoot,
// metatarsals, toes; met1_2 and toe1 last to leave) and zero outside it. Each region's peak
// area is chosen, by bisection on the model, so that its peak ELASTIC force is
// kPeakElasticForceShare x body weight, capped so that the contact ellipse is at most 0.9 x the
// region's sensor area and 0.95 x the largest ellipse inside the region's bounding box (the truth
// says where the cap bound). The footprint is centred on that box (unless placement_sd_mm moves it
// per stance) and stretched, keeping its area, from the ellipsoid's aspect A/B to the box's aspect:
// the insole only sees a region's own cells, and an ellipse spilling out of one side would make the
// measured area stop growing while the force still grows. Force against area, all the fit sees, is
// unchanged by the stretch. The force grows about as area^(2+n), so the 40 N events span about 85 %
// of the contact: with the defaults a stance from heel strike to toe off lasts about 0.50-0.66 s,
// like the seed's 52-60 frames. The tissue is the same in every step and under both feet unless
// tissue_step_sd_pct, tissue_drift_pct_per_min or tissue_asymmetry_pct says otherwise.
//
// Determinism: one std::mt19937_64 seeded with the seed drives every draw in a fixed order
// (phase, gait durations, dc biases of L then R sensors, the tissue's step factors if asked
// for, the placement shifts if asked for, then noise per frame, L then R, in sensor order); uniform
// doubles are the top 53 bits of a draw, normals come from Box-Muller. So the draws are the same on
// every machine. The physics uses libm's pow, cos and log, which can differ in the last bit between
// C libraries; the bytes are identical for a given build and library.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "gaitmon/config.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/tissue_model.hpp"
#include "gaitmon/types.hpp"

namespace gaitmon {

/// How a region's pressure field becomes cell loads (model-notes section 4).
/// CellCentre: a cell carries the pressure at its centre times its area if its centre is in the
/// contact ellipse; if no centre is, the cell nearest the ellipse's centre takes the whole force.
/// Coverage: a cell carries the pressure averaged over its area (8 x 8 sub-samples), so partly
/// covered cells read partly; if no sub-sample is covered, the nearest cell takes the force.
/// Either way the loads are then rescaled to sum exactly to the region's force, and negative
/// loads (possible only with the SeedEq25 sign) are set to 0 before rescaling.
/// The simulator's default is CellCentre.
enum class Rasterisation { CellCentre, Coverage };

/// "centre" or "coverage".
std::string_view rasterisation_name(Rasterisation mode);
std::optional<Rasterisation> parse_rasterisation(std::string_view text);

/// Peak elastic force of each region as a share of body weight (m g), indexed by index_of(
/// Region): heel 0.75, midfoot posterior 0.12, midfoot anterior 0.12, met1-2 0.40, met3-5 0.50,
/// toe1 0.12, toe2 0.03, toes3-5 0.06. The regions peak at different times of the stance (the
/// heel alone early, the metatarsals together late), so the foot's total force peaks at about
/// one body weight, less where the contact-area cap binds (heel and toes with the Appendix I
/// means of size 37-38 at 60 kg).
inline constexpr std::array<double, kRegionCount> kPeakElasticForceShare{0.75, 0.12, 0.12, 0.40,
                                                                         0.50, 0.12, 0.03, 0.06};

/// Largest contact ellipse the simulator lets a region reach, as a fraction of the region's
/// sensor area, and as a fraction of the largest ellipse inside the region's bounding box (so
/// the footprint stays on the region's own cells, which is all the insole can measure).
inline constexpr double kMaxContactFractionOfSensorArea = 0.9;
inline constexpr double kMaxContactFractionOfInscribedEllipse = 0.95;

/// Parameters of one simulation effect by name (e.g. {"tau_s", 0.1}); the ones left out take
/// their defaults (simulation_effect_params).
using EffectParams = std::map<std::string, double>;

/// How far one stance moved the foot's footprints from their regions' box centres, mm.
struct PlacementShift {
  double x_mm = 0.0;  ///< lateral-medial
  double y_mm = 0.0;  ///< anterior-posterior
};

struct GaitTiming {
  double stride_s = 1.10;         ///< heel strike to the same foot's next heel strike, (0.5, 3]
  double stance_fraction = 0.62;  ///< contact (any load) / stride duration, [0.3, 0.8]
  double jitter_pct = 3.0;        ///< SD of each stride and stance duration, % of nominal, [0, 10]
};

struct SimulationOptions {
  InsoleSize size = InsoleSize::S37_38;
  double duration_s = 60.0;  ///< (0, 86400]
  std::uint64_t seed = 1;
  double body_mass_kg = 60.0;  ///< (0, 300]
  GaitTiming timing;
  ModelVariant model = ModelVariant::Correct;
  Rasterisation rasterisation = Rasterisation::CellCentre;
  double noise_sd_bits = 0.5;  ///< Gaussian noise on every reading, [0, 50]
  /// Step-to-step variation of the tissue: each stance and region multiplies kbar and cbar by
  /// independent log-normal factors with this SD of their logarithm, in % ([0, 100]; 0 keeps
  /// every step at the region's parameters). The contact area keeps its course, so the force
  /// follows the factors. For checking estimators that pool the steps (pooling.hpp).
  double tissue_step_sd_pct = 0.0;
  /// A steady change of the tissue over the session: a stance starting t minutes into the
  /// recording has kbar and cbar multiplied by (1 + pct / 100)^t, on top of the step factors
  /// ([-20, 20]; 0 keeps them). For checking the drift estimate (drift.hpp).
  double tissue_drift_pct_per_min = 0.0;
  /// A difference between the feet: every stance of the right foot has kbar and cbar multiplied
  /// by 1 + pct / 100, on top of the step and drift factors ([-50, 50]; 0 keeps the feet alike).
  /// For checking the comparison of the feet (asymmetry.hpp).
  double tissue_asymmetry_pct = 0.0;
  /// Step-to-step placement of the foot on the insole: each stance shifts all of the foot's
  /// footprints by independent normal offsets with this SD along x and y, in mm ([0, 10]; 0
  /// keeps every footprint on its region's box centre). A real foot does not land on the same
  /// spot of the cell grid every step, so the raster's error in the measured area changes from
  /// step to step instead of repeating (README, "How honest the standard errors are").
  double placement_sd_mm = 0.0;
  /// Per-sensor dc bias, a uniform integer in min..max bits, 0 <= min <= max <= 50. A cell whose
  /// bias is under about two noise SDs reads its noise clipped at 0 in the swing (README, "Sensor
  /// creep of the insoles": what that does to a creep measured from the zeros).
  int min_bias_bits = 0;
  int max_bias_bits = 2;
  /// Per region; empty means the seed's Appendix I means for the size (Config::seed_tissue).
  std::array<std::optional<EllipsoidParams>, kRegionCount> region_params;
  /// Named physical effects (simulation_effect_names()), applied in this order.
  std::vector<std::string> effects;
  /// Parameters per effect name; an effect without an entry uses its defaults.
  std::map<std::string, EffectParams> effect_params;
  std::string subject = "simulated";
};

/// One stance as the recording shows it. Frames are 0-based per foot; heel strike and toe off
/// are the first and last frames where the noise-free, bias-free total force of the foot exceeds
/// event_threshold_bits x newtons_per_bit.
struct SimulatedStep {
  Foot foot = Foot::Left;
  int index = 0;  ///< 0-based per foot, in time order
  double t_heel_strike_s = 0.0;
  double t_toe_off_s = 0.0;
  std::int64_t heel_strike_frame = 0;
  std::int64_t toe_off_frame = 0;
  /// The planned contact (any load) in recording time; may begin before 0 or end after the end.
  double t_contact_start_s = 0.0;
  double t_contact_end_s = 0.0;
  bool partial = false;  ///< the contact began before the first or ended after the last frame
  std::array<double, kRegionCount> peak_force_n{};  ///< per region, over the recorded frames
  double peak_total_force_n = 0.0;
  /// Per region, the factors on kbar and cbar of this stance (SimulationOptions::
  /// tissue_step_sd_pct, tissue_drift_pct_per_min and tissue_asymmetry_pct).
  std::array<double, kRegionCount> kbar_factor{}, cbar_factor{};
  /// Where this stance put the foot (SimulationOptions::placement_sd_mm).
  PlacementShift placement_shift;
};

struct SimulatedRegion {
  EllipsoidParams params;
  double sensor_area_mm2 = 0.0;  ///< the region's cells x one cell's area
  double peak_area_mm2 = 0.0;    ///< the contact ellipse's area at the bump's peak
  double target_elastic_force_n = 0.0;
  double peak_elastic_force_n = 0.0;  ///< reached at peak_area_mm2; below target if capped
  bool area_capped = false;
};

struct SimulationTruth {
  SimulationOptions options;
  double sample_rate_hz = 0.0;
  std::int64_t frames_per_foot = 0;
  double newtons_per_bit = 0.0;
  double event_threshold_n = 0.0;
  double start_phase_s = 0.0;  ///< gait time at the first frame, in [0, stride_s)
  std::array<SimulatedRegion, kRegionCount> regions;
  std::array<std::vector<int>, 2> dc_bias_bits;  ///< [foot][sensor]
  std::vector<SimulatedStep> steps;              ///< both feet, by heel strike time
  std::uint64_t negative_force_samples = 0;      ///< region-frames whose force was < 0, set to 0
  std::uint64_t clipped_high_samples = 0;        ///< readings above 255 before clipping
  std::uint64_t clipped_low_samples = 0;  ///< readings below 0 before clipping (noise at rest)
};

/// Simulates a session: writes the session CSV and the truth JSON, returns the truth. The cells
/// creep as the config's [sensor_creep] says unless `options` name sensor_creep themselves; the
/// truth's options then list it among the effects. Throws
/// std::invalid_argument naming the option for an out-of-range option or unknown effect, and
/// std::runtime_error if a file cannot be written.
SimulationTruth simulate_session(const Config& config, const SimulationOptions& options,
                                 const std::filesystem::path& csv_out,
                                 const std::filesystem::path& truth_json_out);

/// The contact area (mm^2) at which the region's elastic force (ddot = 0) equals
/// `target_force_n`, by bisection, or `max_area_mm2` if even that falls short.
double contact_area_for_elastic_force(const EllipsoidParams& params, double target_force_n,
                                      double max_area_mm2);

/// The simulator's planned contact area of `region` (mm^2) at `fraction` of a contact's duration
/// (0 at its start, 1 at its end), and its rate in mm^2 per unit fraction (divide by the contact's
/// duration for mm^2/s): the smooth bump the area stage follows. Lets a caller rebuild the exact
/// area course without the sensors, as the estimation bounds in the tests do.
std::pair<double, double> planned_contact_area_mm2(const SimulatedRegion& simulated, Region region,
                                                   double fraction);

/// Per-cell loads (N), in the order of layout.region_sensors(region), for one region whose
/// ellipsoid is deformed by d at rate ddot: the contact ellipse (radii from eqs 5, 6, axes along
/// the grid's x and y) is centred at the centroid of the region's cells in the grid frame
/// (Sensor::grid_x_mm, grid_y_mm; cells are sensor width x height there) moved by `shift`, and
/// the loads are rescaled to sum to `force_n` (all zero if force_n <= 0 or d <= 0).
std::vector<double> rasterise_region(const InsoleLayout& layout, Region region,
                                     const EllipsoidParams& params, double d_mm,
                                     double ddot_mm_per_s, ModelVariant variant, Rasterisation mode,
                                     double force_n, PlacementShift shift = {});

/// One region of one foot at one frame, as a tissue-stage effect sees it.
struct TissueSample {
  Foot foot = Foot::Left;
  Region region = Region::Heel;
  double t_s = 0.0;
  double t_contact_start_s = 0.0;  ///< when this stance's contact (any load) began
  double area_mm2 = 0.0;
  double d_mm = 0.0;
  double ddot_mm_per_s = 0.0;
  double frame_interval_s = 0.01;  ///< between frames; the effect is not called out of contact
};

/// One sensor of one foot at one frame, as a sensor-stage effect sees it.
struct SensorSample {
  Foot foot = Foot::Left;
  std::size_t sensor = 0;
  double t_s = 0.0;
};

/// A named physical effect on top of the ellipsoid model (relaxation, hysteresis, saturation,
/// ...). One instance lives for one session and sees each foot's frames in time order, so it
/// may keep state. The defaults leave the value unchanged, so an effect overrides only its stage.
class SimulationEffect {
 public:
  virtual ~SimulationEffect() = default;
  /// Tissue stage: the region's force (N) from the model, before it is rasterised.
  virtual double tissue_force_n(const TissueSample& /*sample*/, double force_n) { return force_n; }
  /// Sensor stage: a reading (bits, unrounded) before dc bias, noise, rounding and clipping.
  virtual double sensor_bits(const SensorSample& /*sample*/, double bits) { return bits; }
  /// Frame stage: one foot's whole frame of readings (bits, unrounded, in sensor order) after
  /// the sensor stage, for an effect that couples cells.
  virtual void sensor_frame(const InsoleLayout& /*layout*/, std::span<double> /*bits*/) {}
};

/// The effect names simulate_session accepts; "none" is the model alone. The effects and their
/// physics are described in src/simulation_effects.cpp and the README.
std::vector<std::string_view> simulation_effect_names();

/// One parameter of an effect: its default and the physically plausible range it must lie in.
struct EffectParamSpec {
  std::string_view name;
  double default_value = 0.0;
  double min = 0.0;
  double max = 0.0;
  std::string_view meaning;
};

/// The parameters `name` takes (empty for "none"); throws std::invalid_argument for an unknown
/// name.
std::vector<EffectParamSpec> simulation_effect_params(std::string_view name);

/// `params` completed with the defaults; throws std::invalid_argument naming the effect and the
/// parameter for an unknown name, an unknown parameter or a value outside its range.
EffectParams resolve_effect_params(std::string_view name, const EffectParams& params);

/// The effect for `name` with `params` (resolved as above): nullptr for "none"; throws
/// std::invalid_argument as resolve_effect_params does.
std::unique_ptr<SimulationEffect> make_simulation_effect(std::string_view name,
                                                         const EffectParams& params = {});

}  // namespace gaitmon
