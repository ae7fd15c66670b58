// libFuzzer target for the daemon's protocol line parser and command check: arbitrary bytes
// must never crash, hang or throw; an accepted line is an object with a string cmd; every
// error has a code; every reply built from what was read is one line of valid JSON.
#include <cstdint>
#include <cstdlib>
#include <string>

#include "insitu/daemon/protocol.h"

namespace {

void Check(bool condition) {
  if (!condition) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string line(reinterpret_cast<const char*>(data), size);
  const insitu::daemon::ParsedLine p = insitu::daemon::ParseRequest(line, 4096);
  std::string reply;
  if (!p.ok) {
    Check(!p.error.code.empty());
    reply = insitu::daemon::ReplyError(p.error.id, p.error.code, p.error.message);
  } else {
    Check(p.request.body.is_object());
    const auto error = insitu::daemon::CheckRequest(p.request);
    reply = error ? insitu::daemon::ReplyError(error->id, error->code, error->message)
                  : insitu::daemon::ReplyOk(p.request.id);
  }
  Check(!reply.empty() && reply.back() == '\n');
  Check(reply.find('\n') == reply.size() - 1);
  Check(nlohmann::json::accept(reply));
  return 0;
}
