#include "core/common/atomic_file.h"

#include "core/common/posix_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <new>
#include <string>

namespace animspace {
namespace {

// A name no other writer uses: the pid separates processes, the counter separates threads and
// calls of this process, the clock separates a pid reused after a crash. O_EXCL makes a
// collision an error (retried) rather than a shared file.
std::string temporary_name(const std::string& target_name, int attempt) {
  static std::atomic<uint64_t> counter{0};
  const auto ticks = static_cast<uint64_t>(
      std::chrono::steady_clock::now().time_since_epoch().count());
  uint64_t mixed = ticks ^ (counter.fetch_add(1) * 0x9E3779B97F4A7C15ULL) ^
                   static_cast<uint64_t>(attempt);
  mixed ^= mixed >> 29;
  char suffix[17];
  static constexpr char kHex[] = "0123456789abcdef";
  for (int i = 15; i >= 0; --i) {
    suffix[i] = kHex[mixed & 0xF];
    mixed >>= 4;
  }
  suffix[16] = '\0';
  return "." + target_name + ".tmp." + std::to_string(::getpid()) + "." + suffix;
}

int write_all(int fd, std::string_view bytes) {
  const char* data = bytes.data();
  size_t remaining = bytes.size();
  while (remaining > 0) {
    const ssize_t written = ::write(fd, data, remaining);
    if (written < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    data += written;
    remaining -= static_cast<size_t>(written);
  }
  return 0;
}

int fsync_retrying(int fd) {
  while (::fsync(fd) != 0) {
    if (errno != EINTR) return errno;
  }
  return 0;
}

}  // namespace

Status write_file_atomically(const std::filesystem::path& path, std::string_view bytes) {
  return write_file_atomically(path, [&](const AppendPiece& append) { append(bytes); });
}

Status write_file_atomically(const std::filesystem::path& path,
                             const std::function<void(const AppendPiece& append)>& write_pieces) {
  const std::string target_name = path.filename().string();
  if (target_name.empty() || target_name == "." || target_name == "..") {
    return make_error(ErrorCode::kIo, path.string() + ": not a file path");
  }
  std::filesystem::path directory = path.parent_path();
  if (directory.empty()) directory = ".";

  // Create the temporary file next to the target: rename() is atomic only within one file system.
  std::filesystem::path temporary;
  int fd = -1;
  for (int attempt = 0; attempt < 16 && fd < 0; ++attempt) {
    temporary = directory / temporary_name(target_name, attempt);
    fd = ::open(temporary.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd < 0 && errno != EEXIST) return io_error(path, "cannot create temporary file", errno);
  }
  if (fd < 0) return io_error(path, "cannot create a uniquely named temporary file", EEXIST);
  FileDescriptor file(fd);

  // From here on every failure removes the temporary file; `path` has not been touched.
  auto fail = [&](std::string_view what, int error_number) -> Status {
    if (file.get() >= 0) file.close_checked();
    ::unlink(temporary.c_str());
    return io_error(path, what, error_number);
  };

  // Replacing a file keeps its permission bits (rename installs a new inode, which would
  // otherwise get the umask default).
  struct stat existing {};
  if (::stat(path.c_str(), &existing) == 0 && S_ISREG(existing.st_mode)) {
    if (::fchmod(file.get(), existing.st_mode & 07777) != 0) {
      return fail("cannot copy permissions to temporary file", errno);
    }
  }
  int write_error = 0;
  write_pieces([&](std::string_view piece) {
    if (write_error == 0) write_error = write_all(file.get(), piece);
    return write_error == 0;
  });
  if (write_error != 0) return fail("cannot write temporary file", write_error);
  // The data must be on disk before the rename makes it visible, or a crash could leave `path`
  // naming an empty or partial file (the classic ext4 delayed-allocation zero-length file).
  if (int error_number = fsync_retrying(file.get()); error_number != 0) {
    return fail("cannot fsync temporary file", error_number);
  }
  if (int error_number = file.close_checked(); error_number != 0) {
    return fail("cannot close temporary file", error_number);
  }
  if (::rename(temporary.c_str(), path.c_str()) != 0) {
    return fail("cannot rename temporary file over it", errno);
  }

  // The rename is durable only once the directory entry is: fsync the directory. If this fails
  // the new content is already in place (no undo is possible), but the caller must know that a
  // crash could still bring back the old file.
  const int directory_fd = ::open(directory.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (directory_fd < 0) {
    return io_error(path, "replaced, but cannot open its directory to fsync it", errno);
  }
  FileDescriptor directory_file(directory_fd);
  if (int error_number = fsync_retrying(directory_file.get()); error_number != 0) {
    return io_error(path, "replaced, but cannot fsync its directory", error_number);
  }
  return Status::Ok();
}

namespace {

const char* file_type_name(mode_t mode) {
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  if (S_ISDIR(mode)) return "a directory";
  return "not a regular file";
}

using HeadCheck = std::function<Status(std::string_view head, uint64_t size_on_disk)>;

// Appends what `file` holds from its current offset until end of file or until `bytes` holds
// `limit` bytes. Returns whether the file ended: at the limit, one byte more is read to tell
// (and lost) when `probe_at_limit`, else the answer is false.
Result<bool> append_until_end(int file, const std::filesystem::path& path, std::string& bytes,
                              size_t limit, bool probe_at_limit) {
  char buffer[1 << 16];
  while (true) {
    const size_t room = limit - std::min(limit, bytes.size());
    if (room == 0) {
      if (!probe_at_limit) return false;
      // At the limit: one more byte says whether the file ends here.
      char probe = 0;
      ssize_t count;
      while ((count = ::read(file, &probe, 1)) < 0 && errno == EINTR) {
      }
      if (count < 0) return io_error(path, "cannot read", errno);
      return count == 0;
    }
    const ssize_t count = ::read(file, buffer, std::min(sizeof buffer, room));
    if (count < 0) {
      if (errno == EINTR) continue;
      return io_error(path, "cannot read", errno);
    }
    if (count == 0) return true;
    bytes.append(buffer, static_cast<size_t>(count));
  }
}

Result<std::string> read_file(const std::filesystem::path& path, bool regular_only,
                              size_t head_size = 0, const HeadCheck* check_head = nullptr) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | (regular_only ? O_NONBLOCK : 0));
  if (fd < 0) {
    const int error_number = errno;
    if (error_number == ENOENT) {
      return make_error(ErrorCode::kNotFound, path.string() + ": no such file");
    }
    return io_error(path, "cannot open", error_number);
  }
  FileDescriptor file(fd);

  std::string bytes;
  try {
    struct stat info {};
    const bool stated = ::fstat(file.get(), &info) == 0;
    if (regular_only && (!stated || !S_ISREG(info.st_mode))) {
      return make_error(ErrorCode::kFailedPrecondition,
                        path.string() + " is " + (stated ? file_type_name(info.st_mode) : "of unknown type") +
                            ", not a regular file: refused");
    }
    const uint64_t size_on_disk = stated && S_ISREG(info.st_mode) ? static_cast<uint64_t>(info.st_size) : 0;
    if (check_head != nullptr) {
      auto ended = append_until_end(file.get(), path, bytes, head_size, false);
      if (!ended.ok()) return ended.error();
      ANIMSPACE_RETURN_IF_ERROR((*check_head)(bytes, size_on_disk));
      bytes.reserve(static_cast<size_t>(size_on_disk));
      // The head vouched for size_on_disk bytes; more than that is a file changing under us.
      ended = append_until_end(file.get(), path, bytes, static_cast<size_t>(size_on_disk), true);
      if (!ended.ok()) return ended.error();
      if (!*ended) {
        return make_error(ErrorCode::kFailedPrecondition,
                          path.string() + " grew past " + std::to_string(size_on_disk) +
                              " bytes while being read: refused");
      }
      return bytes;
    }
    if (size_on_disk > 0) bytes.reserve(static_cast<size_t>(size_on_disk));
    // Read until end of file rather than trusting st_size: the file may grow or shrink while
    // being read, and pseudo-files report size 0.
    auto ended = append_until_end(file.get(), path, bytes, SIZE_MAX, false);
    if (!ended.ok()) return ended.error();
  } catch (const std::bad_alloc&) {
    return io_error(path, "cannot read", ENOMEM);
  }
  return bytes;
}

}  // namespace

Result<std::string> read_whole_file(const std::filesystem::path& path) { return read_file(path, false); }

Result<std::string> read_regular_file(const std::filesystem::path& path) { return read_file(path, true); }

Result<std::string> read_regular_file(const std::filesystem::path& path, size_t head_size,
                                      const HeadCheck& check_head) {
  return read_file(path, true, head_size, &check_head);
}

}  // namespace animspace
