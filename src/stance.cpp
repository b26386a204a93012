// Turns a segmented step into per-region force, area and ellipse series (seed 3.4, 3.5, ch. 4).
#include "gaitmon/stance.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

#include "gaitmon/crosstalk.hpp"
#include "parallel_for.hpp"

namespace gaitmon {
namespace {

// The footprints fitted over the thresholded and the unthresholded cells may differ by this
// fraction at most. Beyond it one of them is wrong and the frame gets no footprint: either the
// low readings are not the cap's rim but a sensor still reading after its load has gone, as
// under creep (4 bits on every cell around a cap of 8 widened it by three quarters), or the
// thresholded fit rests on a few nearly flat loads and extrapolates (met3_5 of a simulated
// step: 1422 mm^2 between 987 and 1174, where the unthresholded fit gave 1070; the damping
// term turned that one-frame spike into 40-76 N of residual).
constexpr double kMaxUnthresholdedChange = 0.15;

// Applies the threshold to readings already zeroed (and corrected, where asked).
void threshold(std::span<const double> readings, double threshold_bits, std::span<double> out) {
  for (std::size_t i = 0; i < readings.size(); ++i) {
    out[i] = readings[i] < threshold_bits ? 0.0 : readings[i];
  }
}

// measure_frame from the zeroed readings before the threshold.
std::array<RegionSample, kRegionCount> measure_readings(
    std::span<const double> readings, double threshold_bits, const InsoleLayout& layout,
    const Calibration& calibration, bool first_instant, ContactEllipseCache* cache,
    FrameScratch& scratch) {
  const std::size_t sensors = layout.sensor_count();
  const double sensor_area_mm2 = layout.geometry().area_mm2();
  const double newtons_per_bit = calibration.newtons_per_bit(sensor_area_mm2);
  const CellSize cell{layout.geometry().width_mm, layout.geometry().height_mm};
  scratch.zeroed.resize(sensors);
  scratch.cells.reserve(sensors);
  scratch.loaded.reserve(sensors);
  threshold(readings, threshold_bits, scratch.zeroed);
  std::array<RegionSample, kRegionCount> samples{};
  for (Region region : kRegions) {
    RegionSample& sample = samples[index_of(region)];
    double bits = 0.0;
    scratch.cells.clear();
    scratch.loaded.clear();
    scratch.unloaded.clear();
    for (std::size_t i : layout.region_sensors(region)) {
      const Sensor& s = layout.sensor(i);
      if (scratch.zeroed[i] <= 0.0) {
        scratch.unloaded.push_back({s.grid_x_mm, s.grid_y_mm});
        continue;
      }
      bits += scratch.zeroed[i];
      scratch.cells.push_back({s.grid_x_mm, s.grid_y_mm, s.row == layout.outermost_heel_row()});
      scratch.loaded.push_back({s.grid_x_mm, s.grid_y_mm, scratch.zeroed[i]});
    }
    sample.force_n = bits * newtons_per_bit;
    sample.active_sensors = static_cast<int>(scratch.cells.size());
    sample.sensor_area_mm2 = static_cast<double>(scratch.cells.size()) * sensor_area_mm2;
    sample.ellipse = cache != nullptr
                         ? cache->fit(scratch.cells, cell, region, first_instant)
                         : fit_contact_ellipse(scratch.cells, cell, region, first_instant);
    sample.free_footprint = free_footprint(scratch.loaded, cell, scratch.unloaded);
    sample.footprint_area_mm2 =
        sample.free_footprint
            ? std::optional<double>(sample.free_footprint->area_mm2)
            : footprint_area_at_aspect_mm2(scratch.loaded, cell, layout.region_box_aspect(region),
                                           scratch.unloaded);
  }
  return samples;
}

}  // namespace

std::array<RegionSample, kRegionCount> measure_frame(
    std::span<const std::uint8_t> raw, std::span<const double> zero, double threshold_bits,
    const InsoleLayout& layout, const Calibration& calibration, bool first_instant,
    ContactEllipseCache* cache, FrameScratch& scratch) {
  const std::size_t sensors = layout.sensor_count();
  if (raw.size() != sensors || zero.size() != sensors) {
    throw std::invalid_argument("measure_frame: a frame of " + std::to_string(raw.size()) +
                                " sensors with a zero of " + std::to_string(zero.size()) +
                                ", the layout has " + std::to_string(sensors));
  }
  scratch.readings.resize(sensors);
  for (std::size_t i = 0; i < sensors; ++i) {
    scratch.readings[i] = static_cast<double>(raw[i]) - zero[i];
  }
  return measure_readings(scratch.readings, threshold_bits, layout, calibration, first_instant,
                          cache, scratch);
}

namespace {

/// RegionSample::spill_in_n of every region: `measured` the zeroed readings as read, `corrected`
/// the same with the crosstalk undone.
void spill_in(std::span<const double> measured, std::span<const double> corrected,
              double threshold_bits, const InsoleLayout& layout, double newtons_per_bit,
              double coupling, std::array<RegionSample, kRegionCount>& samples) {
  for (Region region : kRegions) {
    double bits = 0.0;
    for (std::size_t i : layout.region_sensors(region)) {
      if (measured[i] < threshold_bits || !(measured[i] > 0.0)) continue;  // as measure_readings
      for (const Neighbour& nb : layout.neighbours(i)) {
        if (layout.sensor(nb.sensor).region != region)
          bits += nb.shared_edge * corrected[nb.sensor];
      }
    }
    samples[index_of(region)].spill_in_n = coupling * bits * newtons_per_bit;
  }
}

/// Fits every frame's footprint of each region again, from its zeroed readings before the
/// threshold: at the aspect the stance's free fits share (the region's box where none has one),
/// and then over the cells under the threshold too; and, where asked, the footprint of averaging
/// cells at that aspect.
void refit_footprints(std::span<const std::vector<double>> readings, double threshold_bits,
                      const InsoleLayout& layout, StanceSeries& series, FrameScratch& scratch,
                      CellMeanFootprint cell_mean) {
  const CellSize cell{layout.geometry().width_mm, layout.geometry().height_mm};
  std::array<double, kRegionCount> aspect{};
  std::vector<Footprint> fits;
  for (Region region : kRegions) {
    fits.clear();
    for (const auto& frame : series.frames) {
      if (const auto& f = frame[index_of(region)].free_footprint) fits.push_back(*f);
    }
    aspect[index_of(region)] = shared_aspect(fits).value_or(layout.region_box_aspect(region));
  }
  for (std::size_t f = 0; f < series.size(); ++f) {
    const std::vector<double>& frame = readings[f];
    threshold(frame, threshold_bits, scratch.zeroed);
    for (Region region : kRegions) {
      RegionSample& sample = series.frames[f][index_of(region)];
      if (sample.active_sensors == 0) continue;
      scratch.loaded.clear();
      scratch.unloaded.clear();
      scratch.region.clear();
      for (std::size_t i : layout.region_sensors(region)) {
        const Sensor& s = layout.sensor(i);
        if (scratch.zeroed[i] <= 0.0) {
          scratch.unloaded.push_back({s.grid_x_mm, s.grid_y_mm});
        } else {
          scratch.loaded.push_back({s.grid_x_mm, s.grid_y_mm, scratch.zeroed[i]});
        }
        scratch.region.push_back({s.grid_x_mm, s.grid_y_mm, frame[i]});
      }
      const double a = aspect[index_of(region)];
      if (cell_mean == CellMeanFootprint::Fit) {
        sample.footprint_cell_mean_area_mm2 =
            footprint_area_cell_mean_mm2(scratch.region, cell, a, threshold_bits);
      }
      const auto thresholded =
          footprint_area_at_aspect_mm2(scratch.loaded, cell, a, scratch.unloaded);
      const auto unthresholded =
          thresholded ? footprint_area_unthresholded_mm2(scratch.region, cell, a, threshold_bits)
                      : std::nullopt;
      if (!unthresholded) {
        sample.footprint_area_mm2 = thresholded;
      } else if (std::abs(*unthresholded / *thresholded - 1.0) <= kMaxUnthresholdedChange) {
        sample.footprint_area_mm2 = unthresholded;
      } else {
        sample.footprint_area_mm2.reset();
      }
    }
  }
}

}  // namespace

StanceSeries measure_stance(const Step& step, const InsoleLayout& layout,
                            const Calibration& calibration, ContactEllipseCache* cache,
                            CellMeanFootprint cell_mean, const CrosstalkCorrection* crosstalk) {
  const std::size_t sensors = layout.sensor_count();
  if (step.sensor_zero_bits.size() != sensors) {
    throw std::invalid_argument("measure_stance: the step's zero has " +
                                std::to_string(step.sensor_zero_bits.size()) +
                                " sensors, the layout " + std::to_string(sensors));
  }
  StanceSeries series;
  series.t_s.reserve(step.stance.size());
  series.frames.reserve(step.stance.size());
  series.total_force_n.reserve(step.stance.size());
  FrameScratch scratch;
  std::vector<std::vector<double>> readings(step.stance.size());
  std::vector<std::vector<double>> measured(crosstalk != nullptr ? step.stance.size() : 0);
  const double newtons_per_bit = calibration.newtons_per_bit(layout.geometry().area_mm2());
  double corrected_max_summed = 0.0;
  for (std::size_t f = 0; f < step.stance.size(); ++f) {
    const Frame& frame = step.stance[f];
    if (frame.bits.size() != sensors) {
      throw std::invalid_argument("measure_stance: a frame has " +
                                  std::to_string(frame.bits.size()) + " sensors, the layout " +
                                  std::to_string(sensors));
    }
    std::vector<double>& r = readings[f];
    r.resize(sensors);
    for (std::size_t i = 0; i < sensors; ++i) {
      r[i] = static_cast<double>(frame.bits[i]) - step.sensor_zero_bits[i];
    }
    if (crosstalk != nullptr) {
      measured[f] = r;
      crosstalk->undo(r);
      const double summed = std::accumulate(r.begin(), r.end(), 0.0);
      corrected_max_summed = f == 0 ? summed : std::max(corrected_max_summed, summed);
    }
  }
  // The adaptive threshold is a share of the step's highest summed reading, which mixing raised
  // by up to 4 k: the corrected readings take the same share of their own, as the segmenter
  // would have set it for the insole without crosstalk. (Held at the mixed readings' threshold,
  // the corrected footprints lost their rim and came out smaller and more scattered than the
  // same session's without crosstalk: heel area RMS 98 mm^2 off it at size 37-38, 83 uncorrected.)
  // The noise floor under it stays as the raw readings gave it: undoing the mixing amplifies the
  // noise by 1.2-1.3 % RMS at k = 0.05, 5.2-5.7 % at 0.1 (README, Crosstalk).
  const double threshold_bits =
      crosstalk != nullptr && step.max_summed_bits > 0.0
          ? std::max(step.threshold_floor_bits, step.adaptive_threshold_bits *
                                                    std::max(0.0, corrected_max_summed) /
                                                    step.max_summed_bits)
          : step.adaptive_threshold_bits;
  for (std::size_t f = 0; f < step.stance.size(); ++f) {
    auto samples =
        measure_readings(readings[f], threshold_bits, layout, calibration, f == 0, cache, scratch);
    if (crosstalk != nullptr) {
      spill_in(measured[f], readings[f], step.adaptive_threshold_bits, layout, newtons_per_bit,
               crosstalk->coupling(), samples);
    }
    double total = 0.0;
    for (const RegionSample& sample : samples) total += sample.force_n;
    series.t_s.push_back(step.stance[f].t_s);
    series.frames.push_back(samples);
    series.total_force_n.push_back(total);
  }
  refit_footprints(readings, threshold_bits, layout, series, scratch, cell_mean);
  return series;
}

CellReadingFits& CellReadingFits::operator+=(const CellReadingFits& other) {
  frames += other.frames;
  mean_better += other.mean_better;
  cells += other.cells;
  centre_residual_ss += other.centre_residual_ss;
  mean_residual_ss += other.mean_residual_ss;
  return *this;
}

std::optional<CellReading> CellReadingFits::favoured() const {
  // A reading that is the insole's own fits every large footprint closely and the other only
  // where noise hides the rim; a split says neither fits (a pressure that is no cap).
  constexpr int kMinFrames = 10;
  if (frames < kMinFrames) return std::nullopt;
  if (4 * mean_better >= 3 * frames && mean_residual_ss < centre_residual_ss) {
    return CellReading::Mean;
  }
  if (4 * (frames - mean_better) >= 3 * frames && centre_residual_ss < mean_residual_ss) {
    return CellReading::Centre;
  }
  return std::nullopt;
}

CellReadingEvidence& CellReadingEvidence::operator+=(const CellReadingEvidence& other) {
  for (std::size_t k = 0; k < at_coupling.size(); ++k) at_coupling[k] += other.at_coupling[k];
  return *this;
}

namespace {

// The better reading's residual per cell at one coupling; infinite without frames, as a
// coupling whose fits failed says nothing.
double best_residual_per_cell(const CellReadingFits& f) {
  if (f.cells == 0) return std::numeric_limits<double>::infinity();
  return std::min(f.centre_residual_ss, f.mean_residual_ss) / f.cells;
}

}  // namespace

std::size_t CellReadingEvidence::best_index() const {
  std::size_t best = 0;
  for (std::size_t k = 1; k < at_coupling.size(); ++k) {
    if (best_residual_per_cell(at_coupling[k]) < best_residual_per_cell(at_coupling[best])) {
      best = k;
    }
  }
  // A cap is no foot: where neither reading fits down to the noise, undoing a little crosstalk
  // takes up some of the misfit too, and the coupling must earn its place.
  const double as_read = best_residual_per_cell(at_coupling[0]);
  const double ratio = kMaxResidualRatioWithCoupling * kMaxResidualRatioWithCoupling;
  if (std::isfinite(as_read) && best_residual_per_cell(at_coupling[best]) > ratio * as_read) {
    return 0;
  }
  return best;
}

double CellReadingEvidence::coupling() const {
  const std::size_t k = best_index();
  if (at_coupling[k].cells == 0) return 0.0;
  if (k == 0 || k + 1 == at_coupling.size()) return kCouplings[k];
  // The residual is quadratic in the coupling near its least, as the readings are linear in it.
  const bool mean = at_coupling[k].mean_residual_ss < at_coupling[k].centre_residual_ss;
  const auto residual = [&](std::size_t i) {
    const CellReadingFits& f = at_coupling[i];
    if (f.cells == 0) return std::numeric_limits<double>::quiet_NaN();
    return (mean ? f.mean_residual_ss : f.centre_residual_ss) / f.cells;
  };
  const double lo = residual(k - 1);
  const double mid = residual(k);
  const double hi = residual(k + 1);
  const double curvature = lo - 2.0 * mid + hi;
  if (!std::isfinite(curvature) || !(curvature > 0.0)) return kCouplings[k];
  const double step = kCouplings[k + 1] - kCouplings[k];
  return kCouplings[k] + 0.5 * step * (lo - hi) / curvature;
}

namespace {

// One step's evidence with the readings' crosstalk undone at each of `corrections` (one per
// CellReadingEvidence::kCouplings). A region's frame is the one of the largest summed reading
// as read: undoing a coupling moves a little of its load onto its cells from around them and
// does not change which frame carries the most. Regions share few such frames, and undoing one
// is a solve over every cell, so each is undone once per coupling.
CellReadingEvidence step_cell_reading_evidence(const Step& step, const InsoleLayout& layout,
                                               std::span<const CrosstalkCorrection> corrections) {
  const std::size_t sensors = layout.sensor_count();
  if (step.sensor_zero_bits.size() != sensors) {
    throw std::invalid_argument("cell_reading_evidence: the step's zero has " +
                                std::to_string(step.sensor_zero_bits.size()) +
                                " sensors, the layout " + std::to_string(sensors));
  }
  const CellSize cell{layout.geometry().width_mm, layout.geometry().height_mm};
  const double threshold_bits = step.adaptive_threshold_bits;
  const auto zeroed = [&](const Frame& frame, std::size_t i) {
    return static_cast<double>(frame.bits[i]) - step.sensor_zero_bits[i];
  };
  for (const Frame& frame : step.stance) {
    if (frame.bits.size() != sensors) {
      throw std::invalid_argument("cell_reading_evidence: a frame has " +
                                  std::to_string(frame.bits.size()) + " sensors, the layout " +
                                  std::to_string(sensors));
    }
  }
  // Per region, its peak frame's place among the distinct peak frames; -1 without one.
  std::array<int, kRegionCount> peak_of{};
  std::vector<const Frame*> peaks;
  for (Region region : kRegions) {
    const auto& members = layout.region_sensors(region);
    const Frame* peak = nullptr;
    double peak_bits = 0.0;
    for (const Frame& frame : step.stance) {
      double bits = 0.0;
      int active = 0;
      for (std::size_t i : members) {
        const double r = zeroed(frame, i);
        if (r >= threshold_bits && r > 0.0) {
          bits += r;
          ++active;
        }
      }
      if (active >= CellReadingEvidence::kMinEvidenceCells && bits > peak_bits) {
        peak = &frame;
        peak_bits = bits;
      }
    }
    const auto found = std::find(peaks.begin(), peaks.end(), peak);
    peak_of[index_of(region)] = peak == nullptr ? -1 : static_cast<int>(found - peaks.begin());
    if (peak != nullptr && found == peaks.end()) peaks.push_back(peak);
  }
  CellReadingEvidence evidence;
  std::vector<std::vector<double>> readings(peaks.size(), std::vector<double>(sensors));
  std::vector<LoadedCell> all;
  std::vector<LoadedCell> loaded;
  std::vector<CellCentre> unloaded;
  for (std::size_t k = 0; k < corrections.size(); ++k) {
    for (std::size_t p = 0; p < peaks.size(); ++p) {
      for (std::size_t i = 0; i < sensors; ++i) readings[p][i] = zeroed(*peaks[p], i);
      corrections[k].undo(readings[p]);
    }
    for (Region region : kRegions) {
      const int p = peak_of[index_of(region)];
      if (p < 0) continue;
      all.clear();
      loaded.clear();
      unloaded.clear();
      for (std::size_t i : layout.region_sensors(region)) {
        const Sensor& s = layout.sensor(i);
        const double r = readings[static_cast<std::size_t>(p)][i];
        all.push_back({s.grid_x_mm, s.grid_y_mm, r});
        if (r >= threshold_bits && r > 0.0) {
          loaded.push_back({s.grid_x_mm, s.grid_y_mm, r});
        } else {
          unloaded.push_back({s.grid_x_mm, s.grid_y_mm});
        }
      }
      const auto free = free_footprint(loaded, cell, unloaded);
      const double aspect = free ? free->aspect : layout.region_box_aspect(region);
      const auto centre = fit_cell_cap(all, cell, aspect, threshold_bits, CellReading::Centre);
      const auto mean = fit_cell_cap(all, cell, aspect, threshold_bits, CellReading::Mean);
      if (!centre || !mean) continue;
      CellReadingFits& fits = evidence.at_coupling[k];
      ++fits.frames;
      fits.mean_better += mean->residual_ss < centre->residual_ss ? 1 : 0;
      fits.cells += mean->cells;
      fits.centre_residual_ss += centre->residual_ss;
      fits.mean_residual_ss += mean->residual_ss;
    }
  }
  return evidence;
}

std::vector<CrosstalkCorrection> evidence_corrections(const InsoleLayout& layout) {
  std::vector<CrosstalkCorrection> corrections;
  corrections.reserve(CellReadingEvidence::kCouplings.size());
  for (double k : CellReadingEvidence::kCouplings) corrections.emplace_back(layout, k);
  return corrections;
}

}  // namespace

CellReadingEvidence cell_reading_evidence(const Step& step, const InsoleLayout& layout) {
  return step_cell_reading_evidence(step, layout, evidence_corrections(layout));
}

CellReadingEvidence cell_reading_evidence(std::span<const Step> steps, const InsoleLayout& layout) {
  const std::vector<CrosstalkCorrection> corrections = evidence_corrections(layout);
  const std::size_t weighed = std::min(steps.size(), CellReadingEvidence::kMaxSteps);
  std::vector<CellReadingEvidence> per_step(weighed);
  detail::parallel_for(weighed, [&](std::size_t j) {
    per_step[j] =
        step_cell_reading_evidence(steps[j * steps.size() / weighed], layout, corrections);
  });
  CellReadingEvidence sum;
  for (const CellReadingEvidence& e : per_step) sum += e;
  return sum;
}

}  // namespace gaitmon
