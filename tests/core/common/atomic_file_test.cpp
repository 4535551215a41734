#include "core/common/atomic_file.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/test_support.h"

namespace animspace {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;
using testing::write_text_file;

std::vector<std::string> directory_entries(const fs::path& directory) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(directory)) {
    names.push_back(entry.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

std::string read_or_die(const fs::path& path) {
  auto bytes = read_whole_file(path);
  EXPECT_TRUE(bytes.ok()) << bytes.error().message;
  return bytes.ok() ? *bytes : std::string();
}

TEST(AtomicFileTest, WritesNewFileAndLeavesNoTemporary) {
  TempDir dir;
  const fs::path path = dir / "model.anim";
  const std::string bytes("binary\0data\xff\n\0", 14);
  ASSERT_TRUE(write_file_atomically(path, bytes).ok());
  EXPECT_EQ(read_or_die(path), bytes);
  EXPECT_EQ(directory_entries(dir.path()), std::vector<std::string>{"model.anim"});
}

TEST(AtomicFileTest, ReplacesExistingFileAndLeavesNoTemporary) {
  TempDir dir;
  const fs::path path = dir / "model.anim";
  write_text_file(path, "old content that is longer than the new one");
  ASSERT_TRUE(write_file_atomically(path, "new").ok());
  EXPECT_EQ(read_or_die(path), "new");
  EXPECT_EQ(directory_entries(dir.path()), std::vector<std::string>{"model.anim"});
}

TEST(AtomicFileTest, RoundTripsLargeAndEmptyContent) {
  TempDir dir;
  std::string large(9 * 1024 * 1024 + 3, '\0');  // more than one read() and write() chunk
  for (size_t i = 0; i < large.size(); ++i) large[i] = static_cast<char>((i * 2654435761U) >> 13);
  ASSERT_TRUE(write_file_atomically(dir / "large", large).ok());
  EXPECT_EQ(read_or_die(dir / "large"), large);
  ASSERT_TRUE(write_file_atomically(dir / "empty", "").ok());
  EXPECT_EQ(read_or_die(dir / "empty"), "");
}

// Issue #53: a file written a piece at a time is the pieces in order; a writer stops at the first
// failed piece, and nothing replaces the file then.
TEST(AtomicFileTest, AFileWrittenInPiecesIsThePiecesInOrder) {
  TempDir dir;
  const std::vector<std::string> pieces = {"head", "", std::string(3 * 1024 * 1024, 'x'), std::string("\0tail", 5)};
  int handed = 0;
  ASSERT_TRUE(write_file_atomically(dir / "pieces",
                                    [&](const AppendPiece& append) {
                                      for (const std::string& piece : pieces) {
                                        EXPECT_TRUE(append(piece));
                                        ++handed;
                                      }
                                    })
                  .ok());
  EXPECT_EQ(handed, 4);
  EXPECT_EQ(read_or_die(dir / "pieces"), pieces[0] + pieces[1] + pieces[2] + pieces[3]);
  EXPECT_EQ(directory_entries(dir.path()), std::vector<std::string>{"pieces"});
}

TEST(AtomicFileTest, KeepsPermissionsOfReplacedFile) {
  TempDir dir;
  const fs::path path = dir / "secret";
  write_text_file(path, "old");
  ASSERT_EQ(::chmod(path.c_str(), 0600), 0);
  ASSERT_TRUE(write_file_atomically(path, "new").ok());
  struct stat info {};
  ASSERT_EQ(::stat(path.c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 0777, 0600U);
}

TEST(AtomicFileTest, RelativePathWithoutDirectoryWritesIntoCurrentDirectory) {
  TempDir dir;
  const fs::path previous = fs::current_path();
  fs::current_path(dir.path());
  const Status status = write_file_atomically("plain", "x");
  fs::current_path(previous);
  ASSERT_TRUE(status.ok()) << status.error().message;
  EXPECT_EQ(read_or_die(dir / "plain"), "x");
}

TEST(AtomicFileTest, ReadOnlyDirectoryFailsWithIoAndKeepsOldFile) {
  if (::geteuid() == 0) GTEST_SKIP() << "root ignores directory permissions";
  TempDir dir;
  const fs::path locked = dir / "locked";
  fs::create_directory(locked);
  const fs::path path = locked / "model.anim";
  write_text_file(path, "old");
  ASSERT_EQ(::chmod(locked.c_str(), 0500), 0);
  const Status status = write_file_atomically(path, "new");
  ::chmod(locked.c_str(), 0700);  // so that TempDir can clean up
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.error().code, ErrorCode::kIo);
  EXPECT_NE(status.error().message.find(path.string()), std::string::npos) << status.error().message;
  EXPECT_EQ(read_or_die(path), "old");
  EXPECT_EQ(directory_entries(locked), std::vector<std::string>{"model.anim"});
}

// Runs as root too: rename() refuses to replace a non-empty directory whatever the permissions,
// so this reaches the failure path after the temporary file has been written and synced.
TEST(AtomicFileTest, FailedRenameRemovesTemporaryAndKeepsTarget) {
  TempDir dir;
  const fs::path target = dir / "model.anim";
  fs::create_directory(target);
  write_text_file(target / "inside", "old");
  const Status status = write_file_atomically(target, "new");
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.error().code, ErrorCode::kIo);
  EXPECT_NE(status.error().message.find(target.string()), std::string::npos);
  EXPECT_NE(status.error().message.find("rename"), std::string::npos) << status.error().message;
  EXPECT_TRUE(fs::is_directory(target));
  EXPECT_EQ(read_or_die(target / "inside"), "old");
  EXPECT_EQ(directory_entries(dir.path()), std::vector<std::string>{"model.anim"});
}

TEST(AtomicFileTest, MissingDirectoryFailsWithIoNamingThePath) {
  TempDir dir;
  const fs::path path = dir / "no-such-directory" / "model.anim";
  const Status status = write_file_atomically(path, "x");
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.error().code, ErrorCode::kIo);
  EXPECT_NE(status.error().message.find(path.string()), std::string::npos);
  EXPECT_NE(status.error().message.find("No such file or directory"), std::string::npos)
      << status.error().message;
}

