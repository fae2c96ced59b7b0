// Status and Expected<T>: how core/ reports anything a user can cause (bad
// files, bad options, corrupted stores). Asserts are kept for internal
// invariants only. The server maps StatusCode to grpc::Status in one place.
//
// Thread-safety: plain values; safe to copy and move between threads.
#pragma once

#include <cassert>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>

namespace outcore {

enum class StatusCode {
  kOk = 0,
  kInvalidArgument,     // the user's input or option is wrong
  kNotFound,            // a named file, brick or generator does not exist
  kAlreadyExists,       // the output exists and would be overwritten
  kDataLoss,            // stored data is truncated or altered (checksum)
  kFailedPrecondition,  // e.g. a store of another format version
  kResourceExhausted,   // a budget would be exceeded
  kOutOfRange,          // an index or size beyond what the format allows
  kPermissionDenied,    // the caller may not use what it named
  kCancelled,           // interrupted by the user
  kIoError,             // the operating system refused a read or write
  kInternal,            // a broken invariant; a bug in Outcore
};

const char* status_code_name(StatusCode code);

class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

  static Status Ok() { return {}; }

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "INVALID_ARGUMENT: message"
  std::string to_string() const;

  // Prefixes context ("while packing x.obj: ") to the message, keeping the code.
  Status with_context(const std::string& context) const {
    if (ok()) return *this;
    return Status(code_, context + ": " + message_);
  }

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

inline Status invalid_argument(std::string m) {
  return {StatusCode::kInvalidArgument, std::move(m)};
}
inline Status not_found(std::string m) {
  return {StatusCode::kNotFound, std::move(m)};
}
inline Status already_exists(std::string m) {
  return {StatusCode::kAlreadyExists, std::move(m)};
}
inline Status data_loss(std::string m) {
  return {StatusCode::kDataLoss, std::move(m)};
}
inline Status failed_precondition(std::string m) {
  return {StatusCode::kFailedPrecondition, std::move(m)};
}
inline Status resource_exhausted(std::string m) {
  return {StatusCode::kResourceExhausted, std::move(m)};
}
inline Status out_of_range(std::string m) {
  return {StatusCode::kOutOfRange, std::move(m)};
}
inline Status permission_denied(std::string m) {
  return {StatusCode::kPermissionDenied, std::move(m)};
}
inline Status cancelled(std::string m) {
  return {StatusCode::kCancelled, std::move(m)};
}
inline Status io_error(std::string m) {
  return {StatusCode::kIoError, std::move(m)};
}
inline Status internal_error(std::string m) {
  return {StatusCode::kInternal, std::move(m)};
}

// "path: strerror(errno)" for the current errno.
Status io_error_from_errno(const std::string& what);

// A value or the Status that explains why there is none.
template <class T>
class [[nodiscard]] Expected {
  static_assert(!std::is_same_v<T, Status>);

 public:
  Expected(T value) : storage_(std::move(value)) {}        // NOLINT(implicit)
  Expected(Status status) : storage_(std::move(status)) {  // NOLINT(implicit)
    assert(!std::get<Status>(storage_).ok() && "Expected built from an OK status");
  }

  bool ok() const { return std::holds_alternative<T>(storage_); }
  explicit operator bool() const { return ok(); }

  const Status& status() const {
    static const Status kOk;
    return ok() ? kOk : std::get<Status>(storage_);
  }
  T& value() & {
    assert(ok());
    return std::get<T>(storage_);
  }
  const T& value() const& {
    assert(ok());
    return std::get<T>(storage_);
  }
  T&& value() && {
    assert(ok());
    return std::get<T>(std::move(storage_));
  }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

 private:
  std::variant<T, Status> storage_;
};

}  // namespace outcore

#define OUTCORE_CONCAT_INNER(a, b) a##b
#define OUTCORE_CONCAT(a, b) OUTCORE_CONCAT_INNER(a, b)

#define OUTCORE_RETURN_IF_ERROR(expr)                  \
  do {                                                 \
    ::outcore::Status outcore_status_ = (expr);        \
    if (!outcore_status_.ok()) return outcore_status_; \
  } while (0)

#define OUTCORE_ASSIGN_OR_RETURN_IMPL(tmp, lhs, expr) \
  auto tmp = (expr);                                  \
  if (!tmp.ok()) return tmp.status();                 \
  lhs = std::move(tmp).value()

// OUTCORE_ASSIGN_OR_RETURN(auto x, make_x()); returns the Status on failure.
#define OUTCORE_ASSIGN_OR_RETURN(lhs, expr) \
  OUTCORE_ASSIGN_OR_RETURN_IMPL(OUTCORE_CONCAT(outcore_expected_, __LINE__), lhs, expr)
