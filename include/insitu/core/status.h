// Status and Result<T>: how I/O, hardware and configuration paths report failure.
// A Status is ok or carries a code and one human-readable line that names what is wrong
// (the file, key or device) and what was expected. Asserts are for programmer bugs only.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <variant>

namespace insitu {

enum class StatusCode {
  kOk = 0,
  kInvalidArgument,   // bad value from an operator, a file or the network
  kNotFound,          // missing file, key or device
  kParseError,        // malformed file or line
  kOutOfRange,        // value outside the allowed range (stage travel, field size)
  kFailedPrecondition,// wrong state (laser not armed, device not open)
  kDeviceError,       // the hardware (or the simulated hardware) reported a fault
  kCancelled,
  kInternal,
};

const char* StatusCodeName(StatusCode code);

class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

  static Status Ok() { return {}; }
  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "invalid_argument: <message>" or "ok".
  std::string ToString() const;
  // A copy with `context + ": "` put in front of the message (keeps the code).
  Status Prefixed(const std::string& context) const;

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

inline Status InvalidArgument(std::string m) { return {StatusCode::kInvalidArgument, std::move(m)}; }
inline Status NotFound(std::string m) { return {StatusCode::kNotFound, std::move(m)}; }
inline Status ParseError(std::string m) { return {StatusCode::kParseError, std::move(m)}; }
inline Status OutOfRange(std::string m) { return {StatusCode::kOutOfRange, std::move(m)}; }
inline Status FailedPrecondition(std::string m) {
  return {StatusCode::kFailedPrecondition, std::move(m)};
}
inline Status DeviceError(std::string m) { return {StatusCode::kDeviceError, std::move(m)}; }
inline Status Internal(std::string m) { return {StatusCode::kInternal, std::move(m)}; }

// A value or the Status saying why there is none.
template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : value_(std::move(value)), status_() {}  // NOLINT: implicit by design
  Result(Status status) : status_(std::move(status)) {  // NOLINT: implicit by design
    if (status_.ok()) status_ = Status(StatusCode::kInternal, "result built from an ok status");
  }

  bool ok() const { return value_.has_value(); }
  // Ok when a value is held, else why there is none.
  const Status& status() const { return status_; }
  T& value() & { return *value_; }
  const T& value() const& { return *value_; }
  T&& value() && { return std::move(*value_); }
  T* operator->() { return &*value_; }
  const T* operator->() const { return &*value_; }
  T& operator*() { return *value_; }
  const T& operator*() const { return *value_; }

 private:
  std::optional<T> value_;
  Status status_;
};

}  // namespace insitu

#define INSITU_RETURN_IF_ERROR(expr)          \
  do {                                        \
    ::insitu::Status _st = (expr);            \
    if (!_st.ok()) return _st;                \
  } while (0)

#define INSITU_CONCAT_INNER(a, b) a##b
#define INSITU_CONCAT(a, b) INSITU_CONCAT_INNER(a, b)
#define INSITU_ASSIGN_OR_RETURN(lhs, expr)                                  \
  auto INSITU_CONCAT(_res_, __LINE__) = (expr);                             \
  if (!INSITU_CONCAT(_res_, __LINE__).ok())                                 \
    return INSITU_CONCAT(_res_, __LINE__).status();                         \
  lhs = std::move(INSITU_CONCAT(_res_, __LINE__)).value()
