// An output file that appears under its final name only when complete, so a failed run never
// leaves a file that looks finished.
#pragma once

#include <cstdio>
#include <filesystem>
#include <string_view>

namespace gaitmon::cli {

class OutputFile {
 public:
  /// Opens `path` + ".partial" for writing; throws std::runtime_error naming the file.
  explicit OutputFile(std::filesystem::path path);
  /// Removes the partial file if commit() was not reached.
  ~OutputFile();
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  void write(std::string_view text);
  /// Flushes, closes and renames to the final name; throws std::runtime_error on failure.
  void commit();
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
  std::filesystem::path partial_;
  std::FILE* file_ = nullptr;
};

}  // namespace gaitmon::cli
