// An output file that appears under its final name only when complete, so a failed run never
// leaves a file that looks finished.
#pragma once

#include <cstdio>
#include <filesystem>
#include <initializer_list>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace gaitmon::cli {

/// Refuses, before any work, an output path that publishing would harm or cannot reach: empty,
/// an existing directory, or an existing node that is not a regular file (a device, a FIFO, a
/// socket or a symlink, which the final rename would replace with a regular file). Throws
/// CLI::ValidationError naming `option` (a usage error, exit 2).
void check_output_path(const std::filesystem::path& path, const std::string& option);

/// Refuses, before any work, an output folder that cannot be one: an empty path, an existing
/// node that is not a folder, a path that cannot be looked up (a file on the way), or a new
/// folder whose nearest existing parent this user cannot write in (found only after the work
/// otherwise). Throws CLI::ValidationError naming `option` (a usage error, exit 2).
void check_output_dir(const std::filesystem::path& dir, const std::string& option);

/// Removes the files `names` (a command's whole set of outputs) that an earlier run left in `dir`,
/// before this run starts: a run that fails then leaves none of them, where the earlier run's
/// complete set would look like its own. Logs what it removed. Throws CLI::ValidationError
/// naming --out, before removing anything, where one of them is one of `inputs`, the files the
/// command reads (a session copied in as steps.csv would be deleted), and std::runtime_error naming
/// a file that cannot be removed.
void remove_earlier_outputs(const std::filesystem::path& dir,
                            std::initializer_list<std::string_view> names,
                            std::span<const std::filesystem::path> inputs);

class OutputFile {
 public:
  /// Opens `path` + ".partial" for writing; throws std::runtime_error naming the file.
  explicit OutputFile(std::filesystem::path path);
  /// Removes the partial file if commit_all() did not publish it.
  ~OutputFile();
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  void write(std::string_view text);
  const std::filesystem::path& path() const { return path_; }

  /// For a writer that opens its files by path: closes this one's stream and returns the partial
  /// path to write to instead. commit_all() and the destructor treat that file as their own.
  const std::filesystem::path& hand_over();

  /// Commits several files as one: all are flushed and closed first (where a full disk shows),
  /// then renamed; if a rename fails, the files already renamed are removed again, so a run
  /// leaves either every output or none. Throws std::runtime_error naming the file.
  static void commit_all(std::span<OutputFile* const> files);

 private:
  void close();
  void rename();

  std::filesystem::path path_;
  std::filesystem::path partial_;
  std::FILE* file_ = nullptr;
  bool published_ = false;
};

/// Whole files written in memory first and published together by commit(). A command makes
/// its set before any work, naming every file it may write, so that the list of what a rerun
/// removes and what it writes is one list.
class OutputSet {
 public:
  /// remove_earlier_outputs(dir, names, inputs).
  OutputSet(std::filesystem::path dir, std::initializer_list<std::string_view> names,
            std::span<const std::filesystem::path> inputs);
  /// Creates dir/name.partial holding `text`; throws std::runtime_error naming the file, and
  /// std::logic_error for a name the set was not made with.
  void add(std::string_view name, std::string_view text);
  /// OutputFile::commit_all over the files added; returns their final paths. Throws
  /// std::runtime_error naming a file that cannot be committed.
  std::vector<std::filesystem::path> commit();

 private:
  std::filesystem::path dir_;
  std::vector<std::string> names_;
  std::vector<std::unique_ptr<OutputFile>> files_;
};

}  // namespace gaitmon::cli
