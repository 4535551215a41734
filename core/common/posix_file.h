// Small helpers shared by the modules that talk to the file system through POSIX descriptors
// (atomic writes, the model container, the miss log): one RAII descriptor, one I/O error shape,
// and the hex renderings their messages use for magic numbers and checksums.
#pragma once

#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>
#include <utility>

#include "core/common/result.h"

namespace animspace {

// kIo naming the path, what failed and the system's reason.
inline Error io_error(const std::filesystem::path& path, std::string_view what, int error_number) {
  return make_error(ErrorCode::kIo,
                    path.string() + ": " + std::string(what) + ": " + std::strerror(error_number));
}

// Closes a descriptor on scope exit unless released first.
class FileDescriptor {
 public:
  explicit FileDescriptor(int fd) : fd_(fd) {}
  ~FileDescriptor() {
    if (fd_ >= 0) ::close(fd_);
  }
  FileDescriptor(const FileDescriptor&) = delete;
  FileDescriptor& operator=(const FileDescriptor&) = delete;
  int get() const { return fd_; }
  int release() { return std::exchange(fd_, -1); }
  // Closes now and reports close()'s error (0 when none): on NFS and some other file systems a
  // failed write surfaces only here.
  int close_checked() {
    const int fd = std::exchange(fd_, -1);
    return ::close(fd) == 0 ? 0 : errno;
  }

 private:
  int fd_;
};

// Reads up to `count` bytes at `offset` of `fd` into `out`, retrying short reads and EINTR;
// returns how many there were (fewer only at end of file). kIo naming `path` on a read error.
inline Result<uint64_t> read_at(int fd, const std::filesystem::path& path, char* out, uint64_t count,
                                uint64_t offset) {
  uint64_t done = 0;
  while (done < count) {
    const uint64_t chunk = count - done < (uint64_t{1} << 30) ? count - done : (uint64_t{1} << 30);
    const ssize_t got = ::pread(fd, out + done, static_cast<size_t>(chunk), static_cast<off_t>(offset + done));
    if (got < 0 && errno == EINTR) continue;
    if (got < 0) return io_error(path, "cannot read", errno);
    if (got == 0) break;
    done += static_cast<uint64_t>(got);
  }
  return done;
}

// "0x1234abcd".
inline std::string hex32(uint32_t value) {
  char text[11];
  std::snprintf(text, sizeof text, "0x%08x", static_cast<unsigned>(value));
  return text;
}

// "89 4d 49 53": bytes as they stand in a file, for messages about magic numbers.
inline std::string hex_bytes(std::string_view bytes) {
  std::string text;
  for (const char c : bytes) {
    char byte[4];
    std::snprintf(byte, sizeof byte, "%02x", static_cast<unsigned>(static_cast<unsigned char>(c)));
    if (!text.empty()) text += ' ';
    text += byte;
  }
  return text;
}

}  // namespace animspace
