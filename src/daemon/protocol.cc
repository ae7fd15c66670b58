#include "insitu/daemon/protocol.h"

#include <algorithm>

namespace insitu::daemon {
namespace {

const char* TypeName(ArgType t) {
  switch (t) {
    case ArgType::kString:
      return "a string";
    case ArgType::kNumber:
      return "a number";
    case ArgType::kBool:
      return "true or false";
    case ArgType::kObject:
      return "an object";
    case ArgType::kStringOrObject:
      return "a string (a path) or an object (a job)";
  }
  return "?";
}

bool Matches(const nlohmann::json& v, ArgType t) {
  switch (t) {
    case ArgType::kString:
      return v.is_string();
    case ArgType::kNumber:
      return v.is_number();
    case ArgType::kBool:
      return v.is_boolean();
    case ArgType::kObject:
      return v.is_object();
    case ArgType::kStringOrObject:
      return v.is_string() || v.is_object();
  }
  return false;
}

}  // namespace

ParsedLine ParseRequest(std::string_view line, size_t max_bytes) {
  ParsedLine out;
  if (line.size() > max_bytes) {
    out.error = {errc::kLineTooLong,
                 "line of " + std::to_string(line.size()) + " bytes; the limit is " +
                     std::to_string(max_bytes),
                 nullptr};
    return out;
  }
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  // No exceptions: parse with allow_exceptions = false, a discarded value on any error
  // (invalid UTF-8 included).
  nlohmann::json j = nlohmann::json::parse(line.begin(), line.end(), nullptr, false);
  if (j.is_discarded()) {
    out.error = {errc::kInvalidJson, "the line is not a JSON object", nullptr};
    return out;
  }
  if (!j.is_object()) {
    out.error = {errc::kNotAnObject, "a request is a JSON object {\"id\": ..., \"cmd\": ...}",
                 nullptr};
    return out;
  }
  const nlohmann::json id = j.contains("id") ? j["id"] : nlohmann::json();
  if (!j.contains("cmd")) {
    out.error = {errc::kMissingCmd, "the request has no \"cmd\"", id};
    return out;
  }
  if (!j["cmd"].is_string()) {
    out.error = {errc::kBadType, "\"cmd\" must be a string", id};
    return out;
  }
  out.ok = true;
  out.request = {id, j["cmd"].get<std::string>(), std::move(j)};
  return out;
}

const std::vector<CommandSpec>& CommandTable() {
  static const std::vector<CommandSpec> kTable = {
      {"auth",
       "authenticate with the daemon's token (first, when one is configured)",
       {{"token", ArgType::kString, true}},
       false,
       false},
      {"ping", "is the daemon alive", {}, false, false},
      {"status", "machine state, the running job, its progress and the queue", {}, true, false},
      {"arm", "arm the machine: the next job may fire the marking laser", {}, true, false},
      {"disarm", "disarm the machine (refused while a job runs: cancel it)", {}, true, false},
      {"run",
       "run a job: `job` is a job file path on the daemon's machine or the job itself",
       {{"job", ArgType::kStringOrObject, true}, {"set", ArgType::kObject, false}},
       true,
       false},
      {"cancel",
       "cancel the running job (laser off, list aborted, what was measured kept), or a queued "
       "one by its job_id",
       {{"job_id", ArgType::kString, false}},
       true,
       false},
      {"ack",
       "answer the running job's prompt (machine.operator: person) by its prompt_id: done, or "
       "abort to end the job cancelled",
       {{"prompt_id", ArgType::kNumber, true}, {"abort", ArgType::kBool, false}},
       true,
       false},
      {"result", "a job's report", {{"job_id", ArgType::kString, true}}, true, false},
      {"list_results", "every job the results folder holds, newest first", {}, true, false},
      {"subscribe", "receive state, job, progress and prompt events on this connection", {}, true, false},
      {"shutdown", "stop the daemon safely (admin)", {}, true, true},
  };
  return kTable;
}

const CommandSpec* FindCommand(const std::string& name) {
  const auto& t = CommandTable();
  const auto it =
      std::find_if(t.begin(), t.end(), [&](const CommandSpec& c) { return c.name == name; });
  return it == t.end() ? nullptr : &*it;
}

std::optional<ProtocolError> CheckRequest(const Request& r) {
  const CommandSpec* spec = FindCommand(r.cmd);
  if (spec == nullptr) {
    std::string known;
    for (const CommandSpec& c : CommandTable()) known += (known.empty() ? "" : ", ") + c.name;
    return ProtocolError{errc::kUnknownCommand,
                         "unknown command \"" + r.cmd + "\" (known: " + known + ")", r.id};
  }
  const auto bad = [&](const std::string& message) {
    return ProtocolError{errc::kBadArgument, r.cmd + ": " + message, r.id};
  };
  for (auto item = r.body.begin(); item != r.body.end(); ++item) {
    const std::string& key = item.key();  // not a structured binding: lambdas capture it
    if (key == "id" || key == "cmd") continue;
    const auto it = std::find_if(spec->args.begin(), spec->args.end(),
                                 [&key](const ArgSpec& a) { return a.name == key; });
    if (it == spec->args.end()) return bad("unknown argument \"" + key + "\"");
    if (!Matches(item.value(), it->type))
      return bad("\"" + key + "\" must be " + TypeName(it->type));
  }
  for (const ArgSpec& a : spec->args) {
    if (a.required && !r.body.contains(a.name)) return bad("\"" + a.name + "\" is required");
  }
  return std::nullopt;
}

std::string ErrorCode(const Status& s) {
  switch (s.code()) {
    case StatusCode::kOk:
      return "ok";
    case StatusCode::kInvalidArgument:
      return errc::kBadArgument;
    case StatusCode::kNotFound:
      return errc::kNotFound;
    case StatusCode::kParseError:
      return errc::kBadInput;
    case StatusCode::kOutOfRange:
      return errc::kOutOfRange;
    case StatusCode::kFailedPrecondition:
      return errc::kWrongState;
    case StatusCode::kDeviceError:
      return errc::kDeviceError;
    case StatusCode::kCancelled:
      return errc::kCancelled;
    case StatusCode::kInternal:
      return errc::kInternal;
  }
  return errc::kInternal;
}

std::string ReplyOk(const nlohmann::json& id, nlohmann::json fields) {
  fields["id"] = id;
  fields["ok"] = true;
  // Replace invalid UTF-8 (an echoed id) rather than throw.
  return fields.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

std::string ReplyError(const nlohmann::json& id, const std::string& code,
                       const std::string& message) {
  nlohmann::json j;
  j["id"] = id;
  j["ok"] = false;
  j["error"] = {{"code", code}, {"message", message}};
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

std::string ReplyError(const nlohmann::json& id, const Status& status) {
  return ReplyError(id, ErrorCode(status), status.message());
}

std::string EventLine(const std::string& event, nlohmann::json fields) {
  fields["event"] = event;
  return fields.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

}  // namespace insitu::daemon
