// A one-line progress bar on stderr, shown only when stderr is a terminal.
#pragma once

#include <string>

namespace gaitmon::cli {

class ProgressBar {
 public:
  explicit ProgressBar(std::string label);
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  /// Redraws the bar at `fraction` (0..1) when it moved by a visible amount.
  void update(double fraction);

 private:
  std::string label_;
  bool enabled_;
  int drawn_ = -1;
};

}  // namespace gaitmon::cli
