// The HTML report of `gaitmon analyze`, drawn as inline SVG.
#include "report_html.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string_view>
#include <vector>

#include "html.hpp"

namespace gaitmon::cli {
namespace {

struct Range {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  void add(double v) {
    if (!std::isfinite(v)) return;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  /// Finite and non-empty, padded by `pad` of its span (or by 1 when it is a point).
  Range padded(double pad) const {
    Range r = *this;
    if (!std::isfinite(r.lo)) return {0.0, 1.0};
    const double span = r.hi - r.lo;
    const double p = span > 0.0 ? pad * span : (r.lo != 0.0 ? 0.1 * std::abs(r.lo) : 1.0);
    r.lo -= p;
    r.hi += p;
    return r;
  }
};

/// One chart: a plot area with ticked axes and labels, into which series are drawn.
class Chart {
 public:
  Chart(int width, int height, Range x, Range y, const std::string& title,
        const std::string& x_label, const std::string& y_label)
      : w_(width), h_(height), x_(x), y_(y) {
    fmt::format_to(std::back_inserter(svg_),
                   "<svg width=\"{0}\" height=\"{1}\" "
                   "viewBox=\"0 0 {0} {1}\" role=\"img\">"
                   "<text x=\"{2}\" y=\"16\" class=\"title\" text-anchor=\"middle\">{3}</text>",
                   w_, h_, w_ / 2, escape(title));
    axes(x_label, y_label);
  }

  double px(double x) const { return kLeft + (x - x_.lo) / (x_.hi - x_.lo) * plot_w(); }
  double py(double y) const { return kTop + (1.0 - (y - y_.lo) / (y_.hi - y_.lo)) * plot_h(); }

  void line(std::span<const double> xs, std::span<const double> ys, std::string_view colour,
            double width, double opacity = 1.0) {
    svg_ += "<polyline fill=\"none\" stroke=\"";
    svg_ += colour;
    fmt::format_to(std::back_inserter(svg_),
                   "\" stroke-width=\"{}\" stroke-opacity=\"{}\" points=\"", width, opacity);
    for (std::size_t i = 0; i < xs.size() && i < ys.size(); ++i) {
      fmt::format_to(std::back_inserter(svg_), "{:.1f},{:.1f} ", px(xs[i]), py(ys[i]));
      if (i > 0) trace(px(xs[i - 1]), py(ys[i - 1]), px(xs[i]), py(ys[i]));
    }
    svg_ += "\"/>";
  }

  /// A filled band from `lo` up to `hi` along `xs`, cut at the plot's edges: a wide band must not
  /// set the scale of the values it surrounds.
  void band(std::span<const double> xs, std::span<const double> lo, std::span<const double> hi,
            std::string_view colour, double opacity) {
    const auto inside = [&](double y) { return py(std::clamp(y, y_.lo, y_.hi)); };
    fmt::format_to(std::back_inserter(svg_),
                   "<polygon class=\"band\" fill=\"{}\" fill-opacity=\"{}\" stroke=\"none\" "
                   "points=\"",
                   colour, opacity);
    for (std::size_t i = 0; i < xs.size(); ++i) {
      fmt::format_to(std::back_inserter(svg_), "{:.1f},{:.1f} ", px(xs[i]), inside(lo[i]));
    }
    for (std::size_t i = xs.size(); i-- > 0;) {
      fmt::format_to(std::back_inserter(svg_), "{:.1f},{:.1f} ", px(xs[i]), inside(hi[i]));
    }
    svg_ += "\"/>";
  }

  void dot(double x, double y, std::string_view colour, double r, double opacity = 1.0) {
    fmt::format_to(std::back_inserter(svg_),
                   "<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"{}\" fill=\"{}\" fill-opacity=\"{}\"/>",
                   px(x), py(y), r, colour, opacity);
    drawn_.emplace_back(px(x), py(y));
  }

  /// A box from q1 to q3 with the median, centred at x, half-width in pixels.
  void box(double x, const Spread& s, double half_px, std::string_view colour) {
    const double cx = px(x);
    fmt::format_to(std::back_inserter(svg_),
                   "<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\" "
                   "fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\"/>"
                   "<line x1=\"{:.1f}\" x2=\"{:.1f}\" y1=\"{:.1f}\" y2=\"{:.1f}\" stroke=\"{}\" "
                   "stroke-width=\"2.5\"/>",
                   cx - half_px, py(s.q3), 2 * half_px, std::max(0.5, py(s.q1) - py(s.q3)), colour,
                   cx - half_px, cx + half_px, py(s.median), py(s.median), colour);
  }

  /// A mean with a +/- SD bar at x.
  void mean_sd(double x, double mean, double sd, std::string_view colour) {
    const double cx = px(x);
    fmt::format_to(std::back_inserter(svg_),
                   "<line x1=\"{0:.1f}\" x2=\"{0:.1f}\" y1=\"{1:.1f}\" y2=\"{2:.1f}\" "
                   "stroke=\"{3}\" stroke-width=\"2\"/>"
                   "<rect x=\"{4:.1f}\" y=\"{5:.1f}\" width=\"8\" height=\"8\" fill=\"{3}\"/>",
                   cx, py(mean - sd), py(mean + sd), colour, cx - 4, py(mean) - 4);
  }

  void x_category(double x, std::string_view label) {
    fmt::format_to(std::back_inserter(svg_),
                   "<text x=\"{:.1f}\" y=\"{}\" text-anchor=\"middle\">{}</text>", px(x),
                   kTop + plot_h() + 16, escape(label));
  }

