// The contact ellipse of one region at one instant, fitted to its active sensor cells (seed 4.1).
//
// Order of the rules, and where the seed had to be interpreted:
//  0. Cells are snapped to the lattice of the grid frame (W/2 in x, because rows of different
//     length are centred and may be offset by half a cell, and H in y), anchored at the first
//     finite cell. Duplicate cells count once; cells with non-finite coordinates, or more than
//     10^6 cells from the anchor, are ignored.
//  1. Case 1 (seed 4.1.1): a cell touching no other active cell of the region (rectangles touching,
//     corners included) is noise and is dropped, except in toe1, toe2 and toes3_5, and except a
//     heel cell flagged `outermost_heel_row` at the first instant of the stance. Neighbours are
//     judged among all active cells before anything is dropped. No cell left: kase None. Exactly
//     one cell left (necessarily an exception): kase Isolated with the Case 2 equations.
//  2. Case 2 (4.1.2): the cells form an exact rectangle of Nr cells per row and Nc consecutive rows
//     over the same x-interval: rA = Nr W / sqrt(pi) (eq 49), rB = Nc H / sqrt(pi) (eq 48), angle
//     0, centre = rectangle centre, PI = 1.
//  3. Case 4 (4.1.4), checked before Case 3 because Case 3's fit fails on long shapes (Fig. 23):
//     Nr = bounding-box width / W rounded half away from zero (offset rows can make it x.5),
//     Nc = bounding-box height / H (the row count for connected shapes), R = Nc / Nr (eq 50).
//     R <= 0.4: rA = (Nr + Nc - 1) W / sqrt(pi) (eq 51), rB = Nc H / sqrt(pi).
//     R >= 2: rA = Nr W / sqrt(pi), rB = (Nr + Nc - 1) H / sqrt(pi) (eq 52).
//     Centre = centroid of the cells, angle 0. The seed says these ellipses have the cells' area;
//     with eqs 51/52 as printed they do not (an L of 5 + 1 cells gets PI = 2), and PI is
//     reported as computed.
//  4. Case 3 (4.1.3), kase Neighbours: for every cell side, the part not shared with an adjacent
//     active cell is exposed; its two ends and its midpoint become boundary points (Fig. 19: cell
//     corners and side midpoints, divot corners included), de-duplicated. An algebraic direct
//     least-squares fit (Halir-Flusser form of Fitzgibbon's) starts a geometric fit that minimises
//     the sum of squared orthogonal distances of the points to the ellipse over centre, radii and
//     angle (Brown 2007, seed App. E), solved by ceres::TinySolver with autodiff. The seed's form
//     carries one angle per point; here each point's angle is eliminated by solving for its
//     closest ellipse point exactly (variable projection): the same objective and minimum, with a
//     5-parameter solve. The gradient of an orthogonal distance with the foot point held fixed is
//     its full gradient (the foot point is stationary), so the autodiff Jacobian is exact.
//     If the algebraic fit yields no ellipse, the geometric fit starts from the moment ellipse.
//  5. Fallback, kase Boundary (4.1.3's fail-safe): the fit has failed if the solver hit its
//     iteration limit, or a value is non-finite, or a radius is not positive, or the area is
//     above twice the sensor area (the seed's rule) or below half of it (added: a collapsed
//     ellipse is as wrong as an inflated one). Then the same fit runs on the boundary points that
//     lie on their convex hull, vertices and points on hull edges alike (the seed used MATLAB
//     boundary(), whose outline skips the divots). With rule 4 this reproduces both areas the seed
//     gives for Fig. 21 (5.9254 and 6.5377 cm^2) on a 2 x 2 block with one more cell above one
//     of its columns, so we take that to be the figure's shape. If that fails the same checks, the
//     moment-equivalent ellipse of the cells (the uniform ellipse with the cells' centroid and
//     second moments, each cell counted as a uniform W x H rectangle) scaled to the sensor area,
//     still kase Boundary, PI = 1.
// Fitted ellipses are reported with ra the semi-axis nearer the x axis (|angle| <= pi/4), so ra
// pairs with the ellipsoid's lateral-medial A and rb with its anterior-posterior B.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "gaitmon/types.hpp"

