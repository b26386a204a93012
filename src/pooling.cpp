// Partial pooling of per-step material estimates: the mu-T fixed point and the posteriors.
#include "gaitmon/pooling.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace gaitmon {
namespace {

using Vec = Eigen::Vector4d;
using Mat = Eigen::Matrix4d;

constexpr int kMaxIterations = 200;
constexpr double kTolerance = 1e-12;

Vec to_eigen(const MaterialVector& v) {
  return Vec(v[0], v[1], v[2], v[3]);
}

Mat to_eigen(const MaterialCovariance& m) {
  Mat out;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c)
      out(r, c) = m[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)];
  return out;
}

MaterialVector from_eigen(const Vec& v) {
  return {v(0), v(1), v(2), v(3)};
}

MaterialCovariance from_eigen(const Mat& m) {
  MaterialCovariance out{};
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c)
      out[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)] = m(r, c);
  return out;
}

void check(const MaterialEstimate& e, std::size_t index) {
  const Vec v = to_eigen(e.value);
  const Mat s = to_eigen(e.covariance);
  const std::string where = "pool_steps: step " + std::to_string(index);
  if (!v.allFinite() || !s.allFinite()) throw std::invalid_argument(where + " is not finite");
  if (!s.isApprox(s.transpose(), 1e-9)) {
    throw std::invalid_argument(where + " has a covariance that is not symmetric");
  }
  if (Eigen::LLT<Mat>(s).info() != Eigen::Success) {
    throw std::invalid_argument(where + " has a covariance that is not positive definite");
  }
}

// The positive semi-definite part of a symmetric matrix.
Mat psd_part(const Mat& m) {
  const Eigen::SelfAdjointEigenSolver<Mat> eig(0.5 * (m + m.transpose()));
  const Vec values = eig.eigenvalues().cwiseMax(0.0);
  return eig.eigenvectors() * values.asDiagonal() * eig.eigenvectors().transpose();
}

// Whether the steps share one declared m (MaterialEstimate::slope_on_shared_m), checked alike.
bool at_shared_m(std::span<const MaterialEstimate> steps) {
  const auto shared = [](const MaterialEstimate& e) { return e.slope_on_shared_m.has_value(); };
  if (std::none_of(steps.begin(), steps.end(), shared)) return false;
  for (std::size_t i = 0; i < steps.size(); ++i) {
    const MaterialEstimate& e = steps[i];
    const std::string where = "pool_steps: step " + std::to_string(i);
    if (!shared(e)) throw std::invalid_argument(where + " has no shared m where others have");
    if (e.value[3] != steps[0].value[3] || e.covariance[3][3] != steps[0].covariance[3][3]) {
      throw std::invalid_argument(where + " has another shared m or variance of it than step 0");
    }
    const MaterialVector& slope = *e.slope_on_shared_m;
    if (!std::all_of(slope.begin(), slope.end(), [](double v) { return std::isfinite(v); }) ||
        slope[3] != 1.0) {
      throw std::invalid_argument(where +
                                  " has a slope on the shared m that is not finite or "
                                  "whose m entry is not 1");
    }
    for (std::size_t k = 0; k < 3; ++k) {
      if (e.covariance[3][k] != 0.0) {
        throw std::invalid_argument(where + " has a shared m that covaries with the others");
      }
    }
  }
  return true;
}

}  // namespace

