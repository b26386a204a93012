// Loads config/gaitmon.toml and the two files it names, refusing anything gaitmon does not know.
#include "gaitmon/config.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <toml++/toml.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <map>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <string_view>
#include <tuple>
#include <utility>
#include <vector>

#include "gaitmon/analysis.hpp"
#include "gaitmon/discrepancy.hpp"
#include "gaitmon/error.hpp"
#include "gaitmon/pooling.hpp"
#include "toml_reader.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;
using detail::at_line;
using detail::expected;
using detail::fail_element;
using detail::integer_in;
using detail::number_above;
using detail::number_at_least;
using detail::number_in;
using detail::parse_document;
using detail::TableReader;

// Tables keyed by size or region names: a name gaitmon does not know is reported as such
// rather than as a generic unknown key, with the names it does know.
template <typename Parse>
void refuse_unknown_names(const TableReader& table, Parse parse, std::string_view known) {
  for (const std::string& key : table.keys()) {
    if (!parse(key)) table.fail(key, fmt::format("unknown name; expected one of {}", known));
  }
}

std::string joined_size_names() {
  std::string out;
  for (InsoleSize size : kInsoleSizes)
    out += (out.empty() ? "" : ", ") + std::string(insole_size_name(size));
  return out;
}

std::string joined_region_names() {
  std::string out;
  for (Region region : kRegions)
    out += (out.empty() ? "" : ", ") + std::string(region_name(region));
  return out;
}

// The [sizes] table of a per-size data file, which may name insole sizes only.
TableReader sizes_table(TableReader& root) {
  TableReader sizes = root.table("sizes");
  refuse_unknown_names(
      sizes, [](std::string_view name) { return parse_insole_size(name).has_value(); },
      joined_size_names());
  return sizes;
}

// An insole is about 100 mm wide with up to 9 cells a row: a cell or a spacing beyond 50 mm is
// a typo, and would only fail later, in the geometry, without naming the key.
double at_most_a_cell(TableReader& table, std::string_view key, double value) {
  constexpr double kMaxMm = 50.0;
  if (value > kMaxMm) table.fail(key, fmt::format("must be <= {} mm, got {}", kMaxMm, value));
  return value;
}

void read_sensor(TableReader table, SensorGeometry& sensor) {
  sensor.width_mm = at_most_a_cell(table, "width_mm", number_above(table, "width_mm", 0.0));
  sensor.height_mm = at_most_a_cell(table, "height_mm", number_above(table, "height_mm", 0.0));
  // Overlapping cells would count the same patch of sole twice.
  sensor.pitch_x_mm =
      at_most_a_cell(table, "pitch_x_mm", number_at_least(table, "pitch_x_mm", sensor.width_mm));
  sensor.pitch_y_mm =
      at_most_a_cell(table, "pitch_y_mm", number_at_least(table, "pitch_y_mm", sensor.height_mm));
  const std::string alignment = table.string("row_alignment");
  if (alignment == "centred") {
    sensor.alignment = RowAlignment::Centred;
  } else if (alignment == "lateral") {
    sensor.alignment = RowAlignment::Lateral;
  } else if (alignment == "medial") {
    sensor.alignment = RowAlignment::Medial;
  } else {
    table.fail("row_alignment",
               fmt::format(R"(must be "centred", "lateral" or "medial", got "{}")", alignment));
  }
  table.finish();
}

void read_calibration(TableReader table, Calibration& calibration) {
  calibration.full_scale_bits = number_above(table, "full_scale_bits", 0.0);
  calibration.full_scale_n_per_cm2 = number_above(table, "full_scale_n_per_cm2", 0.0);
  table.finish();
}

// The ranges the discrepancy workflow fits the creep in, which measures it (README, "Sensor creep
// undone in the readings").
void read_sensor_creep(TableReader table, SensorCreepSettings& creep) {
  creep.gain = number_in(table, "gain", 0.0, 2.0);
  creep.tau_s = number_in(table, "tau_s", 0.02, 60.0);
  table.finish();
}