namespace gaitmon {

/// One active sensor cell: its centre in the contiguous grid frame (Sensor::grid_x_mm/grid_y_mm).
struct ActiveCell {
  double x_mm = 0.0;
  double y_mm = 0.0;
  bool outermost_heel_row = false;  ///< in the most posterior heel row (Case 1 exception)
};

/// The sensing area of one cell: width lateral-medial (x), height anterior-posterior (y).
struct CellSize {
  double width_mm = 7.5;
  double height_mm = 15.0;
};

/// Which rule produced the ellipse; the seed's Cases 1-4 with Case 3 split by point set.
enum class EllipseCase { None, Isolated, Rectangle, Neighbours, Boundary, Long };

/// "none", "isolated", "rectangle", "neighbours", "boundary", "long".
std::string_view ellipse_case_name(EllipseCase kase);

struct ContactEllipse {
  EllipseCase kase = EllipseCase::None;
  double cx_mm = 0.0;  ///< centre, grid frame
  double cy_mm = 0.0;
  double ra_mm = 0.0;            ///< semi-axis along the direction at angle_rad from +x
  double rb_mm = 0.0;            ///< the other semi-axis
  double angle_rad = 0.0;        ///< in [-pi/4, pi/4]
  double area_mm2 = 0.0;         ///< pi ra rb
  double sensor_area_mm2 = 0.0;  ///< cells_used x W x H
  double pi = 0.0;               ///< performance index area / sensor area (eq 53); 0 if None
  int cells_used = 0;
};

/// Fits the contact ellipse of one region's active cells at one instant by the rules above.
/// Never throws on any cell pattern and never returns NaN; an empty or all-noise pattern gives
/// kase None with zeros. Throws std::invalid_argument if the cell size is not finite and positive.
/// Thread-safe; reuses per-thread scratch buffers.
ContactEllipse fit_contact_ellipse(std::span<const ActiveCell> cells, CellSize size, Region region,
                                   bool first_instant);

/// The point sets of the Case 3 fit: all exposed-side points, or those on their convex hull.
enum class BoundaryPoints { Neighbours, ConvexHull };

/// The Case 3 fit alone (rules 0, 4 and 5's checks) on one point set, for comparing the seed's
/// Neighbours and validation (Boundary) PIs of Table 4. No noise removal, no closed-form case and
/// no fallback: nullopt if fewer than two distinct cells or the fit fails its checks. kase is
/// Neighbours or Boundary. Throws std::invalid_argument for a bad cell size.
std::optional<ContactEllipse> fit_irregular_ellipse(std::span<const ActiveCell> cells,
                                                    CellSize size, BoundaryPoints points);

namespace detail {

/// Rule 5's last fallback alone on cells snapped as rule 0 snaps them (no noise removal): the
/// moment-equivalent ellipse, kase Boundary. Exposed for tests, which cannot reach it through a
/// pattern whose Case 3 fits succeed. kase None for no finite cell. Internal.
ContactEllipse moment_ellipse(std::span<const ActiveCell> cells, CellSize size);

}  // namespace detail

/// fit_contact_ellipse with the Case 3 fits memoised by the pattern left after Case 1, taken
/// relative to its lowest row and leftmost half-column (a fit does not depend on where the
/// pattern sits), and by the cell size. Patterns repeat from frame to frame and step to step, and
/// a Case 3 fit costs tens of microseconds against about one for a lookup. Results are identical
/// to fit_contact_ellipse's. Holds at most `capacity` fits and forgets them all when full. Not
/// thread-safe: use one per thread.
class ContactEllipseCache {
 public:
  /// Throws std::invalid_argument if capacity is 0.
  explicit ContactEllipseCache(std::size_t capacity = 4096);

  ContactEllipse fit(std::span<const ActiveCell> cells, CellSize size, Region region,
                     bool first_instant);

  std::size_t size() const { return fits_.size(); }
  std::size_t capacity() const { return capacity_; }
  std::size_t hits() const { return hits_; }
  std::size_t misses() const { return misses_; }

 private:
  struct Fitted {
    EllipseCase kase = EllipseCase::None;
    double cx_mm = 0.0;
    double cy_mm = 0.0;
    double ra_mm = 0.0;
    double rb_mm = 0.0;
    double angle_rad = 0.0;
  };
  struct KeyHash {
    std::size_t operator()(const std::vector<std::int64_t>& key) const;
  };

  std::size_t capacity_;
  std::size_t hits_ = 0;
  std::size_t misses_ = 0;
  std::vector<std::int64_t> key_;  ///< reused lookup key: cell size bits, then packed cells
  std::unordered_map<std::vector<std::int64_t>, Fitted, KeyHash> fits_;
};

}  // namespace gaitmon
