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
// p = p_max (1 - rho^2) whatever the material: it vanishes exactly on the contact ellipse. With
// the ellipsoid's axes along the insole's (A lateral-medial, B anterior-posterior) the pressure
// at a cell centre (x, y) is the axis-aligned quadratic
//     p = c0 + c1 x + c2 y + c3 x^2 + c4 y^2,
// and p >= 0 is the ellipse (x - x*)^2 / rA^2 + (y - y*)^2 / rB^2 <= 1 with
// p_max = c0 - c1^2 / (4 c3) - c2^2 / (4 c4), rA^2 = -p_max / c3, rB^2 = -p_max / c4, so
//     area = pi p_max / sqrt(c3 c4).
// The quadratic is fitted to the active cells' loads by linear least squares. The overall scale
// of the loads cancels, so any unit (bits, N) serves.
//
// Cells in two rows (the midfoot) do not see the anterior-posterior curvature c4. There the
// caller's aspect rA / rB (the region's box: the footprint grows into its region in the region's
// shape) fixes it: c4 = c3 rA^2 / rB^2, leaving 1, x, y and x^2 + (rA / rB)^2 y^2. A wrong aspect
// gives a wrong area, so the free quadratic is always tried first.
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
// The caller then uses the contact ellipse.
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

/// The area (mm^2) of the paraboloid footprint fitted to the cells, or nullopt when the cells do
/// not determine it or `unloaded`, the region's cells that read nothing, contradict it (see
/// above); `aspect` (rA / rB) is used only where the cells do not give it.
/// Never throws for any cell values; non-finite cells give nullopt. Throws std::invalid_argument
/// if the cell size or the aspect is not finite and positive.
std::optional<double> footprint_area_mm2(std::span<const LoadedCell> cells, CellSize size,
                                         double aspect, std::span<const CellCentre> unloaded = {});

}  // namespace gaitmon
