// What every subcommand shares: the config it runs under, and how a fitted value is written.
#include "commands.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <cmath>

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

}  // namespace gaitmon::cli
