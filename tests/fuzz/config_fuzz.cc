// libFuzzer target for ConfigNode/ConfigReader: arbitrary YAML, --set keys and values must never
// crash, hang or throw, every error must name where it comes from, and changing a Clone() must
// leave the original alone. Input: <set key>\<set value>\<YAML text> (FuzzedDataProvider strings).
#include <fuzzer/FuzzedDataProvider.h>

#include <cstdint>
#include <cstdlib>
#include <iterator>
#include <string>
#include <vector>

#include "insitu/core/config.h"

namespace {

constexpr char kOrigin[] = "fuzz.yaml";

void Check(bool condition) {
  if (!condition) std::abort();
}

// Errors name the file, or the --set that produced the value.
void CheckNamed(const insitu::Status& status) {
  if (status.ok()) return;
  const std::string& message = status.message();
  Check(message.find(kOrigin) != std::string::npos || message.find("--set ") != std::string::npos);
}

// Result::status() of a value is not ok, so look at ok() first.
template <typename T>
void CheckNamed(const insitu::Result<T>& result) {
  if (!result.ok()) CheckNamed(result.status());
}

template <typename T>
void ReadAs(insitu::ConfigReader& reader, const std::string& key) {
  T value{};
  reader.Read(key, &value);
}
void ReadArray(insitu::ConfigReader& reader, const std::string& key) {
  double values[3] = {};
  reader.ReadArray(key, values, 3);
}
void ReadEnum(insitu::ConfigReader& reader, const std::string& key) {
  std::string value;
  reader.ReadEnum(key, &value, {"a", "b"});
}

// Reads every entry of `node` the way module code would, choosing how by the key's length.
void ReadAll(insitu::ConfigReader& reader, const insitu::ConfigNode& node, int depth) {
  using Read = void (*)(insitu::ConfigReader&, const std::string&);
  constexpr Read kReads[] = {
      ReadAs<double>, ReadAs<int>, ReadAs<bool>, ReadAs<std::string>, ReadAs<std::vector<double>>,
      ReadArray,      ReadEnum};
  constexpr size_t kWays = std::size(kReads) + 1;  // the last way: a Section
  for (const std::string& key : node.Keys()) {
    const insitu::ConfigNode child = node.Child(key);
    const size_t way = (key.size() + static_cast<size_t>(depth)) % kWays;
    if (way < std::size(kReads)) {
      kReads[way](reader, key);
    } else if (depth < 8) {
      ReadAll(reader.Section(key), child, depth + 1);
    }
    CheckNamed(child.AsDouble());
    CheckNamed(child.AsInt());
    CheckNamed(child.AsBool());
    CheckNamed(child.AsDoubleList());
    (void)child.Where();
    (void)child.At(0).Where();
  }
  reader.Require("required");
  const std::string first = node.Keys().empty() ? "x" : node.Keys()[0];
  reader.FailFromValidate(insitu::OutOfRange(first + " is bad"));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  FuzzedDataProvider input(data, size);
  const std::string set_key = input.ConsumeRandomLengthString(64);
  const std::string set_value = input.ConsumeRandomLengthString(256);
  const std::string text = input.ConsumeRemainingBytesAsString();

  insitu::Result<insitu::ConfigNode> parsed = insitu::ConfigNode::Parse(text, kOrigin);
  if (!parsed.ok()) {
    Check(parsed.status().code() == insitu::StatusCode::kParseError);
    CheckNamed(parsed.status());
    return 0;
  }
  insitu::ConfigNode root = *parsed;
  const std::string before = root.Dump();

  insitu::ConfigNode copy = root.Clone();
  CheckNamed(copy.Set(set_key, set_value));
  CheckNamed(copy.Merge(root));
  Check(root.Dump() == before);

  for (const insitu::ConfigNode* node : {&root, &copy}) {
    insitu::ConfigReader reader(*node);
    ReadAll(reader, *node, 0);
    const insitu::Status status = reader.Finish();
    CheckNamed(status);
    Check(status.ok() == reader.ok());
  }
  CheckNamed(root.Merge(copy));
  return 0;
}
