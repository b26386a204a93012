// The contact area of one region at one instant from its cells' loads rather than their count.
//
// Why: the seed's contact ellipse (contact_ellipse.hpp) sees only which cells are active, so its
// area moves in steps of one cell and misses the footprint's low-pressure rim, which falls below
// the adaptive threshold. F grows about as Ae^(2+n), so those errors bias the fitted stiffness
// exponent n (model-notes.md, section 4).
//
// Derivation: for a contact small against the ellipsoid (g = d/C << 1; at the heel g ~ 0.05),
// eqs 14 and 15 give a local indentation delta = d (1 - rho^2) (1 + O(g)) and a rate
// deltadot = ddot (1 - rho^2) (1 + O(g)), so the pressure k delta + c deltadot is a paraboloid
// p = p_max (1 - rho^2) whatever the material: it vanishes exactly on the contact ellipse. (Not
// so with a fixed tissue column's rate, ModelVariant::MaterialRate: deltadot = ddot throughout,
// the pressure is c ddot on the rim, and this estimator's area is biased; README, The model.) With
// the ellipsoid's axes along the insole's (A lateral-medial, B anterior-posterior) the pressure
// at a cell centre (x, y) is the axis-aligned quadratic
//     p = c0 + c1 x + c2 y + c3 x^2 + c4 y^2,
// and p >= 0 is the ellipse (x - x*)^2 / rA^2 + (y - y*)^2 / rB^2 <= 1 with
// p_max = c0 - c1^2 / (4 c3) - c2^2 / (4 c4), rA^2 = -p_max / c3, rB^2 = -p_max / c4, so
//     area = pi p_max / sqrt(c3 c4).
// The quadratic is fitted to the active cells' loads by linear least squares. The overall scale
// of the loads cancels, so any unit (bits, N) serves.
//
// A given aspect rA / rB fixes c4 = c3 rA^2 / rB^2, leaving 1, x, y and x^2 + (rA / rB)^2 y^2.
// The ellipsoid's contact keeps one aspect, A / B, at every depth (eqs 5, 6), so measure_stance
// takes it from the stance's well-loaded frames (shared_aspect) and fits every frame with it: a
// frame at a partial load has too few cells to give its own curvature ratio. Cells in two rows
// (the midfoot) never see c4; where no frame of the stance gives it, the caller's aspect (the
// region's box: the footprint grows into its region in the region's shape) stands in. A wrong
// aspect gives a wrong area (tested).
//
// It is undetermined, and nullopt is returned, when even that fit is not determined (one row;
// fewer than four cells, as a toe of one to three cells: their loads carry no curvature, and the
// loads of cells placed symmetrically about the footprint carry no size), when the fit is not a
// cap (c3 or c4 >= 0, or p_max <= 0: a plateau or a saturated region), when the area is
// outside 0.5-2 times the active sensor area, the seed's plausibility rule for its ellipses
// (4.1.3), or when the cap puts more than a quarter of its peak pressure on the centre of a
// region cell that reads nothing. A covered cell reads; a quarter of the peak is 87 % of the way
// to the rim, which leaves the rim's cells, whose few bits noise and zeroing can take, their
// margin. Without that last rule a frame whose loads are nearly flat now and then extrapolated
// to twice its neighbours' area, a spike the fit and the discrepancy workflow took for physics.
// The caller then leaves the frame without a footprint.
//
// All of this assumes a cell reads the pressure at its centre. Cells that average it over their
// area (the simulator's coverage raster; real insoles) read the concave cap low inside and high
// on the partly covered rim, the quadratic through those readings is flatter and wider, and the
// fitted n comes out about twice the truth (README). footprint_area_cell_mean_mm2 fits a forward
// model of such cells instead: each cell's mean of the clipped paraboloid p_max max(0, 1 - rho^2)
// over its area, by nonlinear least squares over every cell of the region.
#pragma once

#include <optional>
#include <span>

#include "gaitmon/contact_ellipse.hpp"