void read_segmentation(TableReader table, double sample_rate_hz,
                       SegmentationSettings& segmentation) {
  // The largest summed reading the biggest insole can give: 255 bits on each of 161 sensors.
  constexpr int kMaxSummedBits = 255 * 161;
  segmentation.event_threshold_bits = integer_in(table, "event_threshold_bits", 1, kMaxSummedBits);
  segmentation.debounce_frames = integer_in(table, "debounce_frames", 1, 100);
  segmentation.swing_window_frames = integer_in(table, "swing_window_frames", 1, 100);
  segmentation.threshold_noise_sds = number_at_least(table, "threshold_noise_sds", 0.0);
  if (segmentation.threshold_noise_sds > 20.0) {
    table.fail("threshold_noise_sds",
               fmt::format("must be <= 20, got {}", segmentation.threshold_noise_sds));
  }
  // Frame intervals jitter around one sample period (0.0099-0.0100 s in the real recordings at
  // 100 Hz): a limit within half a period of it would cut a steady stream.
  segmentation.max_gap_s = number_above(table, "max_gap_s", 1.5 / sample_rate_hz);
  table.finish();
}

// A positive whole number written in digits only; INT_MAX if too long, so range checks catch it.
std::optional<int> parse_count(std::string_view text) {
  if (text.empty() ||
      !std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; })) {
    return std::nullopt;
  }
  int value = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec == std::errc::result_out_of_range) return INT_MAX;
  if (ec != std::errc() || end != text.data() + text.size()) return std::nullopt;
  return value;
}

// "row:first-last" or "row:n".
std::optional<RowSpan> parse_span(std::string_view text) {
  const auto colon = text.find(':');
  if (colon == std::string_view::npos) return std::nullopt;
  const auto row = parse_count(text.substr(0, colon));
  const std::string_view sensors = text.substr(colon + 1);
  const auto dash = sensors.find('-');
  const auto first = parse_count(sensors.substr(0, dash));
  const auto last = dash == std::string_view::npos ? first : parse_count(sensors.substr(dash + 1));
  if (!row || !first || !last) return std::nullopt;
  return RowSpan{*row, *first, *last};
}

std::string span_problem(const RowSpan& span) {
  if (span.row < 1) return fmt::format("row must be >= 1, got {}", span.row);
  if (span.row > kMaxInsoleRows) {
    return fmt::format("row must be <= {}, got {}", kMaxInsoleRows, span.row);
  }
  if (span.first < 1) return fmt::format("first sensor must be >= 1, got {}", span.first);
  if (span.first > span.last) {
    return fmt::format("first sensor {} is after last sensor {}", span.first, span.last);
  }
  if (span.last > kMaxSensorsPerRow) {
    return fmt::format("sensor numbers must be <= {}, got {}", kMaxSensorsPerRow, span.last);
  }
  return {};
}

// Region spans of one size, checked so that InsoleLayout's invariant holds: every sensor of
// rows 1..N in exactly one region, every region non-empty.
void read_regions(TableReader table, InsoleSpec& spec) {
  refuse_unknown_names(
      table, [](std::string_view name) { return parse_region(name).has_value(); },
      joined_region_names());
  std::map<std::pair<int, int>, Region> owner;  // (row, number) -> region
  for (Region region : kRegions) {
    const std::string name(region_name(region));
    const toml::array& list = table.array(name);
    if (list.empty()) table.fail(name, "lists no sensors; every region needs at least one");
    auto& spans = spec.regions[index_of(region)];
    spans.clear();
    for (std::size_t i = 0; i < list.size(); ++i) {
      const toml::node& element = *list.get(i);
      const std::string key = fmt::format("{}[{}]", table.key_path(name), i);
      const auto* text = element.as_string();
      if (text == nullptr) {
        fail_element(table.file(), key, element,
                     expected(R"(a string "row:first-last" or "row:n")", element));
      }
      const std::optional<RowSpan> span = parse_span(text->get());
      if (!span) {
        fail_element(table.file(), key, element,
                     fmt::format(R"(malformed span "{}"; expected "row:first-last" or "row:n")",
                                 text->get()));
      }
      if (const std::string problem = span_problem(*span); !problem.empty()) {
        fail_element(table.file(), key, element, problem);
      }
      for (int number = span->first; number <= span->last; ++number) {
        const auto [it, fresh] = owner.try_emplace({span->row, number}, region);
        if (fresh) continue;
        if (it->second == region) {
          fail_element(
              table.file(), key, element,
              fmt::format("row {} sensor {} is listed twice in {}", span->row, number, name));
        }
        fail_element(table.file(), key, element,
                     fmt::format("row {} sensor {} is in both {} and {}", span->row, number,
                                 region_name(it->second), name));
      }
      spans.push_back(*span);
    }
  }
  std::map<int, int> row_length;
  for (const auto& [cell, region] : owner) {
    row_length[cell.first] = std::max(row_length[cell.first], cell.second);
  }
  const int last_row = row_length.rbegin()->first;
  for (int row = 1; row <= last_row; ++row) {
    const auto found = row_length.find(row);
    if (found == row_length.end()) {
      table.fail_here(fmt::format(
          "row {} has no sensors but row {} does; rows are numbered from 1 without gaps", row,
          last_row));
    }
    for (int number = 1; number <= found->second; ++number) {
      if (!owner.contains({row, number})) {
        table.fail_here(
            fmt::format("row {} sensor {} is in no region (the row has sensors up to {})", row,
                        number, found->second));
      }
    }
  }
  // Sessions and devices carry a fixed count per size: a layout of another count would accept
  // the file and then reject every frame of it.
  const std::size_t expected = session_sensor_count(spec.size);
  if (owner.size() != expected) {
    table.fail_here(
        fmt::format("the regions hold {} sensors; insole size {} has {} (the session "
                    "format's count, shared/docs/session-format.md)",
                    owner.size(), insole_size_name(spec.size), expected));
  }
  table.finish();
}