TEST(AtomicFileTest, ReadMissingFileIsNotFound) {
  TempDir dir;
  auto bytes = read_whole_file(dir / "absent");
  ASSERT_FALSE(bytes.ok());
  EXPECT_EQ(bytes.error().code, ErrorCode::kNotFound);
  EXPECT_NE(bytes.error().message.find("absent"), std::string::npos);
}

TEST(AtomicFileTest, ReadDirectoryIsIoError) {
  TempDir dir;
  auto bytes = read_whole_file(dir.path());
  ASSERT_FALSE(bytes.ok());
  EXPECT_EQ(bytes.error().code, ErrorCode::kIo);
  EXPECT_NE(bytes.error().message.find(dir.path().string()), std::string::npos);
}


}  // namespace
}  // namespace animspace

namespace animspace {
namespace {

// Issue #54: a FIFO named like a model file hung the daemon (open(2) of a FIFO waits for a writer).
// read_regular_file refuses it, and a directory, at once; read_whole_file keeps reading pipes (a
// token file may be `<(…)`).
TEST(ReadRegularFile, RefusesWhatIsNotARegularFileWithoutBlocking) {
  testing::TempDir dir;
  const std::filesystem::path fifo = dir / "model.anim";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const auto refused = read_regular_file(fifo);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kFailedPrecondition);
  EXPECT_EQ(refused.error().message, fifo.string() + " is a FIFO, not a regular file: refused");
  const auto directory = read_regular_file(dir.path());
  ASSERT_FALSE(directory.ok());
  EXPECT_NE(directory.error().message.find("is a directory, not a regular file"), std::string::npos)
      << directory.error().message;
  const std::filesystem::path plain = dir / "plain";
  testing::write_text_file(plain, "bytes");
  auto read = read_regular_file(plain);
  ASSERT_TRUE(read.ok()) << read.error().message;
  EXPECT_EQ(*read, "bytes");
  EXPECT_EQ(read_regular_file(dir / "absent").error().code, ErrorCode::kNotFound);
}

// Issue #54 item 4: a sparse gigabyte in a model's place is judged by its first bytes.
TEST(ReadRegularFile, AHeadCheckSeesTheHeadAndTheSizeBeforeAnythingElseIsRead) {
  testing::TempDir dir;
  const std::filesystem::path sparse = dir / "model.anim";
  testing::write_text_file(sparse, "head-of-file");
  constexpr uint64_t kSize = uint64_t{1} << 30;
  ASSERT_EQ(::truncate(sparse.c_str(), static_cast<off_t>(kSize)), 0);

  std::string seen_head;
  uint64_t seen_size = 0;
  const auto refused = read_regular_file(sparse, 4, [&](std::string_view head, uint64_t size) {
    seen_head = head;
    seen_size = size;
    return Status(make_error(ErrorCode::kInvalidArgument, "not ours"));
  });
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().message, "not ours");
  EXPECT_EQ(seen_head, "head");
  EXPECT_EQ(seen_size, kSize);

  const std::filesystem::path plain = dir / "plain";
  testing::write_text_file(plain, "the whole file");
  auto accepted = read_regular_file(plain, 64, [&](std::string_view head, uint64_t size) {
    EXPECT_EQ(head, "the whole file");  // shorter than the head: all of it
    EXPECT_EQ(size, 14U);
    return Status::Ok();
  });
  ASSERT_TRUE(accepted.ok()) << accepted.error().message;
  EXPECT_EQ(*accepted, "the whole file");
  accepted = read_regular_file(plain, 3, [](std::string_view, uint64_t) { return Status::Ok(); });
  ASSERT_TRUE(accepted.ok()) << accepted.error().message;
  EXPECT_EQ(*accepted, "the whole file");
}

}  // namespace
}  // namespace animspace