namespace gaitmon {

/// One active cell: its centre in the grid frame and its zeroed load (any unit).
struct LoadedCell {
  double x_mm = 0.0;
  double y_mm = 0.0;
  double load = 0.0;
};

/// The centre of a region cell that reads nothing.
struct CellCentre {
  double x_mm = 0.0;
  double y_mm = 0.0;
};

/// The free (five-term) fit of a frame's cells where it is a plausible cap: its area, its aspect
/// rA / rB and its peak load (the unit of the loads).
struct Footprint {
  double area_mm2 = 0.0;
  double aspect = 0.0;
  double peak = 0.0;
};

/// The free fit of the cells, or nullopt when they do not determine it or `unloaded`, the
/// region's cells that read nothing, contradict it (see above). Never throws for any cell
/// values; non-finite cells give nullopt. Throws std::invalid_argument if the cell size is not
/// finite and positive.
std::optional<Footprint> free_footprint(std::span<const LoadedCell> cells, CellSize size,
                                        std::span<const CellCentre> unloaded = {});

/// The area of the four-term fit with the aspect rA / rB given, whatever the cells could say of
/// it; nullopt as for free_footprint. Throws std::invalid_argument as free_footprint does, and if
/// the aspect is not finite and positive.
std::optional<double> footprint_area_at_aspect_mm2(std::span<const LoadedCell> cells, CellSize size,
                                                   double aspect,
                                                   std::span<const CellCentre> unloaded = {});

/// The area of the four-term fit at `aspect` over all of a region's cells, read without the
/// adaptive threshold: starting from the cells at or above `threshold_bits`, the fit takes in
/// every cell its cap covers, whatever it reads (zeroed bits, so also under the threshold or
/// below zero), and leaves out every cell it does not, until the set of cells stops changing.
/// Why: where the pressure is low for the contact's size (at toe off) the threshold cuts off a
/// wide rim, and the cap's size rests on the few cells left; the rim's low readings are unbiased
/// looks at the pressure there (noise of half a bit dithers the rounding). On the simulator's
/// raster at three quarters of the sensor area and a fifth of the force, the thresholded fit's
/// area scatters by 2-3.5 %, this one's by 1.2-1.5 % (tests/footprint_test.cpp). It holds only
/// where an unloaded cell reads its zero: a sensor that still reads after the load has gone (creep)
/// breaks it, which is why the caller checks it against the thresholded fit (measure_stance).
/// nullopt as for free_footprint (with no cell counted as reading nothing: every cell the cap
/// covers is in the fit). Throws std::invalid_argument as footprint_area_at_aspect_mm2 does.
std::optional<double> footprint_area_unthresholded_mm2(std::span<const LoadedCell> region_cells,
                                                       CellSize size, double aspect,
                                                       double threshold_bits);

/// The area of the clipped paraboloid p_max max(0, 1 - rho^2) at `aspect` whose means over the
/// cells best match their readings: least squares over every cell of `region_cells` (zeroed, not
/// thresholded: a cell reading about nothing says the cap does not reach it), free p_max, centre
/// and rA. Why: where a cell averages the pressure over its area, the four-term fit, which takes
/// each reading as the pressure at the cell's centre, is biased (see above); on such readings
/// this one recovers the area to within a few per cent (tests/footprint_test.cpp). On cells that
/// do read at their centres it is the biased one. It starts from the four-term fit's cap over
/// the cells at or above `threshold_bits` (or, where that is no cap, from their centroid and
/// area). nullopt when fewer than four cells reach the threshold, when the fit does not converge
/// or is not a cap, or when its area is outside 0.5-2 times those cells' sensor area. It does not
/// check the low readings against the thresholded fit as footprint_area_unthresholded_mm2's
/// caller does, so a sensor still reading after its load has gone (creep) widens it. Throws
/// std::invalid_argument as footprint_area_at_aspect_mm2 does.
std::optional<double> footprint_area_cell_mean_mm2(std::span<const LoadedCell> region_cells,
                                                   CellSize size, double aspect,
                                                   double threshold_bits);

/// How a cell turns the pressure over it into its reading.
enum class CellReading {
  Centre,  ///< the pressure at the cell's centre (the simulator's centre raster)
  Mean,    ///< the pressure averaged over the cell's area (the coverage raster)
};

/// The clipped paraboloid's fit to a region's cells as they read it.
struct CellCapFit {
  double area_mm2 = 0.0;
  double residual_ss = 0.0;  ///< the sum of the squared residuals, in the readings' unit squared
  int cells = 0;             ///< the residuals: every cell of the region
};

/// The fit of footprint_area_cell_mean_mm2 with each cell read as `reading` says, its residual
/// sum of squares beside the area: with the same four free parameters over the same cells, the
/// two readings' sums compare directly, and the smaller says how the insole's cells read
/// (cell_reading_evidence, stance.hpp). CellReading::Mean gives footprint_area_cell_mean_mm2's
/// area. nullopt and throws as footprint_area_cell_mean_mm2 does.
std::optional<CellCapFit> fit_cell_cap(std::span<const LoadedCell> region_cells, CellSize size,
                                       double aspect, double threshold_bits, CellReading reading);

/// The aspect shared by a stance's footprints of one region: the mean of their log aspects
/// weighted by their peak squared, or nullopt if there is none. Why: the ellipsoid's contact
/// keeps the aspect A / B at every depth (eqs 5, 6), and a frame's own curvature ratio, from a
/// few cells at a partial load, scatters (10 % in area at half the peak); fixing it from the
/// well-loaded frames leaves each frame two fewer terms.
std::optional<double> shared_aspect(std::span<const Footprint> footprints);

}  // namespace gaitmon