void read_insoles(const fs::path& path, const std::string& main_file, Config& config) {
  const toml::table doc = parse_document(path, main_file, "insoles_file");
  TableReader root(doc, path.string(), "");
  TableReader sizes = sizes_table(root);
  for (InsoleSize size : kInsoleSizes) {
    TableReader entry = sizes.table(insole_size_name(size));
    InsoleSpec& spec = config.insoles[index_of(size)];
    spec.size = size;
    spec.adaptive_threshold_pct = number_above(entry, "adaptive_threshold_pct", 0.0);
    if (spec.adaptive_threshold_pct > 100.0) {
      entry.fail("adaptive_threshold_pct",
                 fmt::format("must be <= 100, got {}", spec.adaptive_threshold_pct));
    }
    read_regions(entry.table("regions"), spec);
    entry.finish();
  }
  sizes.finish();
  root.finish();
}

// One { lower = ..., upper = ... } pair: both positive (the fit works in log scale for most
// parameters) and lower < upper.
Bounds read_bounds(TableReader& fit, std::string_view key) {
  TableReader table = fit.table(key);
  Bounds bounds;
  bounds.lower = number_above(table, "lower", 0.0);
  bounds.upper = table.number("upper");
  if (!(bounds.upper > bounds.lower)) {
    table.fail("upper", fmt::format("must be > lower ({}), got {}", bounds.lower, bounds.upper));
  }
  table.finish();
  return bounds;
}

void read_fit(TableReader table, FitBounds& fit) {
  fit.A_mm = read_bounds(table, "A_mm");
  fit.B_mm = read_bounds(table, "B_mm");
  fit.C_mm = read_bounds(table, "C_mm");
  fit.d0_mm = read_bounds(table, "d0_mm");
  fit.kbar_n_per_mm3 = read_bounds(table, "kbar_n_per_mm3");
  fit.n = read_bounds(table, "n");
  fit.cbar_ns_per_mm3 = read_bounds(table, "cbar_ns_per_mm3");
  fit.m = read_bounds(table, "m");
  table.finish();
}

// One { mean = ..., sd = ... } pair; every Appendix I quantity is positive on average.
std::pair<double, double> read_stat(TableReader& region, std::string_view key) {
  TableReader stat = region.table(key);
  const double mean = number_above(stat, "mean", 0.0);
  const double sd = number_at_least(stat, "sd", 0.0);
  stat.finish();
  return {mean, sd};
}

void read_tissue_region(TableReader table, SeedTissueStats& stats) {
  const auto read = [&](std::string_view key, double& mean, double& sd) {
    std::tie(mean, sd) = read_stat(table, key);
  };
  read("d0_mm", stats.mean.d0_mm, stats.sd.d0_mm);
  read("A_mm", stats.mean.A_mm, stats.sd.A_mm);
  read("B_mm", stats.mean.B_mm, stats.sd.B_mm);
  read("C_mm", stats.mean.C_mm, stats.sd.C_mm);
  read("kbar_n_per_mm3", stats.mean.kbar_n_per_mm3, stats.sd.kbar_n_per_mm3);
  read("cbar_ns_per_mm3", stats.mean.cbar_ns_per_mm3, stats.sd.cbar_ns_per_mm3);
  read("n", stats.mean.n, stats.sd.n);
  read("m", stats.mean.m, stats.sd.m);
  read("nrmse_pct", stats.nrmse_pct_mean, stats.nrmse_pct_sd);
  table.finish();
}

