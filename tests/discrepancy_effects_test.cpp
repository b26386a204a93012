// The candidate effects keep the promises the workflow's solver relies on: one that says it is
// affine in the model force is, and one that says it only adds to the force does. The solver
// solves K and D in closed form for the first and computes the chain's linear part once for the
// second, so a false promise would give wrong fits without any error. The same goes for the
// slope an effect gives Gauss-Newton.
#include "src/discrepancy_effects.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

namespace gaitmon::discrepancy_detail {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr std::size_t kFrames = 60;

// A stance of one region: a half-sine of area, depth and force, 10-ms frames.
Unit stance(Region region, int step, double t0_s) {
  Unit u;
  u.region = region;
  u.step = step;
  u.dt_s = 0.01;
  u.t_contact_s = t0_s;
  for (std::size_t i = 0; i < kFrames; ++i) {
    const double s = std::sin(kPi * (static_cast<double>(i) + 0.5) / kFrames);
    u.t.push_back(t0_s + 0.01 * static_cast<double>(i));
    u.area.push_back(1200.0 * s);
    u.d_mm.push_back(6.0 * s);
    u.y.push_back(400.0 * s * s);
  }
  u.peak_n = 400.0;
  return u;
}

// Two forces unlike each other and unlike the measured one.
std::vector<double> force(double scale, double cycles) {
  std::vector<double> f;
  for (std::size_t i = 0; i < kFrames; ++i) {
    const double x = (static_cast<double>(i) + 0.5) / kFrames;
    f.push_back(scale * std::sin(kPi * x) * (1.2 + std::cos(2.0 * kPi * cycles * x)));
  }
  return f;
}

std::vector<double> apply(const Applied& e, std::size_t ui, const Unit& u,
                          const std::vector<double>& F, std::size_t choice) {
  std::vector<double> out(F.size());
  e.apply(ui, u, F, out, choice);
  return out;
}

std::vector<double> combine(double a, const std::vector<double>& x, double b,
                            const std::vector<double>& y) {
  std::vector<double> out(x.size());
  for (std::size_t i = 0; i < x.size(); ++i) out[i] = a * x[i] + b * y[i];
  return out;
}

// The largest |T(a F1 + b F2) - T(0) - a (T(F1) - T(0)) - b (T(F2) - T(0))| over the frames.
double affine_defect(const Applied& e, std::size_t ui, const Unit& u, std::size_t choice) {
  const std::vector<double> F1 = force(300.0, 1.0);
  const std::vector<double> F2 = force(150.0, 2.5);
  const std::vector<double> zero(kFrames, 0.0);
  const double a = 0.7;
  const double b = 1.9;
  const std::vector<double> T0 = apply(e, ui, u, zero, choice);
  const std::vector<double> T1 = apply(e, ui, u, F1, choice);
  const std::vector<double> T2 = apply(e, ui, u, F2, choice);
  const std::vector<double> T12 = apply(e, ui, u, combine(a, F1, b, F2), choice);
  double worst = 0.0;
  for (std::size_t i = 0; i < kFrames; ++i) {
    const double predicted = T0[i] + a * (T1[i] - T0[i]) + b * (T2[i] - T0[i]);
    worst = std::max(worst, std::abs(T12[i] - predicted));
  }
  return worst;
}

// The largest |(T(F) - F) - T(0)| over the frames, for two forces.
double additive_defect(const Applied& e, std::size_t ui, const Unit& u, std::size_t choice) {
  const std::vector<double> zero(kFrames, 0.0);
  const std::vector<double> T0 = apply(e, ui, u, zero, choice);
  double worst = 0.0;
  for (const std::vector<double>& F : {force(300.0, 1.0), force(150.0, 2.5)}) {
    const std::vector<double> T = apply(e, ui, u, F, choice);
    for (std::size_t i = 0; i < kFrames; ++i)
      worst = std::max(worst, std::abs(T[i] - F[i] - T0[i]));
  }
  return worst;
}

struct Made {
  std::string name;
  std::unique_ptr<Applied> effect;
};

// Every candidate at the middle of each of its parameters' grids, over a heel and a metatarsal
// stance whose force carries over from one to the next.
std::vector<Made> every_candidate(const std::vector<Unit>& units) {
  std::vector<Made> made;
  for (const CandidateSpec& spec : candidate_specs(112.5, 0.0441)) {
    std::vector<double> theta;
    for (const ParamSpec& p : spec.params) theta.push_back(p.grid[p.grid.size() / 2]);
    made.push_back({spec.name, spec.make(units, theta)});
  }
  return made;
}

std::vector<Unit> two_steps() {
  std::vector<Unit> units{stance(Region::Heel, 0, 0.5), stance(Region::Heel, 1, 1.6),
                          stance(Region::Met1_2, 0, 0.8)};
  units[1].prev = 0;
  return units;
}

TEST(DiscrepancyEffects, ThoseThatSayTheyAreAffineInTheForceAre) {
  const std::vector<Unit> units = two_steps();
  int checked = 0;
  for (const Made& m : every_candidate(units)) {
    if (!m.effect->affine()) continue;
    for (std::size_t ui = 0; ui < units.size(); ++ui) {
      if (!m.effect->affects(units[ui])) continue;
      for (std::size_t c = 0; c < m.effect->choices(units[ui]); ++c) {
        EXPECT_LT(affine_defect(*m.effect, ui, units[ui], c), 1e-9)
            << m.name << " unit " << ui << " choice " << c;
        ++checked;
      }
    }
  }
  // Relaxation, hysteresis and creep on 3 units, 1 choice each; impact on 2 heels x 21 onsets.
  EXPECT_EQ(checked, 3 * 3 + 2 * 21);
}

TEST(DiscrepancyEffects, TheAffineCheckCatchesTheCeilingThatIsNot) {
  const std::vector<Unit> units = two_steps();
  int found = 0;
  for (const Made& m : every_candidate(units)) {
    if (m.name != "sensor_saturation") continue;
    ++found;
    EXPECT_FALSE(m.effect->affine());
    EXPECT_GT(affine_defect(*m.effect, 0, units[0], 0), 1.0);
  }
  EXPECT_EQ(found, 1) << "no sensor_saturation candidate to check";
}

TEST(DiscrepancyEffects, ThoseThatSayTheyOnlyAddToTheForceDo) {
  const std::vector<Unit> units = two_steps();
  std::vector<std::string> additive;
  for (const Made& m : every_candidate(units)) {
    bool depends_on_force = false;
    for (std::size_t ui = 0; ui < units.size(); ++ui) {
      if (!m.effect->affects(units[ui])) continue;
      for (std::size_t c = 0; c < m.effect->choices(units[ui]); ++c) {
        const double defect = additive_defect(*m.effect, ui, units[ui], c);
        if (m.effect->additive()) {
          EXPECT_LT(defect, 1e-9) << m.name << " unit " << ui << " choice " << c;
        } else {
          depends_on_force = depends_on_force || defect > 1e-9;
        }
      }
    }
    if (m.effect->additive()) {
      additive.push_back(m.name);
    } else {
      // The check can tell: every other effect changes with the force it is given.
      EXPECT_TRUE(depends_on_force) << m.name;
    }
  }
  EXPECT_EQ(additive, std::vector<std::string>{"impact_transient"});
}

// Gauss-Newton takes an effect's slope in place of differences, so a slope that is off would
// steer the fits without an error. Each frame's slope is checked against differences of `apply`
// over that frame alone (forward or backward: the fraction is interpolated linearly in a table,
// so a central difference may straddle a knot), and no other frame may move with it.
TEST(DiscrepancyEffects, ThoseThatGiveTheirSlopeGiveApplysSlopeFrameByFrame) {
  const std::vector<Unit> units = two_steps();
  std::vector<std::string> with_slope;
  for (const Made& m : every_candidate(units)) {
    const Unit& u = units[0];
    const std::vector<double> F = force(300.0, 1.0);
    std::vector<double> out(kFrames), slope(kFrames);
    if (!m.effect->apply_with_slope(0, u, F, out, slope)) continue;
    with_slope.push_back(m.name);
    const std::vector<double> plain = apply(*m.effect, 0, u, F, 0);
    int moved = 0;
    for (std::size_t i = 0; i < kFrames; ++i) {
      EXPECT_DOUBLE_EQ(out[i], plain[i]) << m.name << " frame " << i;
      const double h = 1e-6 * F[i];
      std::vector<double> up = F, down = F;
      up[i] += h;
      down[i] -= h;
      const std::vector<double> at_up = apply(*m.effect, 0, u, up, 0);
      const std::vector<double> at_down = apply(*m.effect, 0, u, down, 0);
      const double forward = (at_up[i] - plain[i]) / h;
      const double backward = (plain[i] - at_down[i]) / h;
      const double off = std::min(std::abs(slope[i] - forward), std::abs(slope[i] - backward));
      EXPECT_LT(off, 1e-6 * std::max(1.0, std::abs(slope[i])))
          << m.name << " frame " << i << ": slope " << slope[i] << ", differences " << forward
          << " and " << backward;
      for (std::size_t j = 0; j < kFrames; ++j) {
        if (j != i) {
          EXPECT_EQ(at_up[j], plain[j]) << m.name << " frame " << j << " moved with " << i;
        }
      }
      if (std::abs(slope[i] - 1.0) > 0.01) ++moved;
    }
    // The ceiling is below every frame's peak here, so the slope is not the identity's.
    EXPECT_EQ(moved, static_cast<int>(kFrames)) << m.name;
  }
  EXPECT_EQ(with_slope, std::vector<std::string>{"sensor_saturation"});
}

}  // namespace
}  // namespace gaitmon::discrepancy_detail