  /// The legend in the top corner that covers fewer of the points drawn so far (the right one
  /// on a tie): a forefoot's force and area peak late in the stance, under the right corner.
  void legend(std::span<const std::pair<std::string_view, std::string_view>> entries) {
    const int height = 14 * static_cast<int>(entries.size()) + 4;
    const auto covered = [&](int left) {
      return std::count_if(drawn_.begin(), drawn_.end(), [&](const auto& p) {
        return p.first >= left && p.first <= left + kLegendWidth && p.second >= kTop &&
               p.second <= kTop + 1 + height;
      });
    };
    const int right = w_ - kRight - 12 - kLegendWidth;
    const int left = kLeft + 12;
    const int x = covered(left) < covered(right) ? left : right;
    fmt::format_to(std::back_inserter(svg_),
                   "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"#fff\" "
                   "fill-opacity=\"0.85\" class=\"legend-box\"/>",
                   x, kTop + 1, kLegendWidth, height);
    int y = kTop + 6;
    for (const auto& [colour, label] : entries) {
      fmt::format_to(std::back_inserter(svg_),
                     "<rect x=\"{}\" y=\"{}\" width=\"14\" height=\"4\" fill=\"{}\"/>"
                     "<text x=\"{}\" y=\"{}\" class=\"legend\">{}</text>",
                     x + 4, y, colour, x + 22, y + 5, escape(label));
      y += 14;
    }
  }

  std::string finish() { return svg_ + "</svg>"; }

 private:
  static constexpr int kLeft = 64;
  static constexpr int kRight = 12;
  static constexpr int kTop = 26;
  static constexpr int kBottom = 42;
  static constexpr int kLegendWidth = 112;

  double plot_w() const { return w_ - kLeft - kRight; }
  double plot_h() const { return h_ - kTop - kBottom; }

  /// Points every few pixels along a segment, so that a legend is kept off a line whose
  /// vertices lie outside its box.
  void trace(double x0, double y0, double x1, double y1) {
    if (!std::isfinite(x0) || !std::isfinite(y0) || !std::isfinite(x1) || !std::isfinite(y1)) {
      return;
    }
    const int pieces = 1 + static_cast<int>(std::min(std::hypot(x1 - x0, y1 - y0) / 4.0, 1000.0));
    for (int k = 0; k <= pieces; ++k) {
      const double f = static_cast<double>(k) / pieces;
      drawn_.emplace_back(x0 + f * (x1 - x0), y0 + f * (y1 - y0));
    }
  }

  void axes(const std::string& x_label, const std::string& y_label) {
    fmt::format_to(std::back_inserter(svg_),
                   "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" class=\"frame\"/>", kLeft,
                   kTop, plot_w(), plot_h());
    if (!x_label.empty()) {
      const double step = nice_step(x_.hi - x_.lo, 6);
      for (double t = std::ceil(x_.lo / step) * step; t <= x_.hi + 1e-9 * step; t += step) {
        fmt::format_to(std::back_inserter(svg_),
                       "<line x1=\"{0:.1f}\" x2=\"{0:.1f}\" y1=\"{1}\" y2=\"{2}\" class=\"grid\"/>"
                       "<text x=\"{0:.1f}\" y=\"{3}\" text-anchor=\"middle\">{4:g}</text>",
                       px(t), kTop, kTop + plot_h(), kTop + plot_h() + 14,
                       std::abs(t) < 1e-12 * step ? 0.0 : t);
      }
    }
    const double step = nice_step(y_.hi - y_.lo, 5);
    for (double t = std::ceil(y_.lo / step) * step; t <= y_.hi + 1e-9 * step; t += step) {
      fmt::format_to(std::back_inserter(svg_),
                     "<line x1=\"{0}\" x2=\"{1}\" y1=\"{2:.1f}\" y2=\"{2:.1f}\" class=\"grid\"/>"
                     "<text x=\"{3}\" y=\"{4:.1f}\" text-anchor=\"end\">{5:.4g}</text>",
                     kLeft, kLeft + plot_w(), py(t), kLeft - 4, py(t) + 4,
                     std::abs(t) < 1e-12 * step ? 0.0 : t);
    }
    fmt::format_to(std::back_inserter(svg_),
                   "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" class=\"axis\">{}</text>"
                   "<text transform=\"translate(14,{}) rotate(-90)\" text-anchor=\"middle\" "
                   "class=\"axis\">{}</text>",
                   kLeft + plot_w() / 2, h_ - 6, escape(x_label), kTop + plot_h() / 2,
                   escape(y_label));
  }

