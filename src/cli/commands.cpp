// What every subcommand shares: the config it runs under, and how a fitted value is written.
#include "commands.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <cmath>
#include <exception>
#include <memory>
#include <string>

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

std::string estimate_text(double value, double se, std::string_view plus_minus) {
  return std::isfinite(se) ? fmt::format("{:.4g}{}{:.2g}", value, plus_minus, se)
                           : fmt::format("{:.4g} (no SE)", value);
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

CLI::Validator number_range(double min, double max) {
  return CLI::Validator(
      [min, max](const std::string& text) {
        std::size_t used = 0;
        double value = 0.0;
        try {
          value = std::stod(text, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        // Written as a match so that NaN, which compares false with everything, fails it.
        if (used == text.size() && value >= min && value <= max) return std::string();
        return fmt::format("must be a number from {:g} to {:g}, got {}", min, max, text);
      },
      fmt::format("NUMBER in [{:g}, {:g}]", min, max));
}

CLI::Validator whole_number_from(std::uint64_t min) {
  return CLI::Validator(
      [min](const std::string& text) {
        std::size_t used = 0;
        unsigned long long value = 0;
        try {
          value = std::stoull(text, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        // stoull takes "-1" as the largest value.
        if (used == text.size() && text.find('-') == std::string::npos && value >= min) {
          return std::string();
        }
        return fmt::format("must be a whole number >= {}, got {}", min, text);
      },
      fmt::format("INT >= {}", min));
}

}  // namespace gaitmon::cli
