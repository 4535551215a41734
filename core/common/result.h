// Error values for the core library.
//
// Core functions never throw across their public interface (STYLE.md §5): bad data comes back as
// an `Error` inside a `Result<T>`, programmer mistakes are asserts. The server maps `ErrorCode`
// to a gRPC status in exactly one place (server/status_mapping.cpp).
#pragma once

#include <cassert>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>

namespace animspace {

// What kind of failure; chosen so that each maps to one gRPC status code.
enum class ErrorCode {
  kInvalidArgument,     // the caller's data is malformed (wrong size, NaN, parse error)
  kNotFound,            // a named file, model, version or section does not exist
  kDataLoss,            // stored data is truncated or corrupt (checksum, short read)
  kFailedPrecondition,  // valid data the code cannot use here (e.g. a future format version)
  kOutOfRange,          // an index or value outside the documented range
  kResourceExhausted,   // a configured limit would be exceeded
  kUnimplemented,       // the operation has not been built yet
  kIo,                  // the operating system refused a read, write or rename
  kInternal,            // a broken invariant that is not the caller's fault
};

// Name of the code, for messages and logs ("INVALID_ARGUMENT").
const char* error_code_name(ErrorCode code);

struct Error {
  ErrorCode code = ErrorCode::kInternal;
  // Complete, human-readable sentence naming what was wrong and where (file:line, field,
  // expected vs actual).
  std::string message;
};

// A value or an error. Small on purpose: the toolchain (GCC 12) has no std::expected.
template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : state_(std::move(value)) {}  // NOLINT(google-explicit-constructor)
  Result(Error error) : state_(std::move(error)) {}  // NOLINT(google-explicit-constructor)

  bool ok() const { return std::holds_alternative<T>(state_); }
  explicit operator bool() const { return ok(); }

  T& value() & {
    assert(ok());
    return std::get<T>(state_);
  }
  const T& value() const& {
    assert(ok());
    return std::get<T>(state_);
  }
  T&& value() && {
    assert(ok());
    return std::get<T>(std::move(state_));
  }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

  const Error& error() const {
    assert(!ok());
    return std::get<Error>(state_);
  }

 private:
  std::variant<T, Error> state_;
};

// A result without a value: success, or an error.
class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(Error error) : error_(std::move(error)), ok_(false) {}  // NOLINT

  static Status Ok() { return {}; }
  bool ok() const { return ok_; }
  explicit operator bool() const { return ok_; }
  const Error& error() const {
    assert(!ok_);
    return error_;
  }

 private:
  Error error_;
  bool ok_ = true;
};

inline Error make_error(ErrorCode code, std::string message) { return Error{code, std::move(message)}; }

}  // namespace animspace

// Returns the error of a Result/Status expression from the enclosing function.
#define ANIMSPACE_RETURN_IF_ERROR(expr)              \
  do {                                               \
    auto animspace_status_ = (expr);                 \
    if (!animspace_status_.ok()) return animspace_status_.error(); \
  } while (false)
