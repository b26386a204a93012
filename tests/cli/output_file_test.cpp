// The analyze and discrepancy outputs: files appear under their final names only together and
// only when complete; a failed publication takes back what it had already renamed; an earlier
// run's outputs go before a rerun.
#include "src/cli/output_file.hpp"

#include <gtest/gtest.h>

#include <CLI/Error.hpp>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

#include "test_support.hpp"

namespace gaitmon::cli {
namespace {

namespace fs = std::filesystem;

std::vector<std::string> names_in(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) names.push_back(entry.path().filename());
  std::sort(names.begin(), names.end());
  return names;
}

std::string read(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TEST(OutputFile, NothingHasItsFinalNameUntilTheSetIsCommitted) {
  const fs::path dir = test::scratch_dir("output_commit");
  OutputSet set(dir, {"steps.csv", "session.json"}, {});
  set.add("steps.csv", "a,b\n1,2\n");
  set.add("session.json", "{}\n");
  EXPECT_EQ(names_in(dir), (std::vector<std::string>{"session.json.partial", "steps.csv.partial"}));

  const std::vector<fs::path> paths = set.commit();
  EXPECT_EQ(paths, (std::vector<fs::path>{dir / "steps.csv", dir / "session.json"}));
  EXPECT_EQ(names_in(dir), (std::vector<std::string>{"session.json", "steps.csv"}));
  EXPECT_EQ(read(dir / "steps.csv"), "a,b\n1,2\n");
  EXPECT_EQ(read(dir / "session.json"), "{}\n");
}

TEST(OutputFile, ASetThatIsNeverCommittedLeavesNothingBehind) {
  const fs::path dir = test::scratch_dir("output_abandoned");
  {
    OutputSet set(dir, {"regions.csv"}, {});
    set.add("regions.csv", "foot,step\n");
  }
  EXPECT_TRUE(names_in(dir).empty());
}

TEST(OutputFile, AFailedRenameTakesBackTheFilesAlreadyPublished) {
  const fs::path dir = test::scratch_dir("output_rename_fails");
  {
    OutputSet set(dir, {"steps.csv", "session.json"}, {});
    // A folder that is not empty cannot be replaced by a file, so the second rename fails.
    test::write_text(dir / "session.json" / "keep", "x");
    set.add("steps.csv", "new\n");
    set.add("session.json", "{}\n");
    try {
      set.commit();
      FAIL() << "commit succeeded over a folder";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find((dir / "session.json").string() + ": cannot rename"),
                std::string::npos)
          << e.what();
    }
    EXPECT_FALSE(fs::exists(dir / "steps.csv"));
  }
  EXPECT_EQ(names_in(dir), std::vector<std::string>{"session.json"});
}

TEST(OutputFile, AFileHandedOverToAnotherWriterIsCommittedOrRemovedAsItsOwn) {
  const fs::path dir = test::scratch_dir("output_handed_over");
  {
    OutputFile abandoned(dir / "a.csv");
    test::write_text(abandoned.hand_over(), "written by path\n");
    EXPECT_EQ(names_in(dir), std::vector<std::string>{"a.csv.partial"});
    EXPECT_THROW(abandoned.write("x"), std::logic_error);
  }
  EXPECT_TRUE(names_in(dir).empty());

  OutputFile handed(dir / "b.csv");
  OutputFile own(dir / "b.json");
  test::write_text(handed.hand_over(), "written by path\n");
  own.write("{}\n");
  OutputFile* const files[] = {&handed, &own};
  OutputFile::commit_all(files);
  EXPECT_EQ(names_in(dir), (std::vector<std::string>{"b.csv", "b.json"}));
  EXPECT_EQ(read(dir / "b.csv"), "written by path\n");
}

// A rerun into the folder of an earlier run: the command's whole set goes before the work, so
// that a run that fails leaves none of it (the earlier set would look like this run's).
TEST(OutputFile, AnEarlierRunsOutputsAreRemovedAndOtherFilesKept) {
  const fs::path dir = test::scratch_dir("output_earlier");
  test::write_text(dir / "report.html", "old\n");
  test::write_text(dir / "steps.csv", "old\n");
  test::write_text(dir / "notes.txt", "mine\n");
  remove_earlier_outputs(dir, {"steps.csv", "report.html", "never_written.html"}, {});
  EXPECT_EQ(names_in(dir), std::vector<std::string>{"notes.txt"});
  remove_earlier_outputs(dir / "not_there", {"steps.csv"}, {});
}

TEST(OutputFile, AnEarlierOutputThatCannotBeRemovedIsNamedInTheError) {
  const fs::path dir = test::scratch_dir("output_earlier_stays");
  test::write_text(dir / "report.html" / "keep", "x");
  try {
    remove_earlier_outputs(dir, {"report.html"}, {});
    FAIL() << "removed a folder that is not empty";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find((dir / "report.html").string() +
                                         ": cannot remove an earlier run's output"),
              std::string::npos)
        << e.what();
  }
}