void read_tissue(const fs::path& path, const std::string& main_file, Config& config) {
  const toml::table doc = parse_document(path, main_file, "tissue_file");
  TableReader root(doc, path.string(), "");
  TableReader sizes = sizes_table(root);
  for (InsoleSize size : kInsoleSizes) {
    TableReader entry = sizes.table(insole_size_name(size));
    refuse_unknown_names(
        entry, [](std::string_view name) { return parse_region(name).has_value(); },
        joined_region_names());
    for (Region region : kRegions) {
      read_tissue_region(entry.table(region_name(region)),
                         config.seed_tissue[index_of(size)][index_of(region)]);
    }
    entry.finish();
  }
  sizes.finish();
  root.finish();
}

bool read_boolean(TableReader& table, std::string_view key) {
  const toml::node& n = table.node(key);
  const auto* b = n.as_boolean();
  if (b == nullptr) table.fail(key, expected("a boolean", n));
  return b->get();
}

// [lcm]. The URL's provider is checked here so that a typo fails at load with the key; whether
// LCM accepts the rest of it is known only when the publisher opens it.
std::string read_channel(TableReader& table, std::string_view key) {
  // LCM_MAX_CHANNEL_NAME_LENGTH in lcm/lcm.h; LCM would refuse longer names on every publish.
  constexpr std::size_t kMaxChannelLength = 63;
  std::string name = table.string(key);
  if (name.empty()) table.fail(key, "must name a channel");
  if (name.size() > kMaxChannelLength) {
    table.fail(
        key, fmt::format("must be at most {} characters, got {}", kMaxChannelLength, name.size()));
  }
  if (std::any_of(name.begin(), name.end(),
                  [](char c) { return std::isgraph(static_cast<unsigned char>(c)) == 0; })) {
    table.fail(key, fmt::format("\"{}\" contains a space or a control character", name));
  }
  return name;
}

void read_lcm(TableReader table, LcmSettings& lcm) {
  lcm.url = table.string("url");
  const auto scheme_end = lcm.url.find("://");
  const std::string provider =
      scheme_end == std::string::npos ? std::string() : lcm.url.substr(0, scheme_end);
  static const std::set<std::string, std::less<>> kProviders{"udpm", "mpudpm", "memq", "file",
                                                             "tcpq"};
  if (!kProviders.contains(provider)) {
    table.fail("url", fmt::format("\"{}\" is not PROVIDER://...; providers are udpm, mpudpm, "
                                  "memq, file and tcpq",
                                  lcm.url));
  }
  lcm.raw_enabled = read_boolean(table, "raw_enabled");
  TableReader channels = table.table("channels");
  std::map<std::string, std::string> used;  // channel -> key
  for (auto [key, name] : {std::pair<std::string_view, std::string*>{"frame", &lcm.channels.frame},
                           {"step", &lcm.channels.step},
                           {"fit", &lcm.channels.fit},
                           {"status", &lcm.channels.status},
                           {"raw", &lcm.channels.raw},
                           {"effects", &lcm.channels.effects},
                           {"tissue", &lcm.channels.tissue}}) {
    *name = read_channel(channels, key);
    const auto [it, fresh] = used.try_emplace(*name, std::string(key));
    if (!fresh) {
      channels.fail(key, fmt::format("\"{}\" is also the {} channel; each message type needs its "
                                     "own channel",
                                     *name, it->second));
    }
  }
  channels.finish();
  table.finish();
}

fs::path named_file(TableReader& root, std::string_view key, const fs::path& main_file) {
  const std::string name = root.string(key);
  if (name.empty()) root.fail(key, "must name a file");
  return main_file.parent_path() / name;
}

