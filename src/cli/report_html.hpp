// The self-contained HTML report of `gaitmon analyze`: inline SVG and CSS, no script, no network.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "gaitmon/analysis.hpp"
#include "gaitmon/config.hpp"
#include "gaitmon/discrepancy.hpp"
#include "gaitmon/segmentation.hpp"
#include "gaitmon/stance.hpp"

namespace gaitmon::cli {

/// One line of steps.csv.
struct StepRow {
  Foot foot = Foot::Left;
  int index = 0;
  double t_heel_strike_s = 0.0;
  double t_toe_off_s = 0.0;
  double peak_force_n = 0.0;
  StepStatus status = StepStatus::Ok;
  std::optional<double> nrmse_total_pct;  ///< analysed steps only
};

struct ReportInput {
  std::string session_name;
  InsoleSize size = InsoleSize::S37_38;
  double sample_rate_hz = 100.0;
  const Config* config = nullptr;
  const AnalysisSettings* settings = nullptr;
  bool area_auto = false;  ///< the settings' area was chosen from how the cells read
  std::span<const StepRow> steps;
  std::span<const StepAnalysis> analyses;  ///< Ok steps, by foot then step
  const SessionAnalysis* session = nullptr;
  const ExtendedModelFit* extended = nullptr;  ///< of --effects; null without
  const CellReadingEvidence* cells = nullptr;  ///< how the cells read; null leaves it out
};

/// The effects of an extended model by where `analyze` puts them: inside each step's tissue fit
/// (effect_inside_tissue_fit), undone in the readings before each step is measured
/// (effect_undone_in_readings), or on top of the baseline's tissue parameters, in its order.
struct EffectPlacement {
  std::vector<std::string> inside;
  std::vector<std::string> undone;
  std::vector<std::string> on_top;
};
EffectPlacement place_effects(const ExtendedModelFit& fit);

/// "centre", "mean" or "undetermined".
std::string_view cell_reading_name(std::optional<CellReading> reading);
/// How the cells read, as session.json and discrepancy.json give it.
nlohmann::json cell_reading_json(const CellReadingEvidence& evidence);
/// How the cells read, in one sentence for the summary and the report: how many region-frames
/// each reading fits better, the residuals and what they favour.
std::string cell_reading_sentence(const CellReadingEvidence& evidence);
/// The advice where the footprint `area` is not the one the cells' reading calls for, else empty.
std::string cell_reading_advice(const CellReadingEvidence& evidence, AreaSource area);
/// The residual RMS of `residual_ss` over `cells` residuals (0 without any).
double residual_rms_bits(double residual_ss, int cells);

/// The whole report as one HTML document.
std::string render_report_html(const ReportInput& input);

}  // namespace gaitmon::cli
