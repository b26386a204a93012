// Write-then-rename output files.
#include "output_file.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <CLI/Error.hpp>
#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <system_error>
#include <utility>

namespace gaitmon::cli {
namespace {
[[noreturn]] void fail(const std::filesystem::path& path, const char* what) {
  throw std::runtime_error(path.string() + ": " + what + ": " + std::strerror(errno));
}
}  // namespace

void check_output_path(const std::filesystem::path& path, const std::string& option) {
  if (path.empty()) throw CLI::ValidationError(option, "the path is empty");
  std::error_code ec;
  const auto status = std::filesystem::symlink_status(path, ec);
  if (ec || !std::filesystem::exists(status)) return;
  if (std::filesystem::is_directory(status)) {
    throw CLI::ValidationError(option, path.string() + " is a directory");
  }
  if (!std::filesystem::is_regular_file(status)) {
    throw CLI::ValidationError(option, path.string() +
                                           " exists and is not a regular file (a device, pipe, "
                                           "socket or link), which writing it would replace");
  }
}

void check_output_dir(const std::filesystem::path& dir, const std::string& option) {
  // create_directories("") fails only after the work, with a message that names no option.
  if (dir.empty()) throw CLI::ValidationError(option, "the path is empty");
  std::error_code ec;
  const auto status = std::filesystem::status(dir, ec);
  if (ec && ec != std::errc::no_such_file_or_directory) {
    throw CLI::ValidationError(option, dir.string() + ": " + ec.message());
  }
  if (std::filesystem::exists(status)) {
    if (!std::filesystem::is_directory(status)) {
      throw CLI::ValidationError(option, dir.string() + " exists and is not a folder");
    }
    return;
  }
  std::filesystem::path parent = std::filesystem::absolute(dir).parent_path();
  while (!std::filesystem::exists(parent, ec) && parent.has_relative_path()) {
    parent = parent.parent_path();
  }
  if (::access(parent.c_str(), W_OK | X_OK) != 0) {
    throw CLI::ValidationError(
        option, dir.string() + " cannot be made: " + parent.string() + ": " + std::strerror(errno));
  }
}

void remove_earlier_outputs(const std::filesystem::path& dir,
                            std::initializer_list<std::string_view> names,
                            std::span<const std::filesystem::path> inputs) {
  for (const std::string_view name : names) {
    std::error_code ec;
    if (std::any_of(inputs.begin(), inputs.end(), [&](const std::filesystem::path& input) {
          return std::filesystem::equivalent(dir / name, input, ec);
        })) {
      throw CLI::ValidationError("--out", (dir / name).string() +
                                              " is the file this command reads, and a run "
                                              "replaces it with its own output: give another "
                                              "folder");
    }
  }
  std::vector<std::string> removed;
  for (const std::string_view name : names) {
    const std::filesystem::path path = dir / name;
    std::error_code ec;
    if (std::filesystem::remove(path, ec)) {
      removed.emplace_back(name);
    } else if (ec) {
      throw std::runtime_error(path.string() +
                               ": cannot remove an earlier run's output: " + ec.message());
    }
  }
  if (!removed.empty()) {
    spdlog::info(
        "removed an earlier run's outputs from {}: {} (this run writes its own, or none "
        "if it fails)",
        dir.string(), fmt::join(removed, ", "));
  }
}

OutputFile::OutputFile(std::filesystem::path path)
    : path_(std::move(path)), partial_(path_.string() + ".partial") {
  file_ = std::fopen(partial_.c_str(), "wb");
  if (file_ == nullptr) fail(partial_, "cannot create");
}

OutputFile::~OutputFile() {
  if (file_ != nullptr) std::fclose(file_);
  if (!published_) {
    std::error_code ignored;
    std::filesystem::remove(partial_, ignored);
  }
}

void OutputFile::write(std::string_view text) {
  if (file_ == nullptr) throw std::logic_error(partial_.string() + ": written after hand_over()");
  if (std::fwrite(text.data(), 1, text.size(), file_) != text.size()) fail(partial_, "write");
}

void OutputFile::close() {
  std::FILE* file = std::exchange(file_, nullptr);
  if (file != nullptr && std::fclose(file) != 0) fail(partial_, "close");
}

const std::filesystem::path& OutputFile::hand_over() {
  close();
  return partial_;
}

void OutputFile::rename() {
  std::error_code ec;
  std::filesystem::rename(partial_, path_, ec);
  if (ec) throw std::runtime_error(path_.string() + ": cannot rename: " + ec.message());
  published_ = true;
}

void OutputFile::commit_all(std::span<OutputFile* const> files) {
  for (OutputFile* file : files) file->close();
  std::size_t renamed = 0;
  try {
    for (; renamed < files.size(); ++renamed) files[renamed]->rename();
  } catch (...) {
    std::error_code ignored;
    for (std::size_t i = 0; i < renamed; ++i) {
      std::filesystem::remove(files[i]->path_, ignored);
      files[i]->published_ = false;
    }
    throw;
  }
}

OutputSet::OutputSet(std::filesystem::path dir, std::initializer_list<std::string_view> names,
                     std::span<const std::filesystem::path> inputs)
    : dir_(std::move(dir)), names_(names.begin(), names.end()) {
  remove_earlier_outputs(dir_, names, inputs);
}

void OutputSet::add(std::string_view name, std::string_view text) {
  if (std::find(names_.begin(), names_.end(), name) == names_.end()) {
    throw std::logic_error(
        fmt::format("{}: not among the outputs this set was made with", (dir_ / name).string()));
  }
  files_.push_back(std::make_unique<OutputFile>(dir_ / name));
  files_.back()->write(text);
}

std::vector<std::filesystem::path> OutputSet::commit() {
  std::vector<OutputFile*> files;
  std::vector<std::filesystem::path> paths;
  for (const auto& file : files_) {
    files.push_back(file.get());
    paths.push_back(file->path());
  }
  OutputFile::commit_all(files);
  return paths;
}

}  // namespace gaitmon::cli
