// Tests for core/io/input_file: what the OS answers becomes the right Status naming the path — a missing file,
// a directory, a FIFO (refused before any read could block), a file over the caller's limit (refused before the
// allocation), reads past the end — and a regular file is read exactly.
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "core/io/input_file.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

namespace fs = std::filesystem;

class InputFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("distband_input_file_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& bytes) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path, std::ios::binary) << bytes;
    return path;
  }
  fs::path dir_;
};

TEST_F(InputFileTest, ARegularFileIsReadExactly) {
  const std::string bytes("abc\0def\n", 8);
  const std::string path = write("f.bin", bytes);
  std::string got;
  ASSERT_TRUE(IsOk(readWholeFile(path, 8, "a test file", &got)));
  EXPECT_EQ(got, bytes);
  InputFile f;
  ASSERT_TRUE(IsOk(InputFile::open(path, &f)));
  EXPECT_EQ(f.size(), 8u);
  char part[3];
  ASSERT_TRUE(IsOk(f.readAt(4, part, 3)));
  EXPECT_EQ(std::string(part, 3), "def");
  ASSERT_TRUE(IsOk(f.readAt(8, part, 0)));
  EXPECT_TRUE(IsError(f.readAt(6, part, 3), Status::Code::kIoError, path + ": 3 bytes at byte 6 are past the end"));
}

TEST_F(InputFileTest, EveryRefusalNamesThePathWithTheRightCode) {
  std::string got = "untouched";
  const std::string missing = (dir_ / "missing.bin").string();
  EXPECT_TRUE(IsError(readWholeFile(missing, 100, "a test file", &got), Status::Code::kNotFound,
                      missing + ": cannot open: No such file"));
  const std::string under_a_file = write("plain", "x") + "/inside";
  EXPECT_TRUE(IsError(readWholeFile(under_a_file, 100, "a test file", &got), Status::Code::kNotFound, under_a_file));
  EXPECT_TRUE(IsError(readWholeFile(dir_.string(), 100, "a test file", &got), Status::Code::kInvalidArgument,
                      dir_.string() + ": not a regular file"));
  const std::string fifo = (dir_ / "fifo").string();
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  // No writer ever comes: the refusal must not wait for one.
  EXPECT_TRUE(IsError(readWholeFile(fifo, 100, "a test file", &got), Status::Code::kInvalidArgument,
                      fifo + ": not a regular file"));
  const std::string big = write("big.bin", std::string(101, 'x'));
  EXPECT_TRUE(IsError(readWholeFile(big, 100, "a test file", &got), Status::Code::kResourceExhausted,
                      big + ": 101 bytes are more than a test file of the limits holds (100 bytes)"));
  EXPECT_EQ(got, "untouched");
}

}  // namespace
}  // namespace distband
