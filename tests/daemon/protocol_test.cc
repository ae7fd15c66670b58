// The protocol's outside: every malformed line gets a named error (never an exception), the
// command table checks arguments before any handler, and errors map to one set of codes.
#include "insitu/daemon/protocol.h"

#include <gtest/gtest.h>

#include <random>
#include <set>
#include <string>

namespace insitu::daemon {
namespace {

std::string CodeOf(std::string_view line, size_t limit = kDefaultMaxLineBytes) {
  const ParsedLine p = ParseRequest(line, limit);
  return p.ok ? "ok" : p.error.code;
}

TEST(Protocol, MalformedLinesAreNamed) {
  EXPECT_EQ(CodeOf(R"({"id": 1, "cmd": "ping"})"), "ok");
  EXPECT_EQ(CodeOf("{\"id\": 1, \"cmd\": \"ping\"}\r"), "ok");  // CRLF clients
  EXPECT_EQ(CodeOf(std::string(100, 'x'), 64), "line_too_long");
  EXPECT_EQ(CodeOf("{\"id\": 1, \"cmd\": \"pi"), "invalid_json");  // half a line
  EXPECT_EQ(CodeOf(std::string("\x00\xff\xfe{", 4)), "invalid_json");
  EXPECT_EQ(CodeOf("\xc3\x28"), "invalid_json");  // invalid UTF-8
  EXPECT_EQ(CodeOf("[1, 2]"), "not_an_object");
  EXPECT_EQ(CodeOf("42"), "not_an_object");
  EXPECT_EQ(CodeOf(R"({"id": 7})"), "missing_cmd");
  EXPECT_EQ(CodeOf(R"({"id": 7, "cmd": 3})"), "bad_type");
  // The id comes back whenever it could be read.
  EXPECT_EQ(ParseRequest(R"({"id": "a7", "cmd": 3})").error.id, "a7");
}

TEST(Protocol, RandomBytesNeverThrow) {
  std::mt19937_64 rng(5);
  for (int i = 0; i < 2000; ++i) {
    std::string line(rng() % 64, '\0');
    for (char& c : line) c = static_cast<char>(rng());
    const ParsedLine p = ParseRequest(line);
    if (p.ok) {
      EXPECT_TRUE(p.request.body.is_object());
    } else {
      EXPECT_FALSE(p.error.code.empty());
    }
  }
}

TEST(Protocol, TheCommandTableChecksArguments) {
  const auto check = [](const char* line) -> std::string {
    const ParsedLine p = ParseRequest(line);
    EXPECT_TRUE(p.ok) << line;
    const auto e = CheckRequest(p.request);
    return e ? e->code + ": " + e->message : "ok";
  };
  EXPECT_EQ(check(R"({"id": 1, "cmd": "ping"})"), "ok");
  EXPECT_EQ(check(R"({"id": 1, "cmd": "run", "job": "config/jobs/scan_step_gauge.yaml"})"), "ok");
  EXPECT_EQ(check(R"({"id": 1, "cmd": "run", "job": {"job": "scan"}})"), "ok");
  EXPECT_NE(check(R"({"id": 1, "cmd": "teleport"})").find("unknown_command"), std::string::npos);
  EXPECT_NE(check(R"({"id": 1, "cmd": "teleport"})").find("shutdown"), std::string::npos);
  EXPECT_NE(check(R"({"id": 1, "cmd": "run"})").find("\"job\" is required"), std::string::npos);
  EXPECT_NE(check(R"({"id": 1, "cmd": "run", "job": 5})").find("\"job\" must be"),
            std::string::npos);
  EXPECT_NE(check(R"({"id": 1, "cmd": "ping", "speed": 5})").find("unknown argument \"speed\""),
            std::string::npos);
  EXPECT_NE(check(R"({"id": 1, "cmd": "auth", "token": 12})").find("bad_argument"),
            std::string::npos);
  // Every command documented.
  for (const CommandSpec& c : CommandTable()) EXPECT_FALSE(c.summary.empty()) << c.name;
  EXPECT_TRUE(FindCommand("shutdown")->admin);
  EXPECT_FALSE(FindCommand("auth")->needs_auth);
}

TEST(Protocol, RepliesAndEventsAreOneLineOfJson) {
  const std::string ok = ReplyOk(7, {{"state", "idle"}});
  EXPECT_EQ(ok.back(), '\n');
  const auto j = nlohmann::json::parse(ok);
  EXPECT_EQ(j["id"], 7);
  EXPECT_EQ(j["ok"], true);
  EXPECT_EQ(j["state"], "idle");
  const auto e = nlohmann::json::parse(ReplyError("x", FailedPrecondition("not armed")));
  EXPECT_EQ(e["ok"], false);
  EXPECT_EQ(e["error"]["code"], "wrong_state");
  EXPECT_EQ(e["error"]["message"], "not armed");
  const auto ev = nlohmann::json::parse(EventLine("state", {{"to", "armed"}}));
  EXPECT_EQ(ev["event"], "state");
  EXPECT_FALSE(ev.contains("id"));
  // One mapping for every internal code, all snake_case and distinct.
  std::set<std::string> codes;
  for (StatusCode c : {StatusCode::kInvalidArgument, StatusCode::kNotFound, StatusCode::kParseError,
                       StatusCode::kOutOfRange, StatusCode::kFailedPrecondition,
                       StatusCode::kDeviceError, StatusCode::kCancelled, StatusCode::kInternal}) {
    const std::string code = ErrorCode(Status(c, "x"));
    EXPECT_EQ(code.find_first_not_of("abcdefghijklmnopqrstuvwxyz_"), std::string::npos) << code;
    codes.insert(code);
  }
  EXPECT_EQ(codes.size(), 8u);
  // An id that is not valid UTF-8 still gives a parseable reply.
  const std::string bad_id = ReplyOk(std::string("\xff"));
  EXPECT_TRUE(nlohmann::json::accept(bad_id));
}

}  // namespace
}  // namespace insitu::daemon