void read_model(TableReader table, const std::string& file, ModelSettings& model) {
  const toml::array& effects = table.array("effects");
  for (std::size_t i = 0; i < effects.size(); ++i) {
    const std::string key = fmt::format("model.effects[{}]", i);
    const auto* name = effects[i].as_string();
    if (name == nullptr) fail_element(file, key, effects[i], "must be a string");
    try {
      check_discrepancy_effect(name->get());
    } catch (const std::invalid_argument& e) {
      fail_element(file, key, effects[i], e.what());
    }
    if (std::find(model.effects.begin(), model.effects.end(), name->get()) != model.effects.end()) {
      fail_element(file, key, effects[i], fmt::format("'{}' is listed twice", name->get()));
    }
    model.effects.push_back(name->get());
  }
  // The extended model's k-fold needs at least one step per fold.
  model.effects_window_steps =
      integer_in(table, "effects_window_steps", DiscrepancySettings{}.folds, 100000);
  model.m_per_session = read_boolean(table, "m_per_session");
  model.area = table.string("area");
  if (model.area != "auto" && !parse_area_source(model.area)) {
    table.fail(
        "area",
        fmt::format(R"(must be "auto", "footprint", "footprint-mean" or "ellipse", got "{}")",
                    model.area));
  }
  // The first running m needs this many steps; a window holds at least as many.
  model.m_window_steps = integer_in(table, "m_window_steps", kFirstSharedMSteps, 100000);
  if (model.m_per_session && !model.effects.empty()) {
    table.fail("m_per_session",
               "cannot be true with [model] effects: each step's tissue is fitted again with the "
               "effects inside, at its own m (as analyze refuses --m-per-session with effects)");
  }
  table.finish();
}

// A table of one number per region, each in [0, max].
void read_per_region(TableReader regions, std::array<double, kRegionCount>& values, double max) {
  refuse_unknown_names(
      regions, [](std::string_view name) { return parse_region(name).has_value(); },
      joined_region_names());
  for (Region region : kRegions) {
    const std::string name(region_name(region));
    const double value = regions.number(name);
    if (!(value >= 0.0 && value <= max)) {
      regions.fail(name, fmt::format("must be in [0, {}], got {}", max, value));
    }
    values[index_of(region)] = value;
  }
  regions.finish();
}

// The pair SDs' own keys of `table`; the caller finishes it.
void read_pair_sds(TableReader& table, PairSds& sds) {
  read_per_region(table.table("kbar_pair_sd_pct"), sds.kbar_pair_sd_pct, 100.0);
  read_per_region(table.table("cbar_pair_sd_pct"), sds.cbar_pair_sd_pct, 100.0);
}

// A table's own pair SDs and its m_per_session table's; the caller finishes it.
void read_asymmetry_tables(TableReader& table, AsymmetrySettings& asymmetry) {
  read_pair_sds(table, asymmetry.per_step);
  TableReader shared = table.table("m_per_session");
  read_pair_sds(shared, asymmetry.m_per_session);
  shared.finish();
}

void read_asymmetry(TableReader table, AsymmetrySettings& asymmetry,
                    AsymmetrySettings& footprint_mean) {
  read_asymmetry_tables(table, asymmetry);
  TableReader mean = table.table("footprint_mean");
  read_asymmetry_tables(mean, footprint_mean);
  mean.finish();
  table.finish();
}

// The chain SDs' own keys of `table`; the caller finishes it.
void read_chain_sds(TableReader& table, ChainSds& sds) {
  read_per_region(table.table("kbar_chain_sd_pct"), sds.kbar_chain_sd_pct, 1000.0);
  read_per_region(table.table("n_chain_sd"), sds.n_chain_sd, 1.0);
  read_per_region(table.table("cbar_chain_sd_pct"), sds.cbar_chain_sd_pct, 1000.0);
  read_per_region(table.table("m_chain_sd"), sds.m_chain_sd, 1.0);
  read_per_region(table.table("kbar_step_sd_pct"), sds.kbar_step_sd_pct, 1000.0);
  read_per_region(table.table("n_step_sd"), sds.n_step_sd, 1.0);
  read_per_region(table.table("cbar_step_sd_pct"), sds.cbar_step_sd_pct, 1000.0);
  read_per_region(table.table("m_step_sd"), sds.m_step_sd, 1.0);
}

// A table's own chain SDs and its m_per_session table's; the caller finishes it.
void read_pooling_tables(TableReader& table, PoolingSettings& pooling) {
  read_chain_sds(table, pooling.per_step);
  TableReader shared = table.table("m_per_session");
  read_chain_sds(shared, pooling.m_per_session);
  shared.finish();
}

void read_pooling(TableReader table, PoolingSettings& pooling, PoolingSettings& footprint_mean) {
  read_pooling_tables(table, pooling);
  TableReader mean = table.table("footprint_mean");
  read_pooling_tables(mean, footprint_mean);
  mean.finish();
  table.finish();
}

