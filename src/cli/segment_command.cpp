// `gaitmon segment`: steps, and per region and frame the force, area and contact ellipse.
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>

#include "commands.hpp"
#include "gaitmon/batch.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/stance.hpp"
#include "output_file.hpp"
#include "progress.hpp"

namespace gaitmon::cli {
namespace {

// What a run writes, and so what a rerun removes first.
constexpr std::string_view kStepsCsv = "steps.csv";
constexpr std::string_view kFramesCsv = "frames.csv";

struct SegmentArgs {
  std::filesystem::path session;
  std::filesystem::path out_dir;
};

struct StepRow {
  Foot foot;
  int index;
  double t_heel_strike_s;
  double t_toe_off_s;
  double peak_force_n;
  StepStatus status;
};

struct MeanSd {
  double mean = 0.0;
  double sd = 0.0;
};

MeanSd mean_sd(const std::vector<double>& values) {
  MeanSd r;
  if (values.empty()) return r;
  for (double v : values) r.mean += v;
  r.mean /= static_cast<double>(values.size());
  if (values.size() < 2) return r;
  double ss = 0.0;
  for (double v : values) ss += (v - r.mean) * (v - r.mean);
  r.sd = std::sqrt(ss / static_cast<double>(values.size() - 1));
  return r;
}

void print_summary(const SegmentArgs& args, const SegmentedSessionInfo& info,
                   const std::vector<StepRow>& steps,
                   const std::map<std::pair<Region, EllipseCase>, long>& cases,
                   std::size_t frame_rows) {
  const auto& h = info.header;
  const double duration_s =
      static_cast<double>(std::max(info.frames_per_foot[0], info.frames_per_foot[1])) /
      h.sample_rate_hz;
  fmt::print("{}: insole {}, {} Hz, {} sensors, about {:.1f} s\n", args.session.string(),
             insole_size_name(h.insole_size), h.sample_rate_hz, h.sensors, duration_s);
  fmt::print("{:<5}{:>7}{:>5}{:>12}{:>22}{:>26}\n", "foot", "steps", "ok", "incomplete",
             "stance s, mean (SD)", "peak force N, mean (SD)");
  for (Foot foot : kFeet) {
    std::vector<double> stance;
    std::vector<double> peak;
    int incomplete = 0;
    for (const auto& s : steps) {
      if (s.foot != foot) continue;
      if (s.status != StepStatus::Ok) {
        ++incomplete;
        continue;
      }
      stance.push_back(s.t_toe_off_s - s.t_heel_strike_s);
      peak.push_back(s.peak_force_n);
    }
    const MeanSd st = mean_sd(stance);
    const MeanSd pk = mean_sd(peak);
    fmt::print("{:<5}{:>7}{:>5}{:>12}{:>22}{:>26}\n", foot_name(foot), stance.size() + incomplete,
               stance.size(), incomplete, fmt::format("{:.3f} ({:.3f})", st.mean, st.sd),
               fmt::format("{:.1f} ({:.1f})", pk.mean, pk.sd));
  }
  if (info.gaps_per_foot[0] + info.gaps_per_foot[1] > 0) {
    fmt::print(
        "time gaps over max_gap_s: L {}, R {}; each ends the foot's segmentation as at the "
        "end of a recording (a contact open at a gap is incomplete)\n",
        info.gaps_per_foot[0], info.gaps_per_foot[1]);
  }
  fmt::print("\ncontact-ellipse cases over all analysed frames (seed ch. 4):\n");
  fmt::print("{:<19}", "region");
  const std::array kCases{EllipseCase::None,       EllipseCase::Isolated, EllipseCase::Rectangle,
                          EllipseCase::Neighbours, EllipseCase::Boundary, EllipseCase::Long};
  for (EllipseCase c : kCases) fmt::print("{:>11}", ellipse_case_name(c));
  fmt::print("\n");
  for (Region region : kRegions) {
    fmt::print("{:<19}", region_name(region));
    for (EllipseCase c : kCases) {
      const auto it = cases.find({region, c});
      fmt::print("{:>11}", it == cases.end() ? 0L : it->second);
    }
    fmt::print("\n");
  }
  fmt::print("\nwrote {} ({} steps) and {} ({} rows)\n", (args.out_dir / kStepsCsv).string(),
             steps.size(), (args.out_dir / kFramesCsv).string(), frame_rows);
}

void segment_into_out_dir(const SegmentArgs& args, const Config& config,
                          const InsoleLayout& layout) {
  OutputFile frames_csv(args.out_dir / kFramesCsv);
  frames_csv.write(
      "foot,step,t_s,region,force_n,sensor_area_mm2,ellipse_area_mm2,case,cx_mm,cy_mm,ra_mm,"
      "rb_mm,angle_rad,pi\n");
  std::vector<StepRow> steps;
  std::map<std::pair<Region, EllipseCase>, long> cases;
  std::size_t frame_rows = 0;
  std::string buffer;
  ProgressBar progress("segment");
  ContactEllipseCache ellipses;

  auto on_step = [&](Step&& step) {
    steps.push_back({step.foot, step.index, step.t_heel_strike_s, step.t_toe_off_s,
                     step.peak_force_n, step.status});
    if (step.status != StepStatus::Ok) return;
    const StanceSeries series = measure_stance(step, layout, config.calibration, &ellipses);
    buffer.clear();
    for (std::size_t f = 0; f < series.size(); ++f) {
      for (Region region : kRegions) {
        const RegionSample& s = series.at(f, region);
        const ContactEllipse& e = s.ellipse;
        fmt::format_to(std::back_inserter(buffer),
                       "{},{},{},{},{:.3f},{:.1f},{:.2f},{},{:.3f},{:.3f},{:.3f},{:.3f},{:.5f},"
                       "{:.5f}\n",
                       foot_name(step.foot), step.index, series.t_s[f], region_name(region),
                       s.force_n, s.sensor_area_mm2, e.area_mm2, ellipse_case_name(e.kase), e.cx_mm,
                       e.cy_mm, e.ra_mm, e.rb_mm, e.angle_rad, e.pi);
        ++cases[{region, e.kase}];
        ++frame_rows;
      }
    }
    frames_csv.write(buffer);
  };
  const SegmentedSessionInfo info = segment_session(
      args.session, config, on_step, [&](double fraction) { progress.update(fraction); });

  std::sort(steps.begin(), steps.end(), [](const StepRow& a, const StepRow& b) {
    return std::pair(a.foot, a.index) < std::pair(b.foot, b.index);
  });
  OutputFile steps_csv(args.out_dir / kStepsCsv);
  buffer = "foot,step,t_heel_strike_s,t_toe_off_s,stance_s,peak_force_n,status\n";
  for (const auto& s : steps) {
    fmt::format_to(std::back_inserter(buffer), "{},{},{},{},{:.4f},{:.2f},{}\n", foot_name(s.foot),
                   s.index, s.t_heel_strike_s, s.t_toe_off_s, s.t_toe_off_s - s.t_heel_strike_s,
                   s.peak_force_n, step_status_name(s.status));
  }
  steps_csv.write(buffer);
  OutputFile* const outputs[] = {&frames_csv, &steps_csv};
  OutputFile::commit_all(outputs);
  print_summary(args, info, steps, cases, frame_rows);
}

void run_segment(const GlobalOptions& global, const SegmentArgs& args) {
  const Config config = load_global_config(global);
  check_output_dir(args.out_dir, "--out");
  remove_earlier_outputs(args.out_dir, {kStepsCsv, kFramesCsv}, std::span(&args.session, 1));
  // The layout follows the session's insole size, so read its header first.
  const InsoleLayout layout(config.insole(SessionReader(args.session).header().insole_size),
                            config.sensor);
  // frames.csv is written as the session is read, so the folder comes first; a run that fails
  // takes back a folder it made, as it takes back its files.
  const bool created = std::filesystem::create_directories(args.out_dir);
  try {
    segment_into_out_dir(args, config, layout);
  } catch (...) {
    std::error_code ignored;
    if (created) std::filesystem::remove(args.out_dir, ignored);
    throw;
  }
}

}  // namespace

void add_segment_command(CLI::App& app, const GlobalOptions& global) {
  auto args = std::make_shared<SegmentArgs>();
  CLI::App* sub = app.add_subcommand(
      "segment",
      "Cut a session into steps (seed 3.3) and measure every region's force, active-sensor "
      "area and contact ellipse per frame (seed 3.4, ch. 4): writes DIR/steps.csv and "
      "DIR/frames.csv");
  sub->add_option("session", args->session, "Session CSV v1")
      ->required()
      ->check(session_file_read_twice());
  sub->add_option("--out,-o", args->out_dir, "Output folder")->required();
  sub->callback([&global, args] { run_segment(global, *args); });
}

}  // namespace gaitmon::cli
