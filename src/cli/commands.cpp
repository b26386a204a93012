// What every subcommand shares: the config it runs under, and how a fitted value is written.
#include "commands.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <charconv>
#include <cmath>
#include <filesystem>
#include <memory>
#include <string>
#include <system_error>
#include <vector>

#include "gaitmon/error.hpp"
#include "gaitmon/lcm_connection.hpp"

namespace gaitmon::cli {

Config load_global_config(const GlobalOptions& global) {
  Config config =
      load_config(global.config_path.empty() ? default_config_path() : global.config_path);
  spdlog::set_level(
      spdlog::level::from_str(global.log_level.empty() ? config.log.level : global.log_level));
  return config;
}

std::string sensor_creep_advice(const Config& config, double gain, double tau_s) {
  if (config.sensor_creep.gain > 0.0) {
    return fmt::format(
        "note: that creep is what the readings still show with the config's [sensor_creep] "
        "(gain {:.4g}, tau {:.4g} s) undone; to measure the insoles' creep anew, run again with "
        "its gain set to 0",
        config.sensor_creep.gain, config.sensor_creep.tau_s);
  }
  return fmt::format(
      "to undo this creep in every frame of these insoles, live (run, replay) and in every "
      "command, put in the config ({}):\n[sensor_creep]\ngain = {:.4g}\ntau_s = {:.4g}",
      config.source.string(), gain, tau_s);
}

CLI::Validator number_in(double min, double max, bool open_min) {
  const std::string range = fmt::format("{}{}, {}]", open_min ? "(" : "[", min, max);
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        double value = 0.0;
        const char* end = text.data() + text.size();
        const auto [ptr, ec] = std::from_chars(text.data(), end, value);
        if (ec != std::errc() || ptr != end) return "'" + text + "' is not a number";
        const bool above_min = open_min ? value > min : value >= min;
        if (!(above_min && value <= max)) return "'" + text + "' is not in " + range;
        return {};
      },
      "NUMBER in " + range);
}

CLI::Validator session_file_read_twice() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        std::error_code ec;
        const auto status = std::filesystem::status(text, ec);
        if (ec || !std::filesystem::exists(status)) return "File does not exist: " + text;
        if (std::filesystem::is_directory(status)) return text + " is a folder, not a session";
        if (!std::filesystem::is_regular_file(status)) {
          return text + " is not a regular file; this command reads a session twice, which a " +
                 "pipe cannot give (save it to a file first)";
        }
        return {};
      },
      "FILE");
}

std::vector<std::string> insole_size_names() {
  std::vector<std::string> names;
  for (InsoleSize s : kInsoleSizes) names.emplace_back(insole_size_name(s));
  return names;
}

CLI::Validator whole_number_in(std::uint64_t min, std::uint64_t max) {
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        std::uint64_t value = 0;
        const char* end = text.data() + text.size();
        const auto [ptr, ec] = std::from_chars(text.data(), end, value);
        if (ec == std::errc::result_out_of_range || (ec == std::errc() && value > max)) {
          return "'" + text + "' is larger than " + std::to_string(max);
        }
        if (ec != std::errc() || ptr != end) return "'" + text + "' is not a whole number";
        if (value < min) return "'" + text + "' is less than " + std::to_string(min);
        return {};
      },
      fmt::format("UINT in [{}, {}]", min, max));
}

std::string estimate_text(double value, double se, std::string_view plus_minus) {
  return std::isfinite(se) ? fmt::format("{:.4g}{}{:.2g}", value, plus_minus, se)
                           : fmt::format("{:.4g} (no SE)", value);
}

std::string param_text(const ParamEstimate& p, std::string_view plus_minus) {
  std::string text = estimate_text(p.value, p.se, plus_minus);
  if (std::isfinite(p.se) && std::isfinite(p.robust_se)) {
    text += fmt::format(" (sandwich{}{:.2g})", plus_minus, p.robust_se);
  }
  return text;
}

std::shared_ptr<lcm::LCM> open_lcm_url(const GlobalOptions& global, const std::string& url,
                                       bool from_command_line) {
  try {
    return open_lcm(url);
  } catch (const LcmError& e) {
    if (from_command_line) throw CLI::ValidationError("--lcm-url", e.what());
    throw ConfigError(
        (global.config_path.empty() ? default_config_path() : global.config_path).string(),
        "lcm.url", e.what());
  }
}

}  // namespace gaitmon::cli
