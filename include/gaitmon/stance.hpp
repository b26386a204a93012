// Per region and per frame of one stance: force (eq 42), active-sensor area, contact ellipse and
// load-fitted footprint.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "gaitmon/config.hpp"
#include "gaitmon/contact_ellipse.hpp"
#include "gaitmon/footprint.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/segmentation.hpp"
#include "gaitmon/types.hpp"

namespace gaitmon {

/// One region at one instant of a stance.
struct RegionSample {
  double force_n = 0.0;          ///< eq 42 over the region's active sensors (zeroed bits)
  double sensor_area_mm2 = 0.0;  ///< active sensors x sensing area
  int active_sensors = 0;        ///< sensors at or above the adaptive threshold
  ContactEllipse ellipse;        ///< seed chapter 4; ellipse.kase None when no contact
  /// The paraboloid footprint fitted to the active cells' loads (footprint.hpp); nullopt when
  /// they do not determine it. measure_frame fits it free where the cells allow, else at the
  /// region box's aspect; measure_stance at the stance's shared aspect and over the cells under
  /// the threshold too.
  std::optional<double> footprint_area_mm2;
  /// The free fit of this frame alone (bits), where it is a plausible cap.
  std::optional<Footprint> free_footprint;
  /// The footprint of averaging cells (footprint_area_cell_mean_mm2) at the stance's shared
  /// aspect, where measure_stance was asked for it and the cells determine it.
  std::optional<double> footprint_cell_mean_area_mm2;
  /// Measured with a crosstalk correction: of the force the uncorrected readings give the region
  /// (its cells at or above the threshold as read), what those cells read of other regions' cells
  /// (N). The rest grows with the region's own load: its cells' own, and their share of each
  /// other's. 0 without a correction.
  double spill_in_n = 0.0;
};

/// Whether measure_stance also fits the footprint of averaging cells: a nonlinear fit per region
/// and frame, so only where the analysis will use it.
enum class CellMeanFootprint { Skip, Fit };

class CrosstalkCorrection;  // crosstalk.hpp

/// Every frame of one stance, heel strike to toe off inclusive.
struct StanceSeries {
  std::vector<double> t_s;                                     ///< per frame, the session's clock
  std::vector<std::array<RegionSample, kRegionCount>> frames;  ///< per frame, per region
  std::vector<double> total_force_n;                           ///< per frame, the sum over regions

  std::size_t size() const { return t_s.size(); }
  const RegionSample& at(std::size_t frame, Region region) const {
    return frames[frame][index_of(region)];
  }
};

/// Buffers measure_frame reuses, so measuring a frame allocates nothing once they have grown.
struct FrameScratch {
  std::vector<double> zeroed;
  std::vector<ActiveCell> cells;
  std::vector<LoadedCell> loaded;
  std::vector<CellCentre> unloaded;
  std::vector<LoadedCell> region;  ///< every cell of a region, zeroed but not thresholded
  std::vector<double> readings;    ///< the frame zeroed, before the threshold
};

/// One frame: zeroes the raw bits with `zero`, applies the adaptive threshold and measures every
/// region (force, active-sensor area, contact ellipse, footprint). `first_instant` is Case 1's
/// first instant of a stance. The live monitor calls it per frame; measure_stance per stance frame.
/// Throws std::invalid_argument if `raw` or `zero` does not have the layout's sensor count.
std::array<RegionSample, kRegionCount> measure_frame(
    std::span<const std::uint8_t> raw, std::span<const double> zero, double threshold_bits,
    const InsoleLayout& layout, const Calibration& calibration, bool first_instant,
    ContactEllipseCache* cache, FrameScratch& scratch);

/// Zeroes each stance frame with the step's per-sensor zero, applies its adaptive threshold, and
/// measures every region. The first frame of the stance is the "first instant" of Case 1. Each
/// region's footprints are then fitted again at the aspect its free fits share over the stance
/// (shared_aspect; the region's box where no frame had one), and once more over all its cells
/// without the threshold (footprint_area_unthresholded_mm2), which is kept where it is within
/// 15 % of the thresholded fit; where the two differ by more, the frame has no footprint.
/// With CellMeanFootprint::Fit, each region-frame with active cells also gets the footprint of
/// averaging cells at the same shared aspect.
/// Contact patterns repeat from frame to frame and step to step, so a caller measuring many
/// steps passes one cache for all of them (results are identical with or without it).
/// With `crosstalk`, each frame's zeroed readings are corrected for it before the threshold, and
/// the threshold is the same share of the corrected readings' highest summed reading over the
/// stance as the step's is of Step::max_summed_bits (the step's own where that is not positive;
/// 0 where the corrected readings sum to nothing positive).
StanceSeries measure_stance(const Step& step, const InsoleLayout& layout,
                            const Calibration& calibration, ContactEllipseCache* cache = nullptr,
                            CellMeanFootprint cell_mean = CellMeanFootprint::Skip,
                            const CrosstalkCorrection* crosstalk = nullptr);

/// Both readings' fits (fit_cell_cap) to the same region-frames: which reading fits them better.
struct CellReadingFits {
  int frames = 0;       ///< region-frames where both readings' fits converged
  int mean_better = 0;  ///< of them, those the averaging cells fit with the smaller residual
  int cells = 0;        ///< the residuals summed over the frames (every cell of each region)
  double centre_residual_ss = 0.0;  ///< summed over the frames, bits^2
  double mean_residual_ss = 0.0;    ///< summed over the frames, bits^2

