// The command socket's protocol (CONTRACT.md, "Daemon protocol"): one JSON object per line each
// way. A request is {"id": <any>, "cmd": "<name>", ...}; a reply echoes the id with "ok": true and
// its fields, or "ok": false and {"code": "<snake_case>", "message": "..."}; events carry
// "event" instead of "id".
//
// Everything a client sends passes ParseRequest and CheckRequest before any handler sees it;
// ErrorCode is the one place that maps internal errors to protocol codes.
#pragma once

#include <cstddef>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "insitu/core/status.h"

namespace insitu::daemon {

constexpr size_t kDefaultMaxLineBytes = 1 << 20;  // a job inline fits; a flood does not

struct Request {
  nlohmann::json id;  // null when the client sent none
  std::string cmd;
  nlohmann::json body;  // the whole object (arguments by name)
};

// A protocol error: its code (snake_case, as sent) and message.
struct ProtocolError {
  std::string code;
  std::string message;
  nlohmann::json id;  // the request's id when it could be read, else null
};

// One line (without its newline). Errors, each with the id when readable:
//   line_too_long (over max_bytes), invalid_json (not JSON: garbage, binary, half an object),
//   not_an_object, missing_cmd, bad_type (cmd not a string).
// Never throws.
struct ParsedLine {
  bool ok = false;
  Request request;
  ProtocolError error;
};
ParsedLine ParseRequest(std::string_view line, size_t max_bytes = kDefaultMaxLineBytes);

// A command's arguments: name, JSON type, required.
enum class ArgType { kString, kNumber, kBool, kObject, kStringOrObject };
struct ArgSpec {
  std::string name;
  ArgType type = ArgType::kString;
  bool required = false;
};

// The command table, as data: every command a client may send.
struct CommandSpec {
  std::string name;
  std::string summary;  // one line, for docs/protocol.md and `help`
  std::vector<ArgSpec> args;
  bool needs_auth = true;  // before auth only `auth` (and `ping`) are accepted
  bool admin = false;      // only for admin clients (shutdown)
};
const std::vector<CommandSpec>& CommandTable();
// nullptr for an unknown command.
const CommandSpec* FindCommand(const std::string& name);

// Every error code a reply carries ({"error": {"code": ..., "message": ...}}), as
// docs/protocol.md lists them.
namespace errc {
inline constexpr char kLineTooLong[] = "line_too_long";
inline constexpr char kInvalidJson[] = "invalid_json";
inline constexpr char kNotAnObject[] = "not_an_object";
inline constexpr char kMissingCmd[] = "missing_cmd";
inline constexpr char kBadType[] = "bad_type";
inline constexpr char kUnknownCommand[] = "unknown_command";
inline constexpr char kBadArgument[] = "bad_argument";
inline constexpr char kNotFound[] = "not_found";
inline constexpr char kBadInput[] = "bad_input";
inline constexpr char kOutOfRange[] = "out_of_range";
inline constexpr char kWrongState[] = "wrong_state";
inline constexpr char kDeviceError[] = "device_error";
inline constexpr char kCancelled[] = "cancelled";
inline constexpr char kInternal[] = "internal";
inline constexpr char kAuthTimeout[] = "auth_timeout";
inline constexpr char kIdleTimeout[] = "idle_timeout";
inline constexpr char kUnauthorized[] = "unauthorized";
inline constexpr char kTooManyClients[] = "too_many_clients";
inline constexpr char kForbidden[] = "forbidden";
}  // namespace errc

// Nothing when the request may be handled; else the error to reply with: unknown_command
// (listing the known ones), bad_argument (an unknown argument, a missing required one or a
// wrong type, named).
std::optional<ProtocolError> CheckRequest(const Request& request);

// The protocol code of an internal error: invalid_argument -> bad_argument, not_found ->
// not_found, parse_error -> bad_input, out_of_range -> out_of_range, failed_precondition ->
// wrong_state, device_error -> device_error, cancelled -> cancelled, internal -> internal.
std::string ErrorCode(const Status& status);

// Reply and event lines (each ends in '\n').
std::string ReplyOk(const nlohmann::json& id, nlohmann::json fields = nlohmann::json::object());
std::string ReplyError(const nlohmann::json& id, const std::string& code,
                       const std::string& message);
std::string ReplyError(const nlohmann::json& id, const Status& status);
std::string EventLine(const std::string& event, nlohmann::json fields = nlohmann::json::object());

}  // namespace insitu::daemon