PooledEstimates pool_steps(std::span<const MaterialEstimate> steps, const MaterialBounds& bounds) {
  for (std::size_t i = 0; i < steps.size(); ++i) check(steps[i], i);
  const bool shared_m = at_shared_m(steps);
  PooledEstimates out;
  out.steps.assign(steps.begin(), steps.end());
  if (steps.size() < kMinPoolingSteps) {
    out.not_pooled = "fewer than " + std::to_string(kMinPoolingSteps) + " steps";
    return out;
  }
  std::vector<Vec> theta;
  std::vector<Mat> S;
  for (const MaterialEstimate& e : steps) {
    theta.push_back(to_eigen(e.value));
    S.push_back(to_eigen(e.covariance));
  }
  const auto count = static_cast<double>(theta.size());
  Mat mean_S = Mat::Zero();
  for (const Mat& s : S) mean_S += s / count;

  Mat T = Mat::Zero();
  Vec mu = Vec::Zero();
  Mat mu_covariance = Mat::Zero();
  for (out.iterations = 1; out.iterations <= kMaxIterations; ++out.iterations) {
    Mat weight_sum = Mat::Zero();
    Vec weighted = Vec::Zero();
    for (std::size_t i = 0; i < theta.size(); ++i) {
      const Mat W = (S[i] + T).ldlt().solve(Mat::Identity());
      weight_sum += W;
      weighted += W * theta[i];
    }
    mu_covariance = weight_sum.ldlt().solve(Mat::Identity());
    mu = mu_covariance * weighted;
    Mat scatter = Mat::Zero();
    for (const Vec& t : theta) scatter += (t - mu) * (t - mu).transpose();
    Mat next = psd_part(scatter / (count - 1.0) - mean_S);
    // The steps' m do not scatter at a shared m: T has no m part.
    if (shared_m) {
      next.row(3).setZero();
      next.col(3).setZero();
    }
    const double change = (next - T).norm();
    T = next;
    if (change <= kTolerance * (1.0 + T.norm())) break;
  }
  out.iterations = std::min(out.iterations, kMaxIterations);
  for (std::size_t i = 0; i < 4; ++i) {
    if (!(mu(static_cast<Eigen::Index>(i)) >= bounds.lower[i] &&
          mu(static_cast<Eigen::Index>(i)) <= bounds.upper[i])) {
      out.not_pooled = "the pooled mean leaves the fit bounds";
      return out;
    }
  }

  // At a shared m, with variance s2: every step's estimate moves by its slope g_i times the m's
  // error, so mu by h = (sum W_i)^-1 sum W_i g_i. mu_covariance holds that variance divided by
  // the steps' count, as if each step's m erred on its own; it is replaced by h h^T s2, and each
  // posterior's own slope is h + B (g_i - h).
  Vec h = Vec::Zero();
  double s2 = 0.0;
  if (shared_m) {
    s2 = S.front()(3, 3);
    Vec weighted_slope = Vec::Zero();
    for (std::size_t i = 0; i < theta.size(); ++i) {
      weighted_slope += (S[i] + T).ldlt().solve(to_eigen(*steps[i].slope_on_shared_m));
    }
    h = mu_covariance * weighted_slope;
    mu_covariance.row(3).setZero();
    mu_covariance.col(3).setZero();
  }
  for (std::size_t i = 0; i < out.steps.size(); ++i) {
    MaterialEstimate& step = out.steps[i];
    // B = T (T + S)^-1, computed as ((T + S)^-1 T)^T because T and S are symmetric.
    const Mat B = (T + S[i]).ldlt().solve(T).transpose();
    const Mat shrink = Mat::Identity() - B;
    Mat covariance = T - B * T + shrink * mu_covariance * shrink.transpose();
    if (shared_m) {
      const Vec slope = h + B * (to_eigen(*steps[i].slope_on_shared_m) - h);
      covariance += slope * slope.transpose() * s2;
      step.slope_on_shared_m = from_eigen(slope);
    }
    step.value = from_eigen(Vec(mu + B * (theta[i] - mu)));
    step.covariance = from_eigen(Mat(0.5 * (covariance + covariance.transpose())));
  }
  if (shared_m) {
    mu_covariance += h * h.transpose() * s2;
    out.mean_slope_on_shared_m = from_eigen(h);
  }
  out.pooled = true;
  out.mean = from_eigen(mu);
  out.mean_covariance = from_eigen(Mat(0.5 * (mu_covariance + mu_covariance.transpose())));
  out.between_step = from_eigen(T);
  return out;
}

