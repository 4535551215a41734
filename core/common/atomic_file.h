// Durable whole-file writes.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>

#include "core/common/result.h"

namespace animspace {

// Writes `bytes` to `path` so that a reader (or a crash) sees either the previous file or the
// complete new one: write to a temporary file in the same directory
// (".<name>.tmp.<pid>.<hex>", created with O_EXCL), fsync it, rename it over `path`, fsync the
// directory. A replaced regular file keeps its permission bits. On failure before the rename
// `path` is untouched and the temporary file removed; if only the final directory fsync fails,
// the new content is already in place but may not survive a crash, and the error says so.
// Errors: kIo naming the path, the step that failed and the operating system's reason.
Status write_file_atomically(const std::filesystem::path& path, std::string_view bytes);

// The same for a file made in pieces, so that a large one is never whole in memory (a model file
// with its training frames, issue #53): `write_pieces(append)` hands each piece to append in
// order; append returns false once a write has failed, and write_pieces should then stop (the
// error is the one returned).
using AppendPiece = std::function<bool(std::string_view piece)>;
Status write_file_atomically(const std::filesystem::path& path,
                             const std::function<void(const AppendPiece& append)>& write_pieces);

// Reads a whole file. Errors: kNotFound when it does not exist, kIo otherwise (with reason).
Result<std::string> read_whole_file(const std::filesystem::path& path);

// The same for a file that must be a regular file — a model, a cached basis (issue #54): a FIFO,
// device or socket in its place is refused without blocking on it (opened non-blocking, then
// checked), where reading it would wait for a writer that never comes. Errors: as
// read_whole_file, and kFailedPrecondition naming the path and what it is.
Result<std::string> read_regular_file(const std::filesystem::path& path);

// The same, for a format whose first `head_size` bytes say whether the rest is worth reading:
// `check_head(head, size)` sees them and the file's size on disk before anything more is read,
// so a 2 GB sparse file or a stranger's file in the model's place costs `head_size` bytes, not
// its size (issue #54 item 4). A file that grows past that size while being read is refused.
// Errors: as read_regular_file, then whatever check_head returns.
Result<std::string> read_regular_file(
    const std::filesystem::path& path, size_t head_size,
    const std::function<Status(std::string_view head, uint64_t size_on_disk)>& check_head);

}  // namespace animspace
