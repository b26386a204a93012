// gaitmon command line: one subcommand per job.
#include <CLI/CLI.hpp>

int main(int argc, char** argv) {
  CLI::App app{"gaitmon: real-time gait monitor for pressure-measuring insoles"};
  app.require_subcommand(1);
  CLI11_PARSE(app, argc, argv);
  return 0;
}