// A one-of-several string setting; the reason lists the choices.
template <typename T, std::size_t N>
T choice(TableReader& table, std::string_view key,
         const std::array<std::pair<std::string_view, T>, N>& choices) {
  const std::string text = table.string(key);
  std::string names;
  for (const auto& [name, value] : choices) {
    if (name == text) return value;
    names += fmt::format("{}\"{}\"", names.empty() ? "" : ", ", name);
  }
  table.fail(key, fmt::format("must be one of {}, got \"{}\"", names, text));
}

void read_wire(TableReader table, WireSettings& wire) {
  const toml::array& sync = table.array("sync");
  // One to four bytes: enough for any framing seen in practice, and a fixed bound lets the
  // decoder keep the pattern in place.
  if (sync.empty() || sync.size() > 4) {
    table.fail("sync", fmt::format("must list 1 to 4 bytes, got {}", sync.size()));
  }
  wire.sync.clear();
  for (std::size_t i = 0; i < sync.size(); ++i) {
    const toml::node& element = *sync.get(i);
    const std::string key = fmt::format("{}[{}]", table.key_path("sync"), i);
    const auto* value = element.as_integer();
    if (value == nullptr) fail_element(table.file(), key, element, expected("an integer", element));
    if (value->get() < 0 || value->get() > 255) {
      fail_element(table.file(), key, element,
                   fmt::format("must be in [0, 255], got {}", value->get()));
    }
    wire.sync.push_back(static_cast<std::uint8_t>(value->get()));
  }
  wire.crc =
      choice(table, "crc",
             std::array{std::pair{std::string_view("crc16-ccitt-false"), CrcKind::Crc16CcittFalse},
                        std::pair{std::string_view("crc32"), CrcKind::Crc32},
                        std::pair{std::string_view("none"), CrcKind::None}});
  wire.crc_big_endian = choice(table, "crc_byte_order",
                               std::array{std::pair{std::string_view("little"), false},
                                          std::pair{std::string_view("big"), true}});
  wire.require_size_sensor_count = read_boolean(table, "require_size_sensor_count");
  table.finish();
}

void read_serial(TableReader table, SerialSettings& serial) {
  serial.device = table.string("device");
  if (serial.device.empty()) table.fail("device", "must not be empty");
  const std::int64_t baud = table.integer("baud");
  if (baud < 50 || baud > 4000000) {
    table.fail("baud", fmt::format("must be in [50, 4000000], got {}", baud));
  }
  serial.baud = static_cast<unsigned>(baud);
  serial.parity = choice(table, "parity",
                         std::array{std::pair{std::string_view("none"), SerialParity::None},
                                    std::pair{std::string_view("odd"), SerialParity::Odd},
                                    std::pair{std::string_view("even"), SerialParity::Even}});
  serial.data_bits = integer_in(table, "data_bits", 5, 8);
  serial.stop_bits = integer_in(table, "stop_bits", 1, 2);
  serial.flow_control =
      choice(table, "flow_control",
             std::array{std::pair{std::string_view("none"), SerialFlowControl::None},
                        std::pair{std::string_view("software"), SerialFlowControl::Software},
                        std::pair{std::string_view("hardware"), SerialFlowControl::Hardware}});
  serial.reconnect_initial_ms = integer_in(table, "reconnect_initial_ms", 1, 60000);
  serial.reconnect_max_ms = integer_in(table, "reconnect_max_ms", 1, 600000);
  if (serial.reconnect_max_ms < serial.reconnect_initial_ms) {
    table.fail("reconnect_max_ms",
               fmt::format("must be >= reconnect_initial_ms ({}), got {}",
                           serial.reconnect_initial_ms, serial.reconnect_max_ms));
  }
  table.finish();
}

void read_ring(TableReader table, RingSettings& ring) {
  // 2^24 frames of 184 bytes would already be 3 GB.
  ring.capacity_frames = static_cast<std::size_t>(integer_in(table, "capacity_frames", 2, 1 << 24));
  table.finish();
}

void read_monitor(TableReader table, MonitorSettings& monitor) {
  monitor.workers = integer_in(table, "workers", 1, 64);
  monitor.max_step_backlog = integer_in(table, "max_step_backlog", 1, 100000);
  monitor.status_period_s = number_in(table, "status_period_s", 0.01, 3600.0);
  monitor.publish_frames = read_boolean(table, "publish_frames");
  monitor.tissue_window_steps =
      integer_in(table, "tissue_window_steps", static_cast<int>(kMinPoolingSteps), 100000);
  table.finish();
}

