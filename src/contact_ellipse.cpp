// Contact ellipse of a region's active cells: noise removal, the seed's closed-form cases and the
// geometric ellipse fit for irregular shapes (see contact_ellipse.hpp for the rules).
#include "gaitmon/contact_ellipse.hpp"

#include <ceres/jet.h>
#include <ceres/tiny_solver.h>
#include <ceres/tiny_solver_autodiff_function.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace gaitmon {
namespace {

constexpr double kPi = std::numbers::pi;
const double kSqrtPi = std::sqrt(kPi);

/// A cell on the lattice: ix in half cell widths, iy in rows, from the lattice origin.
struct LatticeCell {
  int ix = 0;
  int iy = 0;
  bool heel_edge = false;
  friend bool operator<(const LatticeCell& l, const LatticeCell& r) {
    return l.iy != r.iy ? l.iy < r.iy : l.ix < r.ix;
  }
  friend bool operator==(const LatticeCell& l, const LatticeCell& r) {
    return l.ix == r.ix && l.iy == r.iy;
  }
};

/// A boundary point in exact integer units: X in quarter widths, Y in half heights, so cell
/// corners, side midpoints and the midpoints of half-exposed sides are all representable.
struct GridPoint {
  std::int64_t X = 0;
  std::int64_t Y = 0;
  friend auto operator<=>(const GridPoint&, const GridPoint&) = default;
};

struct Point {
  double x = 0.0;
  double y = 0.0;
};

struct Ellipse {
  double cx = 0.0;
  double cy = 0.0;
  double a = 0.0;
  double b = 0.0;
  double angle = 0.0;
};

/// The first finite cell's centre: the lattice origin in the grid frame.
struct Anchor {
  double x_mm = 0.0;
  double y_mm = 0.0;
};

struct Scratch {
  std::vector<LatticeCell> cells;
  std::vector<LatticeCell> kept;
  std::vector<GridPoint> grid_points;
  std::vector<GridPoint> hull;
  std::vector<Point> points;
  std::vector<double> roots;
};

Scratch& scratch() {
  thread_local Scratch s;
  return s;
}

/// Lattice offsets beyond this are not cells of one insole region; skipping them keeps the
/// integer arithmetic far from overflow.
constexpr double kMaxLatticeOffset = 1.0e6;

bool has_cell(std::span<const LatticeCell> sorted, int ix, int iy) {
  return std::binary_search(sorted.begin(), sorted.end(), LatticeCell{ix, iy, false});
}

bool touches_another(std::span<const LatticeCell> cells, const LatticeCell& c) {
  return std::any_of(cells.begin(), cells.end(), [&](const LatticeCell& o) {
    return !(o == c) && std::abs(o.iy - c.iy) <= 1 && std::abs(o.ix - c.ix) <= 2;
  });
}

bool is_rectangle(std::span<const LatticeCell> sorted) {
  const int first_ix = sorted.front().ix;
  const int first_iy = sorted.front().iy;
  int row_length = 0;
  while (row_length < static_cast<int>(sorted.size()) &&
         sorted[static_cast<std::size_t>(row_length)].iy == first_iy) {
    ++row_length;
  }
  if (sorted.size() % static_cast<std::size_t>(row_length) != 0) return false;
  for (std::size_t i = 0; i < sorted.size(); ++i) {
    const auto row = static_cast<int>(i / static_cast<std::size_t>(row_length));
    const auto col = static_cast<int>(i % static_cast<std::size_t>(row_length));
    if (sorted[i].iy != first_iy + row || sorted[i].ix != first_ix + 2 * col) return false;
  }
  return true;
}

/// Exposed parts of the side [lo, hi] (quarter widths) at height Y, given the covering intervals.
void add_exposed_parts(std::int64_t lo, std::int64_t hi, std::int64_t Y,
                       std::span<std::array<std::int64_t, 2>> covers, std::vector<GridPoint>& out) {
  // At most three covers: an insertion sort (std::sort here trips a GCC -Warray-bounds false
  // positive on the fixed-size buffer).
  for (std::size_t i = 1; i < covers.size(); ++i) {
    for (std::size_t j = i; j > 0 && covers[j] < covers[j - 1]; --j) {
      std::swap(covers[j], covers[j - 1]);
    }
  }
  std::int64_t from = lo;
  auto emit = [&](std::int64_t p, std::int64_t q) {
    out.push_back({p, Y});
    out.push_back({(p + q) / 2, Y});
    out.push_back({q, Y});
  };
  for (const auto& cv : covers) {
    const std::int64_t c0 = std::max(cv[0], lo);
    const std::int64_t c1 = std::min(cv[1], hi);
    if (c1 <= c0) continue;
    if (c0 > from) emit(from, c0);
    from = std::max(from, c1);
  }
  if (from < hi) emit(from, hi);
}

void collect_neighbour_points(std::span<const LatticeCell> sorted, std::vector<GridPoint>& out) {
  out.clear();
  for (const LatticeCell& c : sorted) {
    const std::int64_t X = 2 * static_cast<std::int64_t>(c.ix);
    const std::int64_t Y = 2 * static_cast<std::int64_t>(c.iy);
    for (const int side : {-1, 1}) {
      if (!has_cell(sorted, c.ix + 2 * side, c.iy)) {
        for (const std::int64_t dy : {-1, 0, 1}) out.push_back({X + 2 * side, Y + dy});
      }
      std::array<std::array<std::int64_t, 2>, 3> covers{};
      std::size_t n = 0;
      for (const int dix : {-1, 0, 1}) {
        if (has_cell(sorted, c.ix + dix, c.iy + side)) {
          const std::int64_t Xn = X + 2 * dix;
          covers[n++] = {Xn - 2, Xn + 2};
        }
      }
      add_exposed_parts(X - 2, X + 2, Y + side, std::span(covers.data(), n), out);
    }
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
}

std::int64_t cross(const GridPoint& o, const GridPoint& a, const GridPoint& b) {
  return (a.X - o.X) * (b.Y - o.Y) - (a.Y - o.Y) * (b.X - o.X);
}

/// Keeps the points on the boundary of their convex hull (vertices and points on edges), the
/// outline that skips the divots. Reproduces the seed's Boundary area for Fig. 21's shape.
void keep_hull_points(std::vector<GridPoint>& sorted_points, std::vector<GridPoint>& hull) {
  const std::vector<GridPoint>& pts = sorted_points;
  // Andrew's monotone chain, strict vertices only.
  hull.assign(2 * pts.size(), GridPoint{});
  std::size_t k = 0;
  for (const GridPoint& p : pts) {
    while (k >= 2 && cross(hull[k - 2], hull[k - 1], p) <= 0) --k;
    hull[k++] = p;
  }
  for (std::size_t i = pts.size() - 1, lower = k + 1; i-- > 0;) {
    while (k >= lower && cross(hull[k - 2], hull[k - 1], pts[i]) <= 0) --k;
    hull[k++] = pts[i];
  }
  hull.resize(k - 1);
  auto on_hull = [&](const GridPoint& p) {
    for (std::size_t i = 0; i < hull.size(); ++i) {
      const GridPoint& a = hull[i];
      const GridPoint& b = hull[(i + 1) % hull.size()];
      if (cross(a, b, p) != 0) continue;
      if (std::min(a.X, b.X) <= p.X && p.X <= std::max(a.X, b.X) && std::min(a.Y, b.Y) <= p.Y &&
          p.Y <= std::max(a.Y, b.Y)) {
        return true;
      }
    }
    return false;
  };
  sorted_points.erase(std::remove_if(sorted_points.begin(), sorted_points.end(),
                                     [&](const GridPoint& p) { return !on_hull(p); }),
                      sorted_points.end());
}

/// Closest point of the ellipse (x/a)^2 + (y/b)^2 = 1 to (u, v), all non-negative, a >= b > 0.
/// Eberly's form: the foot is (a^2 u / (t + a^2), b^2 v / (t + b^2)) at the root of
/// F(t) = (a u / (t + a^2))^2 + (b v / (t + b^2))^2 - 1 on t > -b^2. F is convex and decreasing
/// there, so once an iterate has F >= 0, Newton's method climbs monotonically to the root: the
/// global closest point, never a farther normal foot. From a start right of the root the first
/// step lands left of it, clamped to t_lo = max(q - b^2, p - a^2) where F >= 0 holds. `t` is the
/// start on entry (the previous evaluation's root, as the fit moves little between evaluations)
/// and the root on return. Newton's error after a step s is about s^2 / (t + b^2), so the loop
/// stops once s is below 1e-5 (t + b^2): the root is then exact to ~1e-10 relative.
std::array<double, 2> closest_point_major_x(double a, double b, double u, double v, double& t) {
  const double a2 = a * a;
  const double b2 = b * b;
  const double p = a * u;
  const double q = b * v;
  const double t_lo = std::max(q - b2, p - a2);
  // On the major axis, or so near it that t_lo rounds onto the pole at -b^2: closed form.
  if (!(t_lo + b2 > 0.0)) {
    const double focal = a2 - b2;
    if (a * u < focal) {
      const double x = a2 * u / focal;
      const double r = x / a;
      t = -b2;
      return {x, b * std::sqrt(std::max(0.0, 1.0 - r * r))};
    }
    t = p - a2;
    return {a, 0.0};
  }
  t = std::isfinite(t) ? std::max(t, t_lo) : t_lo;
  for (int it = 0; it < 100; ++it) {
    const double ia = 1.0 / (t + a2);
    const double ib = 1.0 / (t + b2);
    const double ra = p * ia;
    const double rb = q * ib;
    const double f = ra * ra + rb * rb - 1.0;
    const double df = -2.0 * (ra * ra * ia + rb * rb * ib);
    const double next = std::max(t - f / df, t_lo);
    const double step = next - t;
    t = next;
    if (!(std::abs(step) > 1e-5 * (t + b2))) break;
  }
  return {a2 * u / (t + a2), b2 * v / (t + b2)};
}

/// Closest ellipse point to (u, v) in the ellipse's own frame, any quadrant, any radii order.
std::array<double, 2> closest_point(double a, double b, double u, double v, double& t) {
  const double su = std::abs(u);
  const double sv = std::abs(v);
  std::array<double, 2> f;
  if (a >= b) {
    f = closest_point_major_x(a, b, su, sv, t);
  } else {
    const auto g = closest_point_major_x(b, a, sv, su, t);
    f = {g[1], g[0]};
  }
  return {std::copysign(f[0], u), std::copysign(f[1], v)};
}

inline double value_of(double x) {
  return x;
}
template <int N>
double value_of(const ceres::Jet<double, N>& x) {
  return x.a;
}

/// Signed orthogonal distances of the points to the ellipse p = (cx, cy, a, b, angle). Each foot
/// point is found in doubles and held fixed, which gives the exact distance gradient (see header).
/// `roots` keeps each point's foot-point root between evaluations as the next start.
class OrthogonalDistances {
 public:
  OrthogonalDistances(std::span<const Point> points, std::span<double> roots)
      : points_(points), roots_(roots) {}
  int NumResiduals() const { return static_cast<int>(points_.size()); }

  template <typename T>
  bool operator()(const T* p, T* residuals) const {
    using std::cos;
    using std::sin;
    constexpr double kTiny = 1e-9;
    const T c = cos(p[4]);
    const T s = sin(p[4]);
    const double a_val = value_of(p[2]);
    const double b_val = value_of(p[3]);
    const double a_abs = std::max(std::abs(a_val), kTiny);
    const double b_abs = std::max(std::abs(b_val), kTiny);
    const double a_safe = std::copysign(a_abs, a_val);
    const double b_safe = std::copysign(b_abs, b_val);
    for (std::size_t i = 0; i < points_.size(); ++i) {
      const T dx = points_[i].x - p[0];
      const T dy = points_[i].y - p[1];
      const T u = c * dx + s * dy;
      const T v = c * dy - s * dx;
      const auto foot = closest_point(a_abs, b_abs, value_of(u), value_of(v), roots_[i]);
      double nx = foot[0] / (a_abs * a_abs);
      double ny = foot[1] / (b_abs * b_abs);
      const double norm = std::sqrt(nx * nx + ny * ny);
      nx /= norm;
      ny /= norm;
      const T ex = p[2] * (foot[0] / a_safe);
      const T ey = p[3] * (foot[1] / b_safe);
      residuals[i] = nx * (u - ex) + ny * (v - ey);
    }
    return true;
  }

 private:
  std::span<const Point> points_;
  std::span<double> roots_;
};

/// Geometric parameters of the conic A x^2 + B xy + C y^2 + D x + E y + F = 0, if an ellipse.
std::optional<Ellipse> conic_to_ellipse(const Eigen::Matrix<double, 6, 1>& k) {
  const double A = k[0], B = k[1], C = k[2], D = k[3], E = k[4], F = k[5];
  const double den = B * B - 4.0 * A * C;
  if (!(den < 0.0)) return std::nullopt;
  const double x0 = (2.0 * C * D - B * E) / den;
  const double y0 = (2.0 * A * E - B * D) / den;
  if (!(std::isfinite(x0) && std::isfinite(y0))) return std::nullopt;
  const double fc = A * x0 * x0 + B * x0 * y0 + C * y0 * y0 + D * x0 + E * y0 + F;
  Eigen::Matrix2d q;
  q << A, B / 2.0, B / 2.0, C;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig;
  eig.computeDirect(q);
  const Eigen::Vector2d lambda = eig.eigenvalues();
  const double a2 = -fc / lambda[0];
  const double b2 = -fc / lambda[1];
  if (!(a2 > 0.0 && b2 > 0.0 && std::isfinite(a2) && std::isfinite(b2))) return std::nullopt;
  const Eigen::Vector2d axis = eig.eigenvectors().col(0);
  return Ellipse{x0, y0, std::sqrt(a2), std::sqrt(b2), std::atan2(axis.y(), axis.x())};
}

/// Direct least-squares ellipse fit (Fitzgibbon, Pilu, Fisher 1999) with Halir and Flusser's
/// (1998) elimination of the linear terms, on points centred and scaled for conditioning. Their
/// eigenproblem Sr a = lambda C1 a (Sr = S1 - S2 S3^-1 S2^T positive definite, C1 the 4ac - b^2
/// constraint) is solved in its symmetric form: with Sr = L L^T, K = L^-1 C1 L^-T has the
/// eigenvalues 1 / lambda, and by Sylvester's law of inertia exactly one is positive, as for C1;
/// its eigenvector b gives the ellipse a = L^-T b. Closed-form 3 x 3 symmetric eigensolver.
std::optional<Ellipse> fit_algebraic(std::span<const Point> points) {
  if (points.size() < 5) return std::nullopt;
  double mx = 0.0, my = 0.0;
  for (const Point& p : points) {
    mx += p.x;
    my += p.y;
  }
  mx /= static_cast<double>(points.size());
  my /= static_cast<double>(points.size());
  double ss = 0.0;
  for (const Point& p : points) ss += (p.x - mx) * (p.x - mx) + (p.y - my) * (p.y - my);
  const double scale = std::sqrt(ss / static_cast<double>(points.size()));
  if (!(scale > 0.0)) return std::nullopt;
  Eigen::Matrix3d s1 = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d s2 = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d s3 = Eigen::Matrix3d::Zero();
  for (const Point& p : points) {
    const double x = (p.x - mx) / scale;
    const double y = (p.y - my) / scale;
    const Eigen::Vector3d d1(x * x, x * y, y * y);
    const Eigen::Vector3d d2(x, y, 1.0);
    s1 += d1 * d1.transpose();
    s2 += d1 * d2.transpose();
    s3 += d2 * d2.transpose();
  }
  const Eigen::LLT<Eigen::Matrix3d> s3_llt(s3);
  if (s3_llt.info() != Eigen::Success) return std::nullopt;
  const Eigen::Matrix3d t = -s3_llt.solve(s2.transpose());
  const Eigen::Matrix3d sr = s1 + s2 * t;
  const Eigen::LLT<Eigen::Matrix3d> sr_llt(sr);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
  Eigen::Vector3d a1;
  if (sr_llt.info() == Eigen::Success) {
    Eigen::Matrix3d c1;
    c1 << 0.0, 0.0, 2.0, 0.0, -1.0, 0.0, 2.0, 0.0, 0.0;
    const auto l = sr_llt.matrixL();
    const Eigen::Matrix3d y = l.solve(c1);
    Eigen::Matrix3d k = l.solve(y.transpose());
    k = (0.5 * (k + k.transpose())).eval();
    eig.computeDirect(k);
    if (!(eig.eigenvalues()[2] > 0.0)) return std::nullopt;
    a1 = sr_llt.matrixU().solve(eig.eigenvectors().col(2));
  } else {
    // Sr singular: the points lie exactly on a conic, its null vector.
    eig.computeDirect(sr);
    a1 = eig.eigenvectors().col(0);
  }
  if (!(4.0 * a1[0] * a1[2] - a1[1] * a1[1] > 0.0)) return std::nullopt;
  const Eigen::Vector3d a2 = t * a1;
  Eigen::Matrix<double, 6, 1> conic;
  conic << a1, a2;
  auto e = conic_to_ellipse(conic);
  if (!e) return std::nullopt;
  return Ellipse{mx + scale * e->cx, my + scale * e->cy, scale * e->a, scale * e->b, e->angle};
}

/// Uniform ellipse with the cells' centroid and second moments, scaled to the cells' area.
Ellipse moment_ellipse(std::span<const Point> centres, CellSize size) {
  const double n = static_cast<double>(centres.size());
  double mx = 0.0, my = 0.0;
  for (const Point& p : centres) {
    mx += p.x;
    my += p.y;
  }
  mx /= n;
  my /= n;
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (const Point& p : centres) {
    const Eigen::Vector2d d(p.x - mx, p.y - my);
    cov += d * d.transpose() / n;
  }
  cov(0, 0) += size.width_mm * size.width_mm / 12.0;
  cov(1, 1) += size.height_mm * size.height_mm / 12.0;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig;
  eig.computeDirect(cov);
  // A uniform ellipse's variance along a semi-axis r is r^2 / 4.
  const double a = 2.0 * std::sqrt(eig.eigenvalues()[0]);
  const double b = 2.0 * std::sqrt(eig.eigenvalues()[1]);
  const double k = std::sqrt(n * size.width_mm * size.height_mm / (kPi * a * b));
  const Eigen::Vector2d axis = eig.eigenvectors().col(0);
  return {mx, my, k * a, k * b, std::atan2(axis.y(), axis.x())};
}

/// Geometric (orthogonal-distance) ellipse fit from `start`; nullopt if it does not converge.
std::optional<Ellipse> fit_geometric(std::span<const Point> points, const Ellipse& start,
                                     std::vector<double>& roots) {
  using Function = ceres::TinySolverAutoDiffFunction<OrthogonalDistances, Eigen::Dynamic, 5>;
  roots.assign(points.size(), 0.0);
  const OrthogonalDistances distances(points, roots);
  const Function function(distances);
  ceres::TinySolver<Function> solver;
  solver.options.max_num_iterations = 100;
  // Millimetre-scale data: these stop well below a micrometre of change in any parameter.
  solver.options.gradient_tolerance = 1e-10;
  solver.options.parameter_tolerance = 1e-9;
  solver.options.function_tolerance = 1e-10;
  Eigen::Matrix<double, 5, 1> x;
  x << start.cx, start.cy, start.a, start.b, start.angle;
  const auto& summary = solver.Solve(function, &x);
  if (summary.status == ceres::TinySolver<Function>::HIT_MAX_ITERATIONS) return std::nullopt;
  if (!x.allFinite()) return std::nullopt;
  return Ellipse{x[0], x[1], std::abs(x[2]), std::abs(x[3]), x[4]};
}

/// Puts ra on the axis nearer +x: angle in [-pi/4, pi/4].
Ellipse canonical(Ellipse e) {
  double angle = std::remainder(e.angle, kPi);
  if (angle > kPi / 4.0) {
    angle -= kPi / 2.0;
    std::swap(e.a, e.b);
  } else if (angle < -kPi / 4.0) {
    angle += kPi / 2.0;
    std::swap(e.a, e.b);
  }
  e.angle = angle;
  return e;
}

bool acceptable(const std::optional<Ellipse>& e, double sensor_area_mm2) {
  if (!e) return false;
  if (!(std::isfinite(e->cx) && std::isfinite(e->cy) && std::isfinite(e->angle))) return false;
  if (!(e->a > 0.0 && e->b > 0.0 && std::isfinite(e->a) && std::isfinite(e->b))) return false;
  const double area = kPi * e->a * e->b;
  return area <= 2.0 * sensor_area_mm2 && area >= 0.5 * sensor_area_mm2;
}

/// Fits the boundary points: algebraic start (or the moment ellipse), then the geometric fit.
std::optional<Ellipse> fit_points(std::span<const Point> points, const Ellipse& moments,
                                  std::vector<double>& roots) {
  const auto algebraic = fit_algebraic(points);
  return fit_geometric(points, algebraic ? *algebraic : moments, roots);
}

void to_points(std::span<const GridPoint> grid, CellSize size, std::vector<Point>& out) {
  out.clear();
  for (const GridPoint& g : grid) {
    out.push_back({static_cast<double>(g.X) * size.width_mm / 4.0,
                   static_cast<double>(g.Y) * size.height_mm / 2.0});
  }
}

void check_size(CellSize size) {
  if (!(std::isfinite(size.width_mm) && std::isfinite(size.height_mm) && size.width_mm > 0.0 &&
        size.height_mm > 0.0)) {
    throw std::invalid_argument("contact ellipse: cell size must be finite and positive, got " +
                                std::to_string(size.width_mm) + " x " +
                                std::to_string(size.height_mm) + " mm");
  }
}

/// Snaps the cells onto the lattice into s.cells, sorted and without duplicates; nullopt if no
/// cell has finite coordinates.
std::optional<Anchor> snap_cells(std::span<const ActiveCell> cells, CellSize size, Scratch& s) {
  const auto first = std::find_if(cells.begin(), cells.end(), [](const ActiveCell& c) {
    return std::isfinite(c.x_mm) && std::isfinite(c.y_mm);
  });
  if (first == cells.end()) return std::nullopt;
  const Anchor anchor{first->x_mm, first->y_mm};
  s.kept.clear();
  for (const ActiveCell& c : cells) {
    const double fx = 2.0 * (c.x_mm - anchor.x_mm) / size.width_mm;
    const double fy = (c.y_mm - anchor.y_mm) / size.height_mm;
    if (!(std::abs(fx) <= kMaxLatticeOffset && std::abs(fy) <= kMaxLatticeOffset)) continue;
    s.kept.push_back({static_cast<int>(std::lround(fx)), static_cast<int>(std::lround(fy)),
                      c.outermost_heel_row});
  }
  std::sort(s.kept.begin(), s.kept.end());
  // A duplicate flagged as outermost heel row keeps the flag.
  s.cells.clear();
  for (const LatticeCell& c : s.kept) {
    if (!s.cells.empty() && s.cells.back() == c) {
      s.cells.back().heel_edge = s.cells.back().heel_edge || c.heel_edge;
    } else {
      s.cells.push_back(c);
    }
  }
  return anchor;
}

/// Shifts the sorted cells so that the lowest row and leftmost half-column are 0, so every later
/// computation, and so a cached fit, is the same wherever the pattern sits. Returns the origin
/// of the shifted lattice in the grid frame.
Anchor normalise(std::vector<LatticeCell>& sorted, const Anchor& anchor, CellSize size) {
  int min_ix = sorted.front().ix;
  for (const LatticeCell& c : sorted) min_ix = std::min(min_ix, c.ix);
  const int min_iy = sorted.front().iy;
  for (LatticeCell& c : sorted) {
    c.ix -= min_ix;
    c.iy -= min_iy;
  }
  return {anchor.x_mm + min_ix * size.width_mm / 2.0, anchor.y_mm + min_iy * size.height_mm};
}

/// Rules 0 and 1: the normalised cells that count, in s.kept, and their origin; nullopt if none.
std::optional<Anchor> prepare(std::span<const ActiveCell> cells, CellSize size, Region region,
                              bool first_instant, Scratch& s) {
  check_size(size);
  const auto anchor = snap_cells(cells, size, s);
  if (!anchor) return std::nullopt;
  const bool toe = is_toe(region);
  const bool heel_strike = region == Region::Heel && first_instant;
  s.kept.clear();
  for (const LatticeCell& c : s.cells) {
    if (toe || (heel_strike && c.heel_edge) || touches_another(s.cells, c)) s.kept.push_back(c);
  }
  if (s.kept.empty()) return std::nullopt;
  return normalise(s.kept, *anchor, size);
}

/// A result before it is placed: the ellipse relative to the normalised lattice origin.
struct Shape {
  EllipseCase kase = EllipseCase::None;
  Ellipse ellipse;
};

/// Rules 1 (one cell left), 2 and 4; nullopt if the pattern is irregular (rule 3).
std::optional<Shape> closed_form(std::span<const LatticeCell> kept, CellSize size) {
  const double W = size.width_mm;
  const double H = size.height_mm;
  const int n = static_cast<int>(kept.size());
  double sum_x = 0.0, sum_y = 0.0;
  int max_ix = 0;
  for (const LatticeCell& c : kept) {
    sum_x += c.ix * W / 2.0;
    sum_y += c.iy * H;
    max_ix = std::max(max_ix, c.ix);
  }
  const double mean_x = sum_x / n;
  const double mean_y = sum_y / n;
  if (n == 1) {
    return Shape{EllipseCase::Isolated, {mean_x, mean_y, W / kSqrtPi, H / kSqrtPi, 0.0}};
  }
  const double nc = kept.back().iy + 1;  // rows, normalised to start at 0
  if (is_rectangle(kept)) {
    const double per_row = n / nc;
    return Shape{EllipseCase::Rectangle,
                 {mean_x, mean_y, per_row * W / kSqrtPi, nc * H / kSqrtPi, 0.0}};
  }
  const double nr = std::round(max_ix / 2.0 + 1.0);
  const double ratio = nc / nr;
  if (ratio <= 0.4) {
    return Shape{EllipseCase::Long,
                 {mean_x, mean_y, (nr + nc - 1.0) * W / kSqrtPi, nc * H / kSqrtPi, 0.0}};
  }
  if (ratio >= 2.0) {
    return Shape{EllipseCase::Long,
                 {mean_x, mean_y, nr * W / kSqrtPi, (nr + nc - 1.0) * H / kSqrtPi, 0.0}};
  }
  return std::nullopt;
}

/// The Case 3 fit on the neighbour points or on their hull outline; nullopt if it fails.
std::optional<Ellipse> fit_irregular(std::span<const LatticeCell> cells, CellSize size,
                                     BoundaryPoints which, const Ellipse& moments, Scratch& s) {
  collect_neighbour_points(cells, s.grid_points);
  if (which == BoundaryPoints::ConvexHull) keep_hull_points(s.grid_points, s.hull);
  to_points(s.grid_points, size, s.points);
  auto e = fit_points(s.points, moments, s.roots);
  if (!acceptable(e, static_cast<double>(cells.size()) * size.width_mm * size.height_mm)) {
    return std::nullopt;
  }
  return canonical(*e);
}

Ellipse cell_moments(std::span<const LatticeCell> cells, CellSize size, Scratch& s) {
  s.points.clear();
  for (const LatticeCell& c : cells) {
    s.points.push_back({c.ix * size.width_mm / 2.0, c.iy * size.height_mm});
  }
  return moment_ellipse(s.points, size);
}

/// Rule 3 and its fallbacks (rule 5).
Shape irregular(std::span<const LatticeCell> kept, CellSize size, Scratch& s) {
  const Ellipse moments = cell_moments(kept, size, s);
  if (auto e = fit_irregular(kept, size, BoundaryPoints::Neighbours, moments, s)) {
    return {EllipseCase::Neighbours, *e};
  }
  if (auto e = fit_irregular(kept, size, BoundaryPoints::ConvexHull, moments, s)) {
    return {EllipseCase::Boundary, *e};
  }
  return {EllipseCase::Boundary, canonical(moments)};
}

ContactEllipse place(const Shape& shape, const Anchor& origin, std::size_t cells, CellSize size) {
  ContactEllipse r;
  r.kase = shape.kase;
  r.cx_mm = origin.x_mm + shape.ellipse.cx;
  r.cy_mm = origin.y_mm + shape.ellipse.cy;
  r.ra_mm = shape.ellipse.a;
  r.rb_mm = shape.ellipse.b;
  r.angle_rad = shape.ellipse.angle;
  r.area_mm2 = kPi * r.ra_mm * r.rb_mm;
  r.cells_used = static_cast<int>(cells);
  r.sensor_area_mm2 = r.cells_used * size.width_mm * size.height_mm;
  r.pi = r.area_mm2 / r.sensor_area_mm2;
  return r;
}

}  // namespace

std::string_view ellipse_case_name(EllipseCase kase) {
  switch (kase) {
    case EllipseCase::None:
      return "none";
    case EllipseCase::Isolated:
      return "isolated";
    case EllipseCase::Rectangle:
      return "rectangle";
    case EllipseCase::Neighbours:
      return "neighbours";
    case EllipseCase::Boundary:
      return "boundary";
    case EllipseCase::Long:
      return "long";
  }
  return "none";
}

ContactEllipse fit_contact_ellipse(std::span<const ActiveCell> cells, CellSize size, Region region,
                                   bool first_instant) {
  Scratch& s = scratch();
  const auto origin = prepare(cells, size, region, first_instant, s);
  if (!origin) return {};
  const auto shape = closed_form(s.kept, size);
  return place(shape ? *shape : irregular(s.kept, size, s), *origin, s.kept.size(), size);
}

std::optional<ContactEllipse> fit_irregular_ellipse(std::span<const ActiveCell> cells,
                                                    CellSize size, BoundaryPoints points) {
  check_size(size);
  Scratch& s = scratch();
  const auto anchor = snap_cells(cells, size, s);
  if (!anchor || s.cells.size() < 2) return std::nullopt;
  const Anchor origin = normalise(s.cells, *anchor, size);
  const Ellipse moments = cell_moments(s.cells, size, s);
  const auto e = fit_irregular(s.cells, size, points, moments, s);
  if (!e) return std::nullopt;
  const EllipseCase kase =
      points == BoundaryPoints::Neighbours ? EllipseCase::Neighbours : EllipseCase::Boundary;
  return place({kase, *e}, origin, s.cells.size(), size);
}

namespace detail {

ContactEllipse moment_ellipse(std::span<const ActiveCell> cells, CellSize size) {
  check_size(size);
  Scratch& s = scratch();
  const auto anchor = snap_cells(cells, size, s);
  if (!anchor) return {};
  const Anchor origin = normalise(s.cells, *anchor, size);
  return place({EllipseCase::Boundary, canonical(cell_moments(s.cells, size, s))}, origin,
               s.cells.size(), size);
}

}  // namespace detail

std::size_t ContactEllipseCache::KeyHash::operator()(const std::vector<std::int64_t>& key) const {
  // FNV-1a over the words.
  std::uint64_t h = 1469598103934665603ULL;
  for (const std::int64_t w : key) {
    h ^= static_cast<std::uint64_t>(w);
    h *= 1099511628211ULL;
  }
  return static_cast<std::size_t>(h);
}

ContactEllipseCache::ContactEllipseCache(std::size_t capacity) : capacity_(capacity) {
  if (capacity == 0) throw std::invalid_argument("ContactEllipseCache: capacity must be positive");
}

ContactEllipse ContactEllipseCache::fit(std::span<const ActiveCell> cells, CellSize size,
                                        Region region, bool first_instant) {
  Scratch& s = scratch();
  const auto origin = prepare(cells, size, region, first_instant, s);
  if (!origin) return {};
  if (const auto shape = closed_form(s.kept, size)) {
    return place(*shape, *origin, s.kept.size(), size);
  }
  key_.clear();
  key_.push_back(std::bit_cast<std::int64_t>(size.width_mm));
  key_.push_back(std::bit_cast<std::int64_t>(size.height_mm));
  for (const LatticeCell& c : s.kept) {
    key_.push_back((static_cast<std::int64_t>(c.iy) << 32) | static_cast<std::uint32_t>(c.ix));
  }
  if (const auto it = fits_.find(key_); it != fits_.end()) {
    ++hits_;
    return place({it->second.kase,
                  {it->second.cx_mm, it->second.cy_mm, it->second.ra_mm, it->second.rb_mm,
                   it->second.angle_rad}},
                 *origin, s.kept.size(), size);
  }
  ++misses_;
  const Shape shape = irregular(s.kept, size, s);
  if (fits_.size() >= capacity_) fits_.clear();
  fits_.emplace(key_, Fitted{shape.kase, shape.ellipse.cx, shape.ellipse.cy, shape.ellipse.a,
                             shape.ellipse.b, shape.ellipse.angle});
  return place(shape, *origin, s.kept.size(), size);
}

}  // namespace gaitmon
