// The residual diagnostics of the discrepancy workflow: the residual map over region and stance
// phase, and the residuals' bias per phase, runs and correlation with the model's state.
#include "discrepancy_diagnostics.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>

namespace gaitmon::discrepancy_detail {
namespace {

double pearson(const std::vector<double>& x, const std::vector<double>& y) {
  const double n = static_cast<double>(x.size());
  if (n < 3) return 0.0;
  double mx = 0, my = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    mx += x[i];
    my += y[i];
  }
  mx /= n;
  my /= n;
  double sxy = 0, sxx = 0, syy = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    sxy += (x[i] - mx) * (y[i] - my);
    sxx += (x[i] - mx) * (x[i] - mx);
    syy += (y[i] - my) * (y[i] - my);
  }
  return sxx > 0 && syy > 0 ? sxy / std::sqrt(sxx * syy) : 0.0;
}

// The stance's last frame (phase 1) belongs to the last bin.
int phase_bin(double phase, int bins) {
  return std::min(bins - 1, static_cast<int>(phase * bins));
}

}  // namespace

double savgol_noise_sd(std::span<const double> y) {
  // Residual of the 5-point quadratic smoother; for white noise its SD is 0.717 of the noise's.
  if (y.size() < 7) return 0.0;
  std::vector<double> res;
  for (std::size_t i = 2; i + 2 < y.size(); ++i) {
    const double s =
        (-3 * y[i - 2] + 12 * y[i - 1] + 17 * y[i] + 12 * y[i + 1] - 3 * y[i + 2]) / 35;
    res.push_back(std::abs(y[i] - s));
  }
  const auto mid = static_cast<std::ptrdiff_t>(res.size() / 2);
  std::nth_element(res.begin(), res.begin() + mid, res.end());
  double mad = res[static_cast<std::size_t>(mid)];
  // An even count's median is the mean of its two middle values: the upper one alone read 2 %
  // high over a stance's 60 frames.
  if (res.size() % 2 == 0) mad = 0.5 * (mad + *std::max_element(res.begin(), res.begin() + mid));
  return 1.4826 * mad / std::sqrt(630.0 / 1225.0);
}

ResidualMap residual_map(std::span<const Unit> units, const std::vector<std::vector<double>>& preds,
                         int bins) {
  ResidualMap map;
  map.bins = bins;
  std::vector<double> s(kRegionCount * static_cast<std::size_t>(bins), 0.0), s2 = s, f2 = s;
  std::vector<int> count(s.size(), 0);
  for (std::size_t ui = 0; ui < units.size(); ++ui) {
    const Unit& u = units[ui];
    for (std::size_t i = 0; i < u.y.size(); ++i) {
      const int b = phase_bin(u.phase[i], bins);
      const std::size_t c =
          index_of(u.region) * static_cast<std::size_t>(bins) + static_cast<std::size_t>(b);
      const double r = u.y[i] - preds[ui][i];
      s[c] += r;
      s2[c] += r * r;
      f2[c] += u.floor2[i];
      ++count[c];
    }
  }
  for (Region region : kRegions) {
    for (int b = 0; b < bins; ++b) {
      const std::size_t c =
          index_of(region) * static_cast<std::size_t>(bins) + static_cast<std::size_t>(b);
      ResidualCell cell;
      cell.region = region;
      cell.bin = b;
      cell.samples = count[c];
      if (count[c] > 0) {
        cell.rms_n = std::sqrt(s2[c] / count[c]);
        cell.bias_n = s[c] / count[c];
        cell.noise_floor_n = std::sqrt(f2[c] / count[c]);
      }
      map.cells.push_back(cell);
    }
  }
  return map;
}

ResidualDiagnostics diagnose(std::span<const Unit> units,
                             const std::vector<std::vector<double>>& preds, int bins) {
  ResidualDiagnostics d;
  std::vector<double> bias(static_cast<std::size_t>(bins), 0.0);
  std::vector<int> count(bias.size(), 0);
  std::vector<double> res, dd, rate, sign, since, history, sat, step;
  double runs = 0, expected = 0, variance = 0;
  for (std::size_t ui = 0; ui < units.size(); ++ui) {
    const Unit& u = units[ui];
    double impulse = 0;
    int plus = 0, minus = 0, unit_runs = 0;
    int last_sign = 0;
    for (std::size_t i = 0; i < u.y.size(); ++i) {
      const double r = (u.y[i] - preds[ui][i]) / u.peak_n;
      const int b = phase_bin(u.phase[i], bins);
      bias[static_cast<std::size_t>(b)] += r;
      ++count[static_cast<std::size_t>(b)];
      impulse += u.y[i] * u.dt_s;
      res.push_back(r);
      dd.push_back(u.d_mm[i]);
      rate.push_back(u.ddot_mm_per_s[i]);
      sign.push_back(u.ddot_mm_per_s[i] > 0 ? 1.0 : (u.ddot_mm_per_s[i] < 0 ? -1.0 : 0.0));
      since.push_back(u.t[i] - u.t.front());
      history.push_back(impulse / u.peak_n);
      sat.push_back(u.sat[i]);
      step.push_back(u.ordinal);
      const int sg = r > 0 ? 1 : (r < 0 ? -1 : 0);
      if (sg == 0) continue;
      (sg > 0 ? plus : minus)++;
      if (sg != last_sign) ++unit_runs;
      last_sign = sg;
    }
    const double n = plus + minus;
    if (plus > 0 && minus > 0 && n > 1) {
      runs += unit_runs;
      expected += 1.0 + 2.0 * plus * minus / n;
      variance += 2.0 * plus * minus * (2.0 * plus * minus - n) / (n * n * (n - 1));
    }
  }
  for (std::size_t b = 0; b < bias.size(); ++b) {
    d.bias_per_phase_pct.push_back(count[b] > 0 ? 100.0 * bias[b] / count[b] : 0.0);
  }
  d.runs_z = variance > 0 ? (runs - expected) / std::sqrt(variance) : 0.0;
  d.correlations = {{"d_mm", pearson(dd, res)},
                    {"ddot_mm_per_s", pearson(rate, res)},
                    {"sign_ddot", pearson(sign, res)},
                    {"time_since_heel_strike_s", pearson(since, res)},
                    {"load_history_impulse", pearson(history, res)},
                    {"saturated_cells", pearson(sat, res)},
                    {"step_index", pearson(step, res)}};
  return d;
}

}  // namespace gaitmon::discrepancy_detail
