// Status: the outcome of an operation that can fail because of its input, its budget or its caller.
// Contract (LevelDB's Status is the model):
//   * A Status is OK or carries a Code and a message. The message is meant for the person who sent the input: it
//     names the field (or file element) and the rule that was broken, never a server path or raw file contents.
//   * The code says whose fault it is and what to do: kInvalidArgument (the input breaks a rule: fix the input),
//     kNotFound (a named thing does not exist), kResourceExhausted (a limit or budget of this process: ask for
//     less or retry later), kCancelled (the caller gave up), kDeadlineExceeded (the caller's time ran out),
//     kUnavailable (the process is shutting down: retry elsewhere), kUnauthenticated (no valid credentials),
//     kIoError (a local file could not be read or written: the disk, its permissions; the CLI's files only — the
//     server opens no file because of a request), kInternal (a bug or an environment failure; never caused by input).
//   * Exceptions are for broken preconditions (a caller's bug), never for input: every core function that can fail
//     because of its input returns a Status.
//   * The server maps codes to gRPC codes in exactly one place (server/grpc_status.h); core never sees gRPC.
// Plain value type; copyable; not synchronised.
#pragma once

#include <string>
#include <string_view>
#include <utility>

namespace distband {

class [[nodiscard]] Status {
 public:
  enum class Code {
    kOk = 0,
    kInvalidArgument,
    kNotFound,
    kResourceExhausted,
    kCancelled,
    kDeadlineExceeded,
    kUnavailable,
    kUnauthenticated,
    kIoError,
    kInternal,
  };

  Status() = default;  ///< OK
  Status(Code code, std::string message) : code_(code), message_(code == Code::kOk ? std::string() : std::move(message)) {}

  static Status Ok() { return {}; }
  static Status InvalidArgument(std::string m) { return {Code::kInvalidArgument, std::move(m)}; }
  static Status NotFound(std::string m) { return {Code::kNotFound, std::move(m)}; }
  static Status ResourceExhausted(std::string m) { return {Code::kResourceExhausted, std::move(m)}; }
  static Status Cancelled(std::string m) { return {Code::kCancelled, std::move(m)}; }
  static Status DeadlineExceeded(std::string m) { return {Code::kDeadlineExceeded, std::move(m)}; }
  static Status Unavailable(std::string m) { return {Code::kUnavailable, std::move(m)}; }
  static Status Unauthenticated(std::string m) { return {Code::kUnauthenticated, std::move(m)}; }
  static Status IoError(std::string m) { return {Code::kIoError, std::move(m)}; }
  static Status Internal(std::string m) { return {Code::kInternal, std::move(m)}; }

  bool ok() const { return code_ == Code::kOk; }
  Code code() const { return code_; }
  const std::string& message() const { return message_; }

  /// The same code with `prefix: ` in front of the message (for adding the field or file name on the way out).
  Status withPrefix(std::string_view prefix) const {
    if (ok() || prefix.empty()) return *this;
    return {code_, std::string(prefix) + ": " + message_};
  }

  /// "OK" or "<CODE NAME>: <message>".
  std::string toString() const { return ok() ? std::string("OK") : std::string(codeName(code_)) + ": " + message_; }

  static std::string_view codeName(Code code) {
    switch (code) {
      case Code::kOk: return "OK";
      case Code::kInvalidArgument: return "INVALID_ARGUMENT";
      case Code::kNotFound: return "NOT_FOUND";
      case Code::kResourceExhausted: return "RESOURCE_EXHAUSTED";
      case Code::kCancelled: return "CANCELLED";
      case Code::kDeadlineExceeded: return "DEADLINE_EXCEEDED";
      case Code::kUnavailable: return "UNAVAILABLE";
      case Code::kUnauthenticated: return "UNAUTHENTICATED";
      case Code::kIoError: return "IO_ERROR";
      case Code::kInternal: return "INTERNAL";
    }
    return "UNKNOWN";
  }

 private:
  Code code_ = Code::kOk;
  std::string message_;
};

}  // namespace distband