// A set removes an earlier run's files of the names it is made with, and writes no other.
TEST(OutputFile, ASetRemovesTheEarlierRunsFilesOfItsNamesAndWritesNoOther) {
  const fs::path dir = test::scratch_dir("output_set_names");
  test::write_text(dir / "steps.csv", "earlier\n");
  test::write_text(dir / "notes.txt", "mine\n");
  OutputSet set(dir, {"steps.csv", "report.html"}, {});
  EXPECT_EQ(names_in(dir), std::vector<std::string>{"notes.txt"});
  set.add("steps.csv", "new\n");
  EXPECT_THROW(set.add("notes.txt", "overwritten\n"), std::logic_error);
  set.commit();
  EXPECT_EQ(read(dir / "steps.csv"), "new\n");
  EXPECT_EQ(read(dir / "notes.txt"), "mine\n");
}

TEST(OutputFile, AnOutputFolderMustBeAFolderOrNotExistYet) {
  const fs::path dir = test::scratch_dir("output_dir_check");
  EXPECT_NO_THROW(check_output_dir(dir, "--out"));
  EXPECT_NO_THROW(check_output_dir(dir / "new", "--out"));
  EXPECT_NO_THROW(check_output_dir(dir / "new" / "newer", "--out"));
  EXPECT_THROW(check_output_dir("", "--out"), CLI::ValidationError);
  const fs::path file = test::write_text(dir / "file", "x");
  EXPECT_THROW(check_output_dir(file, "--out"), CLI::ValidationError);
  // A file on the way: this was found only when the outputs were written, as exit 1.
  try {
    check_output_dir(file / "sub", "--out");
    FAIL() << "a folder under a file passed";
  } catch (const CLI::ValidationError& e) {
    EXPECT_NE(std::string(e.what()).find((file / "sub").string() + ": Not a directory"),
              std::string::npos)
        << e.what();
  }
}

// A session copied into the output folder under an output's name was deleted as an earlier
// run's output before it was read (`analyze out/steps.csv --out out`).
TEST(OutputFile, TheFileACommandReadsIsNeverRemovedAsAnEarlierOutput) {
  const fs::path dir = test::scratch_dir("output_input");
  const fs::path session = test::write_text(dir / "steps.csv", "a session\n");
  fs::create_directories(dir / "other");
  const fs::path link = dir / "other" / "session.json";
  fs::create_symlink(session, link);
  for (const fs::path& input : {session, link}) {
    try {
      remove_earlier_outputs(dir, {"session.json", "steps.csv"}, std::span(&input, 1));
      FAIL() << "removed the input " << input;
    } catch (const CLI::ValidationError& e) {
      EXPECT_NE(std::string(e.what()).find((dir / "steps.csv").string() +
                                           " is the file this command reads"),
                std::string::npos)
          << e.what();
    }
    EXPECT_EQ(read(session), "a session\n");
  }
  // Through the link the input is also an output's name there: that one goes neither.
  EXPECT_THROW(OutputSet(dir / "other", {"session.json"}, std::span(&session, 1)),
               CLI::ValidationError);
  EXPECT_EQ(read(session), "a session\n");
  EXPECT_TRUE(fs::is_symlink(fs::symlink_status(link)));
}

TEST(OutputFile, AFolderThatCannotBeWrittenIsNamedInTheError) {
  const fs::path dir = test::scratch_dir("output_missing") / "not_there";
  OutputSet set(dir, {"steps.csv"}, {});
  try {
    set.add("steps.csv", "x\n");
    FAIL() << "created a file in a folder that does not exist";
  } catch (const std::runtime_error& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find((dir / "steps.csv.partial").string() + ": cannot create: "),
              std::string::npos)
        << message;
    EXPECT_NE(message.find("No such file or directory"), std::string::npos) << message;
  }
}

}  // namespace
}  // namespace gaitmon::cli