  int w_;
  int h_;
  Range x_;
  Range y_;
  std::string svg_;
  std::vector<std::pair<double, double>> drawn_;  ///< along every line, and every dot, in pixels
};

constexpr std::string_view kMeasured = "#222222";
constexpr std::string_view kModel = "#d62728";
constexpr std::string_view kArea = "#1f77b4";
constexpr std::string_view kSeed = "#ff7f0e";
constexpr std::string_view kLeftFoot = kArea;
constexpr std::string_view kRightFoot = "#2ca02c";
constexpr std::size_t kMaxOverlaid = 60;

std::vector<double> since_heel_strike(const StepAnalysis& s) {
  std::vector<double> t = s.t_s;
  for (double& v : t) v -= s.t_heel_strike_s;
  return t;
}

/// Up to kMaxOverlaid steps with contact in the region, evenly spaced through the session.
std::vector<const StepAnalysis*> overlaid(std::span<const StepAnalysis> analyses, Region region) {
  std::vector<const StepAnalysis*> with;
  for (const auto& s : analyses) {
    if (s.at(region).fit.status == FitStatus::Ok) with.push_back(&s);
  }
  if (with.size() <= kMaxOverlaid) return with;
  std::vector<const StepAnalysis*> out;
  for (std::size_t i = 0; i < kMaxOverlaid; ++i)
    out.push_back(with[i * with.size() / kMaxOverlaid]);
  return out;
}

/// The step whose region fit has the median NRMSE among the Ok fits.
const StepAnalysis* typical_step(std::span<const StepAnalysis> analyses, Region region) {
  std::vector<const StepAnalysis*> ok;
  for (const auto& s : analyses) {
    if (s.at(region).fit.status == FitStatus::Ok) ok.push_back(&s);
  }
  if (ok.empty()) return nullptr;
  std::sort(ok.begin(), ok.end(), [region](const StepAnalysis* a, const StepAnalysis* b) {
    return a->at(region).fit.nrmse_pct < b->at(region).fit.nrmse_pct;
  });
  return ok[(ok.size() - 1) / 2];
}

std::string typical_chart(const StepAnalysis& s, Region region) {
  const RegionAnalysis& r = s.at(region);
  const std::vector<double> t = since_heel_strike(s);
  Range x, y;
  for (double v : t) x.add(v);
  for (double v : r.series.force_n) y.add(v);
  for (double v : r.fit.model_force_n) y.add(v);
  y.add(0.0);
  Chart c(420, 260, x.padded(0.02), y.padded(0.05),
          fmt::format("typical step ({} {}, NRMSE {:.1f} %)", foot_name(s.foot), s.step,
                      r.fit.nrmse_pct),
          "time since heel strike (s)", "force (N)");
  c.line(t, r.series.force_n, kMeasured, 2.0);
  c.line(t, r.fit.model_force_n, kModel, 2.0);
  const std::pair<std::string_view, std::string_view> legend[] = {{kMeasured, "measured"},
                                                                  {kModel, "model"}};
  c.legend(legend);
  return c.finish();
}

std::string overlay_chart(const std::vector<const StepAnalysis*>& steps, Region region,
                          std::size_t total) {
  Range x, y;
  for (const StepAnalysis* s : steps) {
    for (double v : since_heel_strike(*s)) x.add(v);
    for (double v : s->at(region).series.force_n) y.add(v);
    for (double v : s->at(region).fit.model_force_n) y.add(v);
  }
  y.add(0.0);
  Chart c(420, 260, x.padded(0.02), y.padded(0.05),
          fmt::format("all steps ({} of {} shown)", steps.size(), total),
          "time since heel strike (s)", "force (N)");
  for (const StepAnalysis* s : steps) {
    c.line(since_heel_strike(*s), s->at(region).series.force_n, kMeasured, 1.0, 0.35);
  }
  for (const StepAnalysis* s : steps) {
    c.line(since_heel_strike(*s), s->at(region).fit.model_force_n, kModel, 1.0, 0.35);
  }
  const std::pair<std::string_view, std::string_view> legend[] = {{kMeasured, "measured"},
                                                                  {kModel, "model"}};
  c.legend(legend);
  return c.finish();
}

std::string area_chart(const std::vector<const StepAnalysis*>& steps, const StepAnalysis* typical,
                       Region region) {
  Range x, y;
  for (const StepAnalysis* s : steps) {
    for (double v : since_heel_strike(*s)) x.add(v);
    for (double v : s->at(region).series.area_mm2) y.add(v);
  }
  y.add(0.0);
  Chart c(420, 260, x.padded(0.02), y.padded(0.05), "contact area given to the fit",
          "time since heel strike (s)", "area (mm\u00b2)");
  for (const StepAnalysis* s : steps) {
    c.line(since_heel_strike(*s), s->at(region).series.area_mm2, "#888888", 1.0, 0.35);
  }
  c.line(since_heel_strike(*typical), typical->at(region).series.area_mm2, kArea, 2.0);
  const std::pair<std::string_view, std::string_view> legend[] = {{kArea, "typical step"},
                                                                  {"#888888", "other steps"}};
  c.legend(legend);
  return c.finish();
}

struct ParamView {
  const char* label;
  const char* unit;
  double EllipsoidParams::*field;
  const Estimate RegionFit::*estimate;
  const Spread RegionSessionAnalysis::*spread;
  int pooled = -1;  ///< index in MaterialVector (pooling.hpp), -1 for the declared geometry
  const Estimate MaterialParams::*pooled_estimate = nullptr;  ///< the fitted four only
  /// Its trend over the session, for kbar and cbar (drift.hpp).
  const std::optional<LogTrend> RegionSessionAnalysis::*trend = nullptr;
};

constexpr ParamView kFitted[] = {
    {"kbar", "N/mm\u00b3", &EllipsoidParams::kbar_n_per_mm3, &RegionFit::kbar_n_per_mm3,
     &RegionSessionAnalysis::kbar_n_per_mm3, 0, &MaterialParams::kbar_n_per_mm3,
     &RegionSessionAnalysis::kbar_trend},
    {"n", "", &EllipsoidParams::n, &RegionFit::n, &RegionSessionAnalysis::n, 1, &MaterialParams::n},
    {"cbar", "N s/mm\u00b3", &EllipsoidParams::cbar_ns_per_mm3, &RegionFit::cbar_ns_per_mm3,
     &RegionSessionAnalysis::cbar_ns_per_mm3, 2, &MaterialParams::cbar_ns_per_mm3,
     &RegionSessionAnalysis::cbar_trend},
    {"m", "", &EllipsoidParams::m, &RegionFit::m, &RegionSessionAnalysis::m, 3, &MaterialParams::m},
};

constexpr ParamView kAll[] = {
    {"A", "mm", &EllipsoidParams::A_mm, &RegionFit::A_mm, &RegionSessionAnalysis::A_mm},
    {"B", "mm", &EllipsoidParams::B_mm, &RegionFit::B_mm, &RegionSessionAnalysis::B_mm},
    {"C", "mm", &EllipsoidParams::C_mm, &RegionFit::C_mm, &RegionSessionAnalysis::C_mm},
    {"d0", "mm", &EllipsoidParams::d0_mm, &RegionFit::d0_mm, &RegionSessionAnalysis::d0_mm},
    kFitted[0],
    kFitted[1],
    kFitted[2],
    kFitted[3],
};

/// Per step values (jittered strip), their box, and Appendix I's mean +/- SD beside them.
std::string strip_chart(std::span<const StepAnalysis> analyses, Region region, const ParamView& p,
                        const Spread& spread, const SeedTissueStats& seed) {
  std::vector<double> values;
  for (const auto& s : analyses) {
    const RegionFit& f = s.at(region).fit;
    if (f.status == FitStatus::Ok) values.push_back((f.*p.estimate).value);
  }
  Range y;
  for (double v : values) y.add(v);
  const double mean = seed.mean.*p.field;
  const double sd = seed.sd.*p.field;
  y.add(mean - sd);
  y.add(mean + sd);
  const std::string y_label =
      *p.unit ? fmt::format("{} ({})", p.label, p.unit) : std::string(p.label);
  Chart c(200, 260, {0.0, 2.0}, y.padded(0.08), p.label, "", y_label);
  for (std::size_t i = 0; i < values.size(); ++i) {
    // A golden-ratio sequence spreads the points evenly without randomness.
    const double jitter = std::fmod(static_cast<double>(i) * 0.618034, 1.0) - 0.5;
    c.dot(0.6 + 0.45 * jitter, values[i], kArea, 2.0, 0.45);
  }
  if (spread.count > 0) c.box(0.6, spread, 18, kMeasured);
  c.mean_sd(1.5, mean, sd, kSeed);
  c.x_category(0.6, "this session");
  c.x_category(1.5, "App. I");
  return c.finish();
}

/// One fitted parameter per step against its heel strike, a colour per foot, with each foot's
/// pooled per-step values as a line in a band of one standard error either side (the chain's
/// shared error included) where the steps were pooled, and the trend over the session where there
/// is one: a drift over the walk (warm-up, fatigue, a sensor warming) shows here and in no
/// distribution.
std::string course_chart(std::span<const StepAnalysis> analyses, const RegionSessionAnalysis& r,
                         const ParamView& p) {
  struct FootCourse {
    std::vector<double> t, own, t_pooled, pooled, pooled_lo, pooled_hi;
  };
  std::array<FootCourse, 2> feet;
  // pooled_per_step is aligned with the steps analyse_session was given, which are these.
  const bool aligned = r.pooled_per_step.size() == analyses.size();
  Range x, y;
  for (std::size_t i = 0; i < analyses.size(); ++i) {
    const StepAnalysis& s = analyses[i];
    const RegionFit& f = s.at(r.region).fit;
    if (f.status != FitStatus::Ok) continue;
    FootCourse& course = feet[s.foot == Foot::Left ? 0 : 1];
    course.t.push_back(s.t_heel_strike_s);
    course.own.push_back((f.*p.estimate).value);
    x.add(s.t_heel_strike_s);
    y.add(course.own.back());
    if (aligned && r.pooled_per_step[i]) {
      const Estimate& e = (*r.pooled_per_step[i]).*p.pooled_estimate;
      course.t_pooled.push_back(s.t_heel_strike_s);
      course.pooled.push_back(e.value);
      course.pooled_lo.push_back(e.value - e.se);
      course.pooled_hi.push_back(e.value + e.se);
      y.add(e.value);
    }
  }
  const LogTrend* trend = p.trend != nullptr && r.*p.trend ? &*(r.*p.trend) : nullptr;
  const std::array<double, 2> ends = {x.lo, x.hi};
  std::array<double, 2> trend_ends{};
  if (trend != nullptr) {
    trend_ends = {trend->at(x.lo), trend->at(x.hi)};
    for (double v : trend_ends) y.add(v);
  }
  const std::string y_label =
      *p.unit ? fmt::format("{} ({})", p.label, p.unit) : std::string(p.label);
  Chart c(420, 240, x.padded(0.03), y.padded(0.08), fmt::format("{} over the session", p.label),
          "heel strike (s)", y_label);
  const std::array<std::string_view, 2> colours = {kLeftFoot, kRightFoot};
  bool pooled = false;
  for (std::size_t foot = 0; foot < feet.size(); ++foot) {
    for (std::size_t k = 0; k < feet[foot].t.size(); ++k) {
      c.dot(feet[foot].t[k], feet[foot].own[k], colours[foot], 2.2, 0.6);
    }
    if (feet[foot].pooled.empty()) continue;
    c.band(feet[foot].t_pooled, feet[foot].pooled_lo, feet[foot].pooled_hi, colours[foot], 0.15);
    c.line(feet[foot].t_pooled, feet[foot].pooled, colours[foot], 1.5);
    pooled = true;
  }
  std::vector<std::pair<std::string_view, std::string_view>> legend = {
      {kLeftFoot, "left, each step"}, {kRightFoot, "right"}};
  if (pooled) legend.emplace_back(kMeasured, "pooled \u00b1 SE (lines)");
  std::string trend_label;
  if (trend != nullptr) {
    c.line(ends, trend_ends, kModel, 2.0, 0.8);
    trend_label =
        fmt::format("{:+.1f} \u00b1 {:.1f} %/min", trend->pct_per_min, trend->se_pct_per_min);
    legend.emplace_back(kModel, trend_label);
  }
  c.legend(legend);
  return c.finish();
}

std::string num(double v) {
  return fmt::format("{:.4g}", v);
}

// The pooled mean of one fitted parameter with its standard error (the chain's shared error
// included) and the between-step SD the pooling found: SD relative for kbar and cbar, which are
// pooled as logarithms.
std::string pooled_cell(const RegionSessionAnalysis& r, const ParamView& p) {
  if (p.pooled < 0 || !r.pooled_mean) return "&ndash;";
  const auto k = static_cast<std::size_t>(p.pooled);
  const double sd = std::sqrt(r.pooling.between_step[k][k]);
  const Estimate e = material_params(*r.pooled_mean).*p.pooled_estimate;
  const bool log_scale = k == 0 || k == 2;
  return fmt::format("{} &plusmn; {} ({})", num(e.value), num(e.se),
                     log_scale ? fmt::format("{:.0f} %", 100.0 * sd) : num(sd));
}

std::string param_table(const RegionSessionAnalysis& r, const SeedTissueStats& seed) {
  std::string out = fmt::format(
      "<table><tr><th>parameter</th><th>session fit (SE)</th><th>median across steps "
      "(IQR)</th><th>pooled mean &plusmn; SE with the chain&apos;s error (between-step "
      "SD){}</th><th>Appendix I mean (SD)</th></tr>",
      r.pooling.pooled ? "" : "<br>not pooled: " + escape(r.pooling.not_pooled));
  for (const ParamView& p : kAll) {
    const Estimate& e = r.session_fit.*p.estimate;
    const Spread& s = r.*p.spread;
    std::string session = "&ndash;";
    if (r.session_fit.status == FitStatus::Ok) {
      session = e.free ? fmt::format("{} ({})", num(e.value),
                                     std::isfinite(e.se) ? num(e.se) : "undetermined")
                       : fmt::format("{} <i>declared</i>", num(e.value));
      if (e.at_bound) session += " <b>at bound</b>";
    }
    const std::string unit = *p.unit ? fmt::format(" ({})", p.unit) : "";
    fmt::format_to(std::back_inserter(out),
                   "<tr><td>{}{}</td><td>{}</td><td>{}</td><td>{}</td><td>{} ({})</td></tr>",
                   p.label, unit, session,
                   s.count > 0 ? fmt::format("{} ({})", num(s.median), num(s.iqr())) : "&ndash;",
                   pooled_cell(r, p), num(seed.mean.*p.field), num(seed.sd.*p.field));
  }
  fmt::format_to(
      std::back_inserter(out),
      "<tr><td>NRMSE (%)</td><td>{}</td><td>{}</td><td>&ndash;</td><td>{} ({})</td></tr></table>",
      r.session_fit.status == FitStatus::Ok ? fmt::format("{:.1f}", r.session_fit.nrmse_pct)
                                            : "&ndash;",
      r.nrmse_pct.count > 0 ? fmt::format("{:.1f} ({:.1f})", r.nrmse_pct.median, r.nrmse_pct.iqr())
                            : "&ndash;",
      num(seed.nrmse_pct_mean), num(seed.nrmse_pct_sd));
  return out;
}

std::string region_section(const ReportInput& in, const RegionSessionAnalysis& r) {
  const SeedTissueStats& seed = in.config->tissue(in.size, r.region);
  std::string out;
  fmt::format_to(
      std::back_inserter(out),
      "<section id=\"{0}\"><h2>{0}</h2><p>{1} steps with contact, {2} fitted; session-level fit: "
      "{3}{4}. A/B = {5:.3f} (median measured contact-ellipse aspect).</p>",
      region_name(r.region), r.steps_with_contact, r.steps_fitted,
      fit_status_name(r.session_fit.status),
      r.session_fit.reason.empty() ? "" : " (" + escape(r.session_fit.reason) + ")", r.aspect);
  if (r.steps_on_ellipse > 0) {
    fmt::format_to(std::back_inserter(out),
                   "<p class=\"note\">Fitted on the <b>contact ellipse</b> in {} of {} steps: this "
                   "region's active cells determined no footprint, so its area moves in whole "
                   "cells, and n, cbar and m are not determined by it: their values are where the "
                   "fit came to rest, not the tissue's.</p>",
                   r.steps_on_ellipse, r.steps_with_contact);
  }
  const StepAnalysis* typical = typical_step(in.analyses, r.region);
  if (typical != nullptr) {
    const auto shown = overlaid(in.analyses, r.region);
    out += "<div class=\"row\">";
    out += typical_chart(*typical, r.region);
    out += overlay_chart(shown, r.region, static_cast<std::size_t>(r.steps_fitted));
    out += area_chart(shown, typical, r.region);
    out += "</div><div class=\"row\">";
    for (const ParamView& p : kFitted) {
      out += strip_chart(in.analyses, r.region, p, r.*p.spread, seed);
    }
    out += "</div><div class=\"row\">";
    out += course_chart(in.analyses, r, kFitted[0]);
    out += course_chart(in.analyses, r, kFitted[2]);
    out += "</div>";
  } else {
    out += "<p>No step of this region was fitted.</p>";
  }
  out += param_table(r, seed);
  out += "</section>";
  return out;
}

/// Each region's kbar and cbar under the right foot against the left, with two standard errors
/// either side (the steps' and the pair of insoles' together), and the same in a table.
std::string feet_section(const SessionAnalysis& session, AreaSource area) {
  constexpr std::array<std::string_view, kRegionCount> kShort = {
      "heel", "midfoot post.", "midfoot ant.", "met1_2", "met3_5", "toe1", "toe2", "toes3_5"};
  std::string out = "<section id=\"feet\"><h2>Left against right</h2>";
  Range y;
  y.add(0.0);
  bool any = false;
  for (const RegionSessionAnalysis& r : session.regions) {
    for (const auto* a : {&r.kbar_asymmetry, &r.cbar_asymmetry}) {
      if (!*a) continue;
      any = true;
      y.add((*a)->pct - 2.0 * (*a)->se_pct);
      y.add((*a)->pct + 2.0 * (*a)->se_pct);
    }
  }
  if (!any) {
    fmt::format_to(std::back_inserter(out),
                   "<p>Not compared: no region has {} steps of each foot with kbar or cbar off its "
                   "bounds.</p></section>",
                   kMinAsymmetryStepsPerFoot);
    return out;
  }
  Chart c(760, 260, {-0.5, kRegionCount - 0.5}, y.padded(0.08),
          "Right foot against left (\u00b1 2 SE)", "", "right / left \u2212 1 (%)");
  c.line(std::array{-0.5, kRegionCount - 0.5}, std::array{0.0, 0.0}, kMeasured, 1.0);
  std::string rows;
  const auto cell = [](const std::optional<FootAsymmetry>& a, Region region) -> std::string {
    if (!a) return "&ndash;";
    const std::string text =
        fmt::format("{:+.1f} &plusmn; {:.1f} (z {:+.1f})", a->pct, a->se_pct, a->z());
    return std::abs(a->z()) >= 3.0 && !is_toe(region) ? "<b>" + text + "</b>" : text;
  };
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const RegionSessionAnalysis& r = session.regions[i];
    const double x = static_cast<double>(i);
    if (r.kbar_asymmetry) {
      c.mean_sd(x - 0.15, r.kbar_asymmetry->pct, 2.0 * r.kbar_asymmetry->se_pct, kLeftFoot);
    }
    if (r.cbar_asymmetry) {
      c.mean_sd(x + 0.15, r.cbar_asymmetry->pct, 2.0 * r.cbar_asymmetry->se_pct, kRightFoot);
    }
    c.x_category(x, kShort[i]);
    fmt::format_to(std::back_inserter(rows), "<tr><td>{}</td><td>{}</td><td>{}</td></tr>",
                   region_name(r.region), cell(r.kbar_asymmetry, r.region),
                   cell(r.cbar_asymmetry, r.region));
  }
  const std::array<std::pair<std::string_view, std::string_view>, 2> legend = {
      {{kLeftFoot, "kbar"}, {kRightFoot, "cbar"}}};
  c.legend(legend);
  out += c.finish();
  fmt::format_to(
      std::back_inserter(out),
      "<p class=\"note\">How much higher each region's kbar and cbar are under the right foot than "
      "under the left, at the same time of the walk (a drift both feet share is taken out). The "
      "standard error holds the steps' scatter and what the pair of insoles alone makes of the "
      "same tissue (<code>{}</code> of the config, or <code>{}</code> at one m per session): a "
      "difference between the two insoles reads as one of the tissue. Bold: 3 standard errors or "
      "more, outside the toes, "
      "whose one to three active cells scatter beyond their standard errors.</p><table><tr>"
      "<th>region</th><th>kbar, right vs left (%)</th><th>cbar, right vs left (%)</th></tr>{}"
      "</table></section>",
      chain_table_name("asymmetry", area, false), chain_table_name("asymmetry", area, true), rows);
  return out;
}

std::string step_table(std::span<const StepRow> steps) {
  std::string out =
      "<section id=\"steps\"><h2>Steps</h2><table><tr><th>foot</th><th>step</th><th>heel strike "
      "(s)</th>"
      "<th>toe off (s)</th><th>stance (s)</th><th>peak force (N)</th><th>status</th>"
      "<th>total-force NRMSE (%)</th></tr>";
  for (const StepRow& s : steps) {
    fmt::format_to(std::back_inserter(out),
                   "<tr><td>{}</td><td>{}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.3f}</td>"
                   "<td>{:.1f}</td><td>{}</td><td>{}</td></tr>",
                   foot_name(s.foot), s.index, s.t_heel_strike_s, s.t_toe_off_s,
                   s.t_toe_off_s - s.t_heel_strike_s, s.peak_force_n, step_status_name(s.status),
                   s.nrmse_total_pct ? fmt::format("{:.1f}", *s.nrmse_total_pct) : "");
  }
  out += "</table></section>";
  return out;
}

std::string estimate_cell(const ParamEstimate& p) {
  return fmt::format("{} ({})", num(p.value), std::isfinite(p.se) ? num(p.se) : "undetermined");
}

std::string sandwich_cell(const ParamEstimate& p) {
  return std::isfinite(p.se) && std::isfinite(p.robust_se) ? num(p.robust_se) : "&ndash;";
}

// Without it the parameters and model forces below could be read as the baseline's.
std::string effects_section(const ExtendedModelFit& fit) {
  const EffectPlacement placed = place_effects(fit);
  std::string out = "<section id=\"effects\"><h2>Effects in the model (--effects)</h2>";
  if (!placed.inside.empty()) {
    fmt::format_to(std::back_inserter(out),
                   "<p class=\"note\">Each step's tissue parameters and model forces below are "
                   "fitted with <b>{}</b> inside its model: the model force is what the cells "
                   "report of the tissue's force through them.</p>",
                   escape(fmt::format("{}", fmt::join(placed.inside, " and "))));
  }
  if (!placed.undone.empty()) {
    fmt::format_to(std::back_inserter(out),
                   "<p class=\"note\"><b>{}</b> {} undone in the readings at the parameters "
                   "below, and every step measured again from them, before each step's fit; the "
                   "other effects are fitted on those readings. The pooled NRMSE at the end of "
                   "this section compares the model without the effects on the readings as read, "
                   "where creep is fitted from the steps' zeros, with the model with them on the "
                   "readings with it undone.</p>",
                   escape(fmt::format("{}", fmt::join(placed.undone, " and "))),
                   placed.undone.size() == 1 ? "is" : "are");
  }
  if (!placed.on_top.empty()) {
    fmt::format_to(std::back_inserter(out),
                   "<p class=\"note\"><b>{}</b> {} fitted on top of the tissue parameters "
                   "below, not inside each step's fit.</p>",
                   escape(fmt::format("{}", fmt::join(placed.on_top, " and "))),
                   placed.on_top.size() == 1 ? "is" : "are");
  }
  out +=
      "<table><tr><th>effect</th><th>parameter</th><th>value (SE)</th><th>step-clustered "
      "sandwich SE</th><th>in each step's fit</th></tr>";
  for (const EffectEstimate& e : fit.effects) {
    const std::string_view place = effect_inside_tissue_fit(e.name)    ? "inside"
                                   : effect_undone_in_readings(fit, e) ? "undone in the readings"
                                                                       : "on top";
    for (const ParamEstimate& p : e.params) {
      fmt::format_to(std::back_inserter(out),
                     "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                     escape(e.name), escape(p.name), estimate_cell(p), sandwich_cell(p), place);
    }
  }
  fmt::format_to(std::back_inserter(out),
                 "</table><p>Pooled NRMSE over the step-regions compared: {:.2f} % without the "
                 "effects, {:.2f} % with them; held out (k-fold over steps) {:.2f} % and "
                 "{:.2f} %.</p></section>",
                 fit.baseline_nrmse_pct, fit.extended_nrmse_pct, fit.baseline_heldout_nrmse_pct,
                 fit.extended_heldout_nrmse_pct);
  return out;
}

constexpr std::string_view kStyle =
    "body{font-family:sans-serif;margin:24px;color:#222;max-width:1320px}"
    "h1{font-size:22px}h2{font-size:18px;margin-top:28px;border-bottom:1px solid #ccc}"
    "table{border-collapse:collapse;font-size:13px;margin:8px 0}"
    "td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}"
    "th{background:#f2f2f2}.row{display:flex;flex-wrap:wrap;gap:8px}"
    "svg{font-size:11px;background:#fff}svg .title{font-size:13px;font-weight:bold}"
    "svg .axis{font-size:12px}svg .legend{font-size:11px}"
    "svg .frame{fill:none;stroke:#555}svg .grid{stroke:#e4e4e4}"
    ".note{background:#fff8e6;border:1px solid #f0d080;padding:8px;font-size:13px}";

}  // namespace

double residual_rms_bits(double residual_ss, int cells) {
  return cells > 0 ? std::sqrt(residual_ss / cells) : 0.0;
}

std::string_view cell_reading_name(std::optional<CellReading> reading) {
  if (!reading) return "undetermined";
  return *reading == CellReading::Mean ? "mean" : "centre";
}

nlohmann::json cell_reading_json(const CellReadingEvidence& e) {
  const CellReadingFits& f = e.fits();
  return {
      {"frames", f.frames},
      {"mean_better_frames", f.mean_better},
      {"centre_residual_rms_bits", residual_rms_bits(f.centre_residual_ss, f.cells)},
      {"mean_residual_rms_bits", residual_rms_bits(f.mean_residual_ss, f.cells)},
      {"favoured", cell_reading_name(e.favoured())},
      {"crosstalk_coupling", e.coupling()},
      {"note", "each step's frame of each region's largest summed reading (at least " +
                   std::to_string(CellReadingEvidence::kMinEvidenceCells) +
                   " active cells) fitted with a paraboloid cap read at the cells' centres and "
                   "averaged over them, with the readings' crosstalk undone at couplings 0 to " +
                   fmt::format("{:g}", CellReadingEvidence::kCouplings.back()) +
                   "; the fits are those at the coupling where the better reading fits best "
                   "(crosstalk_coupling, refined between the grid's points); favoured: the reading "
                   "with the smaller residual in at least three quarters of at least 10 frames"}};
}

std::string cell_reading_sentence(const CellReadingEvidence& e) {
  const CellReadingFits& f = e.fits();
  if (f.frames == 0) {
    return fmt::format("no region-frame with {} active cells to tell how the cells read",
                       CellReadingEvidence::kMinEvidenceCells);
  }
  const std::optional<CellReading> favoured = e.favoured();
  const double coupling = e.coupling();
  return fmt::format(
      "a cap read at the cells' centres fits {} of {} region-frames better, averaged over them "
      "{} (residual RMS {:.2f} against {:.2f} bits{}): {}",
      f.frames - f.mean_better, f.frames, f.mean_better,
      residual_rms_bits(f.centre_residual_ss, f.cells),
      residual_rms_bits(f.mean_residual_ss, f.cells),
      coupling > 0.0 ? fmt::format(", with a crosstalk of {:.3f} undone", coupling) : "",
      !favoured                        ? "undetermined"
      : *favoured == CellReading::Mean ? "the cells average the pressure (footprint-mean)"
                                       : "the cells read at their centres (footprint)");
}

std::string cell_reading_advice(const CellReadingEvidence& e, AreaSource area) {
  const std::optional<CellReading> favoured = e.favoured();
  if (favoured == CellReading::Mean && area == AreaSource::Footprint) {
    return "the footprint over-reads averaging cells and n comes out about twice the truth; "
           "--area footprint-mean (or auto) fits them";
  }
  if (favoured == CellReading::Centre && area == AreaSource::FootprintMean) {
    return "footprint-mean is biased on cells that read at their centres and n comes out far "
           "below the truth; --area footprint (or auto) fits them";
  }
  return {};
}

EffectPlacement place_effects(const ExtendedModelFit& fit) {
  EffectPlacement placed;
  for (const EffectEstimate& e : fit.effects) {
    (effect_inside_tissue_fit(e.name)    ? placed.inside
     : effect_undone_in_readings(fit, e) ? placed.undone
                                         : placed.on_top)
        .push_back(e.name);
  }
  return placed;
}

std::string render_report_html(const ReportInput& in) {
  std::string out = "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>";
  out += "gaitmon analyze: " + escape(in.session_name);
  out += "</title><style>";
  out += kStyle;
  out += "</style></head><body>";
  const auto& fit = in.settings->fit;
  std::size_t ok = 0;
  for (const auto& s : in.steps) ok += s.status == StepStatus::Ok ? 1 : 0;
  fmt::format_to(
      std::back_inserter(out),
      "<h1>gaitmon analyze: {}</h1><p>Insole {}, {} Hz; {} steps, {} complete and "
      "analysed. Model {}, fit {}, smoothing {}, contact area {}{}{}{}{}. Median total-force "
      "NRMSE {:.1f} % "
      "(IQR {:.1f} %).</p>",
      escape(in.session_name), insole_size_name(in.size), in.sample_rate_hz, in.steps.size(), ok,
      model_variant_name(fit.model), fit_mode_name(fit.mode), smoothing_name(fit.smoothing),
      area_source_name(in.settings->area), in.area_auto ? " (auto, from how the cells read)" : "",
      fit.end_rate == EndRate::TwoFrame ? "" : ", second-order area rate at contact ends",
      fit.free_scale ? ", P free" : "",
      std::any_of(in.session->regions.begin(), in.session->regions.end(),
                  [](const RegionSessionAnalysis& r) { return r.m_per_session.has_value(); })
          ? ", one m per region over the session"
          : "",
      in.session->nrmse_total_pct.median, in.session->nrmse_total_pct.iqr());
  if (in.cells != nullptr) {
    const std::string advice = cell_reading_advice(*in.cells, in.settings->area);
    fmt::format_to(std::back_inserter(out), "<p>How the cells read: {}.{}</p>",
                   escape(cell_reading_sentence(*in.cells)),
                   advice.empty() ? "" : " <strong>Note: " + escape(advice) + ".</strong>");
  }
  if (fit.mode == FitMode::Seed8) {
    out +=
        "<p class=\"note\"><b>--fit seed8</b>: all eight parameters are free, as in the seed. "
        "Force and contact area cannot determine C and d0 (nor, fully, A and B): their values "
        "are wherever the optimiser stopped. Boxes span the interquartile range with the "
        "median; orange marks Appendix I's mean &plusmn; SD.</p>";
  } else {
    fmt::format_to(std::back_inserter(out),
                   "<p class=\"note\">C and d0 are <b>declared</b>, not fitted: force and contact "
                   "area cannot determine them. They are the seed's Appendix I means for insole "
                   "{}; A/B is the median measured contact-ellipse aspect with P = &pi;AB {}. "
                   "kbar and cbar are derived under those declared values, so compare "
                   "them with Appendix I only with that in mind. Per region: the typical step is "
                   "the one with the median NRMSE; boxes span the interquartile range with the "
                   "median; orange marks Appendix I's mean &plusmn; SD. The pooled mean comes "
                   "from pooling the steps' fits, each with its own uncertainty; the "
                   "between-step SD is how much the tissue itself seems to vary beyond those "
                   "uncertainties (in % for kbar and cbar).</p>",
                   insole_size_name(in.size),
                   fit.free_scale ? "fitted per region-step (--free-scale)" : "from Appendix I");
  }
  out += "<p>Regions:";
  for (Region region : kRegions) {
    fmt::format_to(std::back_inserter(out), " <a href=\"#{0}\">{0}</a>", region_name(region));
  }
  out += " &middot; <a href=\"#feet\">left against right</a> &middot; <a href=\"#steps\">steps</a>";
  if (in.extended != nullptr) out += " &middot; <a href=\"#effects\">effects</a>";
  out += "</p>";
  if (in.extended != nullptr) out += effects_section(*in.extended);
  out += feet_section(*in.session, in.settings->area);
  for (const RegionSessionAnalysis& r : in.session->regions) out += region_section(in, r);
  out += step_table(in.steps);
  out += "</body></html>\n";
  return out;
}

}  // namespace gaitmon::cli