MaterialBounds material_bounds(const FitBounds& b) {
  return {
      {std::log(b.kbar_n_per_mm3.lower), b.n.lower, std::log(b.cbar_ns_per_mm3.lower), b.m.lower},
      {std::log(b.kbar_n_per_mm3.upper), b.n.upper, std::log(b.cbar_ns_per_mm3.upper), b.m.upper}};
}

std::optional<MaterialEstimate> material_estimate(const RegionFit& fit) {
  if (fit.status != FitStatus::Ok || !fit.material_covariance) return std::nullopt;
  MaterialEstimate e;
  e.value = {std::log(fit.kbar_n_per_mm3.value), fit.n.value, std::log(fit.cbar_ns_per_mm3.value),
             fit.m.value};
  e.covariance = *fit.material_covariance;
  if (e.covariance[3][3] == 0.0) {
    // m declared (its row and column zero), the same for every step
    // (fit_damping_exponent_per_session): its variance is that of the shared value.
    if (!(fit.m.se > 0.0) || !std::isfinite(fit.m.se) || !fit.material_slope_on_m) {
      return std::nullopt;
    }
    e.covariance[3][3] = fit.m.se * fit.m.se;
    const auto& slope = *fit.material_slope_on_m;
    e.slope_on_shared_m = MaterialVector{slope[0], slope[1], slope[2], 1.0};
  }
  return e;
}

MaterialEstimate within_m_range(MaterialEstimate estimate, const MaterialBounds& bounds) {
  const double range = bounds.upper[3] - bounds.lower[3];
  const double v = estimate.covariance[3][3];
  const double largest = range * range / 3.0;
  if (estimate.slope_on_shared_m || !(v > largest)) return estimate;
  // cov - c c^T (v - largest) / v^2, c = cov[.][3]: the Schur complement on m plus the slopes
  // c / v times m's new variance, so positive semi-definite as the covariance was.
  const MaterialVector c = {estimate.covariance[0][3], estimate.covariance[1][3],
                            estimate.covariance[2][3], v};
  const double shrink = (v - largest) / (v * v);
  for (std::size_t a = 0; a < 4; ++a)
    for (std::size_t b = 0; b < 4; ++b) estimate.covariance[a][b] -= c[a] * c[b] * shrink;
  estimate.covariance[3][3] = largest;
  return estimate;
}

MaterialEstimate with_shared_error(MaterialEstimate estimate, const MaterialVector& sd) {
  for (std::size_t i = 0; i < sd.size(); ++i) {
    if (!(std::isfinite(sd[i]) && sd[i] >= 0.0)) {
      throw std::invalid_argument("with_shared_error: SD " + std::to_string(i) +
                                  " must be finite and not negative, got " + std::to_string(sd[i]));
    }
  }
  const std::size_t own = estimate.slope_on_shared_m ? 3 : 4;
  for (std::size_t i = 0; i < own; ++i) estimate.covariance[i][i] += sd[i] * sd[i];
  if (estimate.slope_on_shared_m) {
    const MaterialVector& g = *estimate.slope_on_shared_m;
    for (std::size_t a = 0; a < 4; ++a)
      for (std::size_t b = 0; b < 4; ++b) estimate.covariance[a][b] += g[a] * g[b] * sd[3] * sd[3];
  }
  return estimate;
}

MaterialParams material_params(const MaterialEstimate& estimate) {
  const auto& v = estimate.value;
  const auto se = [&](std::size_t i) { return std::sqrt(estimate.covariance[i][i]); };
  MaterialParams p;
  p.kbar_n_per_mm3 = {std::exp(v[0]), std::exp(v[0]) * se(0), false, true};
  p.n = {v[1], se(1), false, true};
  p.cbar_ns_per_mm3 = {std::exp(v[2]), std::exp(v[2]) * se(2), false, true};
  p.m = {v[3], se(3), false, true};
  return p;
}

}  // namespace gaitmon