void read_usb(TableReader table, UsbSettings& usb) {
  usb.vendor_id = static_cast<std::uint16_t>(integer_in(table, "vendor_id", 0, 0xFFFF));
  usb.product_id = static_cast<std::uint16_t>(integer_in(table, "product_id", 0, 0xFFFF));
  usb.interface = integer_in(table, "interface", 0, 255);
  const int endpoint = integer_in(table, "endpoint", 0, 255);
  // Bit 7 marks an IN endpoint; the driver only reads.
  if ((endpoint & 0x80) == 0 || (endpoint & 0x70) != 0 || (endpoint & 0x0F) == 0) {
    table.fail("endpoint",
               fmt::format("must be an IN endpoint address 0x81-0x8F, got {:#04x}", endpoint));
  }
  usb.endpoint = static_cast<std::uint8_t>(endpoint);
  usb.transfers = integer_in(table, "transfers", 1, 64);
  usb.transfer_bytes = integer_in(table, "transfer_bytes", 64, 1 << 20);
  usb.reconnect_initial_ms = integer_in(table, "reconnect_initial_ms", 1, 60000);
  usb.reconnect_max_ms = integer_in(table, "reconnect_max_ms", 1, 600000);
  if (usb.reconnect_max_ms < usb.reconnect_initial_ms) {
    table.fail("reconnect_max_ms", fmt::format("must be >= reconnect_initial_ms ({}), got {}",
                                               usb.reconnect_initial_ms, usb.reconnect_max_ms));
  }
  table.finish();
}

void read_log(TableReader table, LogSettings& log) {
  log.level = table.string("level");
  const std::vector<std::string> names = log_level_names();
  if (std::find(names.begin(), names.end(), log.level) == names.end()) {
    table.fail("level", fmt::format("must be one of \"{}\", got \"{}\"", fmt::join(names, "\", \""),
                                    log.level));
  }
  table.finish();
}

}  // namespace

std::vector<std::string> log_level_names() {
  return {"trace", "debug", "info", "warn", "error", "off"};
}

Config load_config(const fs::path& main_file) {
  Config config;
  config.source = main_file;
  const std::string file = main_file.string();
  const toml::table doc = parse_document(main_file, file, "(file)");
  TableReader root(doc, file, "");
  config.sample_rate_hz = number_above(root, "sample_rate_hz", 0.0);
  if (config.sample_rate_hz < kMinSampleRateHz || config.sample_rate_hz > kMaxSampleRateHz) {
    root.fail("sample_rate_hz", fmt::format("must be in [{}, {}], got {}", kMinSampleRateHz,
                                            kMaxSampleRateHz, config.sample_rate_hz));
  }
  const fs::path insoles_file = named_file(root, "insoles_file", main_file);
  const fs::path tissue_file = named_file(root, "tissue_file", main_file);
  read_sensor(root.table("sensor"), config.sensor);
  read_calibration(root.table("calibration"), config.calibration);
  read_sensor_creep(root.table("sensor_creep"), config.sensor_creep);
  read_segmentation(root.table("segmentation"), config.sample_rate_hz, config.segmentation);
  read_fit(root.table("fit"), config.fit_bounds);
  read_model(root.table("model"), file, config.model);
  read_asymmetry(root.table("asymmetry"), config.asymmetry, config.asymmetry_footprint_mean);
  read_pooling(root.table("pooling"), config.pooling, config.pooling_footprint_mean);
  read_wire(root.table("wire"), config.wire);
  read_serial(root.table("serial"), config.serial);
  read_ring(root.table("ring"), config.ring);
  read_monitor(root.table("monitor"), config.monitor);
  read_lcm(root.table("lcm"), config.lcm);
  read_usb(root.table("usb"), config.usb);
  read_log(root.table("log"), config.log);
  root.finish();
  read_insoles(insoles_file, file, config);
  read_tissue(tissue_file, file, config);
  return config;
}

fs::path default_config_path() {
  const char* from_env = std::getenv("GAITMON_CONFIG");
  if (from_env != nullptr && *from_env != '\0') return from_env;
  return GAITMON_DEFAULT_CONFIG;
}

}  // namespace gaitmon
