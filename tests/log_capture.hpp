// Sinks on the default logger for as long as a test needs them, removed on every way out (a
// failed ASSERT too), so that none outlives what it writes into.
#pragma once

#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <memory>
#include <sstream>
#include <utility>

namespace gaitmon::test {

/// Attaches `sink` while it lives. Declare it before anything whose threads log, so that it
/// outlives them.
class ScopedSink {
 public:
  explicit ScopedSink(spdlog::sink_ptr sink) : sink_(std::move(sink)) {
    spdlog::default_logger()->sinks().push_back(sink_);
  }
  ~ScopedSink() {
    auto& sinks = spdlog::default_logger()->sinks();
    sinks.erase(std::remove(sinks.begin(), sinks.end(), sink_), sinks.end());
  }
  ScopedSink(const ScopedSink&) = delete;
  ScopedSink& operator=(const ScopedSink&) = delete;

 private:
  spdlog::sink_ptr sink_;
};

/// What the default logger writes while it lives.
struct LogCapture {
  std::ostringstream text;
  ScopedSink sink{std::make_shared<spdlog::sinks::ostream_sink_mt>(text)};
};

}  // namespace gaitmon::test