  CellReadingFits& operator+=(const CellReadingFits& other);
  /// The reading that fits better in at least three quarters of at least 10 frames, with the
  /// smaller summed residual too; nullopt where the frames do not say (too few, or split).
  std::optional<CellReading> favoured() const;
};

/// What steps say of how the insole's cells read the pressure (CellReading), which decides which
/// footprint fits them (`--area footprint` or `footprint-mean`): both readings' fits to the same
/// region-frames, each step's frame of a region's largest summed reading where at least
/// kMinEvidenceCells cells reach the threshold. Crosstalk spreads a cap's readings onto the
/// cells around it as averaging does, so the fits are made with the readings' crosstalk undone
/// at each of kCouplings, and the evidence is that of the coupling the better reading fits best.
struct CellReadingEvidence {
  static constexpr int kMinEvidenceCells = 8;
  /// A longer walk is weighed at this many steps spread evenly over it: about a thousand
  /// region-frames, where ten can favour a reading. Weighing all 1090 foot-steps of a ten-minute
  /// session at every coupling took 0.36 s of its analysis on two cores, these 0.07 s.
  static constexpr std::size_t kMaxSteps = 200;
  /// Crosstalk couplings (CrosstalkCorrection) the readings are weighed at; the plausible
  /// couplings the matrix simulates run to 0.1 and the grid past it, so that its least there
  /// has neighbours on both sides.
  static constexpr std::array<double, 9> kCouplings{0.0,  0.02, 0.04, 0.06, 0.08,
                                                    0.10, 0.12, 0.14, 0.16};
  /// The least coupling() that shows crosstalk: on the simulator's sessions it was 0 in all 96
  /// without crosstalk on either raster, 0.045-0.104 with couplings of 0.05-0.1 (README, "How
  /// the cells read").
  static constexpr double kShownCoupling = 0.03;
  /// A coupling is taken only where it brings the better reading's residual RMS to at most this
  /// share of that as read. With crosstalk of 0.05-0.1 it came to 0.26-0.80 of it; without,
  /// the least fell to 0.86-0.99 of it at couplings of 0.015-0.086 on averaging cells of sizes
  /// 43-44 and 45-46, whose caps leave 1.0-1.3 bits (README, "How the cells read").
  static constexpr double kMaxResidualRatioWithCoupling = 5.0 / 6.0;
  std::array<CellReadingFits, kCouplings.size()> at_coupling;

  CellReadingEvidence& operator+=(const CellReadingEvidence& other);
  /// The index into kCouplings where either reading's residual RMS over the cells is least, or
  /// 0 where that is more than kMaxResidualRatioWithCoupling of the least as read.
  std::size_t best_index() const;
  /// The fits at best_index(): what the cells' reading is judged by.
  const CellReadingFits& fits() const { return at_coupling[best_index()]; }
  /// The coupling the readings fit best with undone: the parabola through the best reading's
  /// residual at best_index() and its neighbours on the grid, at its vertex (the grid's end
  /// where the least is there; 0 with no frames).
  double coupling() const;
  std::optional<CellReading> favoured() const { return fits().favoured(); }
  /// Whether the cells show crosstalk: some region-frame weighed, at kShownCoupling or more.
  bool shows_crosstalk() const { return fits().frames > 0 && coupling() >= kShownCoupling; }
};

/// The evidence of one step, its readings zeroed with the step's zero and its threshold; the
/// aspect of each frame's fits is that frame's free footprint's (the region's box where it has
/// none). Throws std::invalid_argument as measure_stance does for a frame or zero of the wrong
/// size.
CellReadingEvidence cell_reading_evidence(const Step& step, const InsoleLayout& layout);

/// The evidence of every step, or of kMaxSteps spread evenly over a longer walk, the steps on
/// every core and summed in step order, so that the sums are the same every run.
CellReadingEvidence cell_reading_evidence(std::span<const Step> steps, const InsoleLayout& layout);

}  // namespace gaitmon
