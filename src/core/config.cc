// yaml-cpp stays inside this file. Three of its habits shape the code:
//  - Assigning one YAML::Node to another re-points the assigned node inside the tree (and then
//    rebinds the handle; reset() only rebinds), and an alias (*name) puts the very same node in
//    several places. Parsed documents are therefore copied into alias-free trees, and writes only
//    replace values inside their own maps, so that changing one value never changes another, nor
//    the document a Clone() came from.
//  - YAML::Clone() loses marks (every line becomes 1). Copy() keeps them: it shares the key nodes,
//    whose marks give the lines in messages, and the scalar data.
//  - It throws on malformed input and on misuse. Nothing may leave this API, so every entry point
//    that calls into it catches.
#include "insitu/core/config.h"

#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <utility>

namespace insitu {
namespace {

// Deeper documents, and aliases that expand to more than a few values per input byte, are
// refused. This bounds every recursion below and stops alias cycles ("&a [*a]") and alias bombs.
constexpr int kMaxDepth = 128;
size_t NodeBudget(const std::string& text) { return 1024 + 4 * text.size(); }

struct Origin {
  std::string name;       // file name, "<request>" or "--set key=value"
  bool has_lines = true;  // marks of --set values are positions in the value text, not lines
};

struct Document {
  // Origins of the subtrees that did not come from the parsed text (--set values, merged
  // entries), by dotted path; an entry covers its whole subtree.
  std::map<std::string, Origin> origins;
};

std::string JoinPath(const std::string& parent, const std::string& key) {
  return parent.empty() ? key : parent + "." + key;
}

void EraseSubtree(std::map<std::string, Origin>* origins, const std::string& path) {
  origins->erase(path);
  const std::string prefix = path + ".";
  auto it = origins->lower_bound(prefix);
  while (it != origins->end() && it->first.compare(0, prefix.size(), prefix) == 0) {
    it = origins->erase(it);
  }
}

// Makes the node that `node` refers to hold `value`, for every holder of that node. Plain
// assignment does that too but then also rebinds the handle itself to `value`.
void Replace(const YAML::Node& node, const YAML::Node& value) {
  YAML::Node writer = node;
  writer = value;
}

int LineOf(const YAML::Mark& mark) { return mark.line >= 0 ? mark.line + 1 : 0; }

// Copied maps and sequences have no mark of their own; they start where their first entry does.
int FirstLine(const YAML::Node& node) {
  if (node.IsMap()) return node.begin() == node.end() ? 0 : LineOf(node.begin()->first.Mark());
  if (node.IsSequence()) return node.begin() == node.end() ? 0 : FirstLine(*node.begin());
  return LineOf(node.Mark());
}

// Deep copy, or nullopt past `depth_left` levels or `*budget` nodes.
std::optional<YAML::Node> Copy(const YAML::Node& from, int depth_left, size_t* budget) {
  if (depth_left < 0 || *budget == 0) return std::nullopt;
  --*budget;
  if (from.IsMap()) {
    YAML::Node to(YAML::NodeType::Map);
    for (const auto& entry : from) {
      std::optional<YAML::Node> value = Copy(entry.second, depth_left - 1, budget);
      if (!value) return std::nullopt;
      to.force_insert(entry.first, *value);
    }
    return to;
  }
  if (from.IsSequence()) {
    YAML::Node to(YAML::NodeType::Sequence);
    for (const auto& element : from) {
      std::optional<YAML::Node> value = Copy(element, depth_left - 1, budget);
      if (!value) return std::nullopt;
      to.push_back(*value);
    }
    return to;
  }
  // A node of its own over the same data, so that replacing it leaves `from` alone.
  YAML::Node to(YAML::NodeType::Null);
  Replace(to, from);
  return to;
}

// The value of `key` in `map`, or an undefined node.
YAML::Node FindValue(const YAML::Node& map, const std::string& key) {
  if (map.IsMap()) {
    for (const auto& entry : map) {
      if (entry.first.IsScalar() && entry.first.Scalar() == key) return entry.second;
    }
  }
  return YAML::Node(YAML::NodeType::Undefined);
}

// Counts the documents of a text. YAML::LoadAll() is not used: on some inputs (a lone ",") it
// reports empty documents forever without advancing, which this catches as `stuck`.
class DocumentCounter : public YAML::EventHandler {
 public:
  int documents = 0;
  bool stuck = false;
  YAML::Mark start;

  void OnDocumentStart(const YAML::Mark& mark) override {
    stuck = documents > 0 && mark.pos == start.pos;
    ++documents;
    start = mark;
  }
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark&, YAML::anchor_t) override {}
  void OnAlias(const YAML::Mark&, YAML::anchor_t) override {}
  void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t,
                const std::string&) override {}
  void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                       YAML::EmitterStyle::value) override {}
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                  YAML::EmitterStyle::value) override {}
  void OnMapEnd() override {}
};

std::string Located(const Origin& origin, const YAML::Mark& mark) {
  std::string located = origin.name;
  if (origin.has_lines && mark.line >= 0) located.append(":").append(std::to_string(mark.line + 1));
  return located;
}

// Parses a text that must hold one YAML document.
Result<YAML::Node> LoadOne(const std::string& text, const Origin& origin) {
  const std::string& where = origin.name;
  YAML::Node document;
  try {
    std::istringstream stream(text);
    YAML::Parser parser(stream);
    DocumentCounter counter;
    while (counter.documents < 2 && parser.HandleNextDocument(counter)) {
    }
    if (counter.stuck) {
      return ParseError(Located(origin, counter.start) + ": cannot parse past column " +
                        std::to_string(counter.start.column + 1) + ", expected valid YAML");
    }
    if (counter.documents > 1) {
      return ParseError(where + ": holds several YAML documents, expected one");
    }
    document = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    return ParseError(Located(origin, e.mark) + ": " + e.msg + ", expected valid YAML");
  }
  // An empty text gives a node without storage, which writes could not reach.
  if (!document.IsDefined() || document.IsNull()) return YAML::Node(YAML::NodeType::Null);
  size_t budget = NodeBudget(text);
  std::optional<YAML::Node> copy = Copy(document, kMaxDepth, &budget);
  if (!copy) {
    return ParseError(where + ": nested deeper than " + std::to_string(kMaxDepth) +
                      " levels or aliases expanding too far, expected a plain configuration");
  }
  return *copy;
}

// A scalar as messages show it: quoted, escaped, shortened.
std::string Quote(const std::string& text) {
  constexpr size_t kMaxShown = 40;
  std::string out = "\"";
  for (size_t i = 0; i < text.size() && i < kMaxShown; ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += static_cast<char>(c);
    } else if (c == '\n') {
      out += "\\n";
    } else if (c < 0x20 || c == 0x7f) {
      out += '?';
    } else {
      out += static_cast<char>(c);
    }
  }
  if (text.size() > kMaxShown) out += "...";
  return out + "\"";
}

std::string Join(const std::vector<std::string>& items) {
  std::string out;
  for (const std::string& item : items) out += (out.empty() ? "" : ", ") + item;
  return out;
}

Status Problem(StatusCode code, const std::string& where, const std::string& what) {
  return Status(code, where.empty() ? what : where + ": " + what);
}

bool IsYamlNonFinite(std::string text) {
  if (!text.empty() && (text[0] == '+' || text[0] == '-')) text.erase(0, 1);
  std::transform(text.begin(), text.end(), text.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return text == ".inf" || text == ".nan" || text == "inf" || text == "nan" || text == "infinity";
}

// from_chars, over the whole text, also taking the leading '+' that YAML allows.
template <typename T>
std::errc ParseNumber(const std::string& text, T* value) {
  const char* begin = text.data();
  const char* end = begin + text.size();
  if (end - begin > 1 && *begin == '+' && *(begin + 1) != '-') ++begin;
  const auto [ptr, ec] = std::from_chars(begin, end, *value);
  if (ec == std::errc() && ptr != end) return std::errc::invalid_argument;
  return ec;
}

// Numbers every recorded error, so that Finish() can return the first one in call order across a
// reader and its sections.
std::atomic<uint64_t> g_error_sequence{0};

}  // namespace

struct ConfigNode::Impl {
  std::shared_ptr<Document> doc = std::make_shared<Document>();
  YAML::Node node{YAML::NodeType::Undefined};
  Origin origin;
  std::string path;
  int line = 0;

  // A node below this one, `child_line` being where it starts in its file.
  ConfigNode Below(const std::string& child_path, const YAML::Node& child, int child_line) const {
    auto impl = std::make_shared<Impl>();
    impl->doc = doc;
    impl->node.reset(child);
    impl->path = child_path;
    auto it = doc->origins.find(child_path);
    impl->origin = it != doc->origins.end() ? it->second : origin;
    impl->line = impl->origin.has_lines ? child_line : 0;
    return ConfigNode(std::move(impl));
  }

  // The entry `key_node: value` of this map. The key's mark gives the line: copied maps and
  // sequences have none, and an empty value's mark is where the next key starts.
  ConfigNode Entry(const YAML::Node& key_node, const YAML::Node& value) const {
    return Below(JoinPath(path, key_node.Scalar()), value, LineOf(key_node.Mark()));
  }

  ConfigNode Find(const std::string& key) const {
    const YAML::Node& map = node;
    if (map.IsMap()) {
      for (const auto& entry : map) {
        if (entry.first.IsScalar() && entry.first.Scalar() == key) {
          return Entry(entry.first, entry.second);
        }
      }
    }
    // A missing key is placed at its map, where it would have to be added.
    return Below(JoinPath(path, key), YAML::Node(YAML::NodeType::Undefined), line);
  }

  // The error for a value that is not what `expected` says; `not_what` ends the sentence
  // "<scalar> is not ..." for scalars of the wrong kind.
  Status Mismatch(const std::string& where, const std::string& not_what,
                  const std::string& expected) const {
    const std::string tail = ", expected " + expected;
    if (!node.IsDefined()) return Problem(StatusCode::kNotFound, where, "missing" + tail);
    if (node.IsNull()) return Problem(StatusCode::kInvalidArgument, where, "is empty" + tail);
    if (node.IsMap()) return Problem(StatusCode::kInvalidArgument, where, "is a map" + tail);
    if (node.IsSequence()) return Problem(StatusCode::kInvalidArgument, where, "is a list" + tail);
    return Problem(StatusCode::kInvalidArgument, where,
                   Quote(node.Scalar()) + " is not " + not_what + tail);
  }

  // Records that the entry at `target_path` of this document now comes from `source`.
  void Graft(const std::string& target_path, const Impl& source) const {
    EraseSubtree(&doc->origins, target_path);
    doc->origins[target_path] = source.origin;
    const std::string prefix = source.path + ".";
    for (auto it = source.doc->origins.lower_bound(prefix);
         it != source.doc->origins.end() && it->first.compare(0, prefix.size(), prefix) == 0;
         ++it) {
      doc->origins[target_path + it->first.substr(source.path.size())] = it->second;
    }
  }

  // Merges the map `source` into the map `target`. `source` is a private copy, so its nodes can
  // move into the target document.
  static void MergeMaps(const Impl& target, const Impl& source) {
    std::map<std::string, std::pair<YAML::Node, YAML::Node>> overrides;
    const YAML::Node& source_map = source.node;
    for (const auto& entry : source_map) {
      if (entry.first.IsScalar()) {
        overrides.emplace(entry.first.Scalar(), std::make_pair(entry.first, entry.second));
      }
    }
    // The map is rebuilt so that a replaced entry carries the source's key, whose mark is its
    // line in the overrides, while the target's key order stays.
    YAML::Node merged(YAML::NodeType::Map);
    std::set<std::string> done;
    const YAML::Node& target_map = target.node;
    for (const auto& entry : target_map) {
      auto it = entry.first.IsScalar() ? overrides.find(entry.first.Scalar()) : overrides.end();
      if (it == overrides.end() || !done.insert(it->first).second) {
        merged.force_insert(entry.first, entry.second);
        continue;
      }
      const auto& [key_node, value] = it->second;
      if (entry.second.IsMap() && value.IsMap()) {
        MergeMaps(*target.Find(it->first).impl_, *source.Find(it->first).impl_);
        merged.force_insert(entry.first, entry.second);
      } else {
        merged.force_insert(key_node, value);
        target.Graft(JoinPath(target.path, it->first), *source.Find(it->first).impl_);
      }
    }
    for (const auto& entry : source_map) {  // new entries, in the order of the overrides
      if (entry.first.IsScalar() && !done.insert(entry.first.Scalar()).second) continue;
      merged.force_insert(entry.first, entry.second);
      if (entry.first.IsScalar()) {
        target.Graft(JoinPath(target.path, entry.first.Scalar()),
                     *source.Find(entry.first.Scalar()).impl_);
      }
    }
    Replace(target.node, merged);
  }
};

ConfigNode::ConfigNode() : impl_(std::make_shared<Impl>()) {}
ConfigNode::~ConfigNode() = default;
ConfigNode::ConfigNode(const ConfigNode&) = default;
ConfigNode& ConfigNode::operator=(const ConfigNode&) = default;
ConfigNode::ConfigNode(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}

Result<ConfigNode> ConfigNode::LoadFile(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    return NotFound(path + ": is a directory, expected a YAML file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return NotFound(path + ": cannot open (" + std::strerror(errno) +
                    "), expected a readable YAML file");
  }
  std::ostringstream text;
  text << in.rdbuf();
  return Parse(text.str(), path);
}

Result<ConfigNode> ConfigNode::Parse(const std::string& text, const std::string& origin) {
  try {
    Result<YAML::Node> root = LoadOne(text, {origin, true});
    if (!root.ok()) return root.status();
    auto impl = std::make_shared<Impl>();
    impl->node.reset(*root);
    impl->origin = {origin, true};
    return ConfigNode(std::move(impl));
  } catch (const std::exception& e) {
    return ParseError(origin + ": " + e.what() + ", expected valid YAML");
  }
}

bool ConfigNode::IsDefined() const { return impl_->node.IsDefined(); }
bool ConfigNode::IsMap() const { return impl_->node.IsMap(); }
bool ConfigNode::IsSequence() const { return impl_->node.IsSequence(); }
bool ConfigNode::IsScalar() const { return impl_->node.IsScalar(); }
bool ConfigNode::IsNull() const { return impl_->node.IsNull(); }

ConfigNode ConfigNode::Child(const std::string& key) const {
  try {
    return impl_->Find(key);
  } catch (const std::exception&) {
    return ConfigNode();
  }
}

ConfigNode ConfigNode::At(size_t index) const {
  const std::string child_path = impl_->path + "[" + std::to_string(index) + "]";
  try {
    const YAML::Node& node = impl_->node;
    if (node.IsSequence() && index < node.size()) {
      const YAML::Node element = node[index];
      const int element_line = FirstLine(element);
      return impl_->Below(child_path, element, element_line > 0 ? element_line : impl_->line);
    }
  } catch (const std::exception&) {
  }
  return impl_->Below(child_path, YAML::Node(YAML::NodeType::Undefined), impl_->line);
}

size_t ConfigNode::size() const {
  try {
    return IsMap() || IsSequence() ? impl_->node.size() : 0;
  } catch (const std::exception&) {
    return 0;
  }
}

std::vector<std::string> ConfigNode::Keys() const {
  std::vector<std::string> keys;
  try {
    const YAML::Node& node = impl_->node;
    if (!node.IsMap()) return keys;
    for (const auto& entry : node) {
      if (entry.first.IsScalar()) keys.push_back(entry.first.Scalar());
    }
  } catch (const std::exception&) {
  }
  return keys;
}

Result<double> ConfigNode::AsDouble() const {
  if (!IsScalar()) return impl_->Mismatch(Where(), "a number", "a number");
  const std::string& text = impl_->node.Scalar();
  double value = 0;
  const std::errc ec = ParseNumber(text, &value);
  if (ec == std::errc::result_out_of_range) {
    return Problem(StatusCode::kOutOfRange, Where(),
                   Quote(text) + " is out of range, expected a finite number");
  }
  if ((ec == std::errc() && !std::isfinite(value)) || IsYamlNonFinite(text)) {
    return Problem(StatusCode::kInvalidArgument, Where(),
                   Quote(text) + " is not finite, expected a finite number");
  }
  if (ec != std::errc()) return impl_->Mismatch(Where(), "a number", "a number");
  return value;
}

Result<int64_t> ConfigNode::AsInt() const {
  if (!IsScalar()) return impl_->Mismatch(Where(), "an integer", "an integer");
  const std::string& text = impl_->node.Scalar();
  int64_t value = 0;
  const std::errc ec = ParseNumber(text, &value);
  if (ec == std::errc::result_out_of_range) {
    return Problem(StatusCode::kOutOfRange, Where(),
                   Quote(text) + " is out of range, expected a 64-bit integer");
  }
  if (ec != std::errc()) return impl_->Mismatch(Where(), "an integer", "an integer");
  return value;
}

Result<bool> ConfigNode::AsBool() const {
  // Only the two YAML 1.2 spellings: yes/no/on/off read as booleans surprise people.
  if (IsScalar() && impl_->node.Scalar() == "true") return true;
  if (IsScalar() && impl_->node.Scalar() == "false") return false;
  return impl_->Mismatch(Where(), "true or false", "true or false");
}

Result<std::string> ConfigNode::AsString() const {
  if (!IsScalar()) return impl_->Mismatch(Where(), "a string", "a string");
  return impl_->node.Scalar();
}

Result<std::vector<double>> ConfigNode::AsDoubleList() const {
  if (!IsSequence()) return impl_->Mismatch(Where(), "a list", "a list of numbers");
  std::vector<double> values;
  for (size_t i = 0; i < size(); ++i) {
    Result<double> value = At(i).AsDouble();
    if (!value.ok()) return value.status();
    values.push_back(*value);
  }
  return values;
}

std::string ConfigNode::Where() const {
  std::string where = impl_->origin.name;
  if (impl_->line > 0) where.append(":").append(std::to_string(impl_->line));
  if (!impl_->path.empty()) where += (where.empty() ? "" : ": ") + impl_->path;
  return where;
}

const std::string& ConfigNode::file() const { return impl_->origin.name; }
const std::string& ConfigNode::path() const { return impl_->path; }
int ConfigNode::line() const { return impl_->line; }

Status ConfigNode::Set(const std::string& dotted_key, const std::string& value_text) {
  const std::string origin = "--set " + dotted_key + "=" + value_text;
  std::vector<std::string> keys;
  for (size_t begin = 0;;) {
    const size_t dot = dotted_key.find('.', begin);
    keys.push_back(dotted_key.substr(begin, dot == std::string::npos ? dot : dot - begin));
    if (keys.back().empty()) {
      return InvalidArgument(origin + ": " + Quote(dotted_key) +
                             " has an empty key part, expected keys separated by single dots");
    }
    if (dot == std::string::npos) break;
    begin = dot + 1;
  }
  if (keys.size() > static_cast<size_t>(kMaxDepth)) {
    return InvalidArgument(origin + ": more than " + std::to_string(kMaxDepth) + " key parts");
  }
  try {
    Result<YAML::Node> value = LoadOne(value_text, {origin, false});
    if (!value.ok()) return InvalidArgument(value.status().message());
    if (!IsMap() && !IsNull()) {
      return InvalidArgument(origin + ": " +
                             impl_->Mismatch(Where(), "a map", "a map to set keys in").message());
    }

    // Everything is checked before the first write, so a failed Set changes nothing: once one
    // key is missing, the rest of the path is created and cannot fail. Empty values are replaced
    // by maps rather than filled, as they may share data with the document they were cloned from.
    if (IsNull()) Replace(impl_->node, YAML::Node(YAML::NodeType::Map));
    YAML::Node map = impl_->node;
    std::string path = impl_->path;
    bool created = false;
    for (size_t i = 0; i + 1 < keys.size(); ++i) {
      path = JoinPath(path, keys[i]);
      YAML::Node next = created ? YAML::Node(YAML::NodeType::Undefined) : FindValue(map, keys[i]);
      if (!next.IsDefined()) {
        next.reset(YAML::Node(YAML::NodeType::Map));
        map.force_insert(keys[i], next);
        if (!created) impl_->doc->origins[path] = {origin, false};
        created = true;
      } else if (next.IsNull()) {
        Replace(next, YAML::Node(YAML::NodeType::Map));
      } else if (!next.IsMap()) {
        return InvalidArgument(origin + ": " + path + " is " +
                               (next.IsSequence() ? "a list" : "a scalar") +
                               ", expected a map to set " + keys[i + 1] + " in");
      }
      map.reset(next);
    }
    path = JoinPath(path, keys.back());
    YAML::Node old = FindValue(map, keys.back());
    if (old.IsDefined()) {
      Replace(old, *value);  // the old value is in this map only: there are no aliases
    } else {
      map.force_insert(keys.back(), *value);
    }
    EraseSubtree(&impl_->doc->origins, path);
    impl_->doc->origins[path] = {origin, false};
    return Status::Ok();
  } catch (const std::exception& e) {
    return Internal(origin + ": " + e.what());
  }
}

Status ConfigNode::Merge(const ConfigNode& overrides) {
  try {
    if (!overrides.IsDefined() || overrides.IsNull()) return Status::Ok();
    if (!overrides.IsMap()) {
      return overrides.impl_->Mismatch(overrides.Where(), "a map", "a map of overrides");
    }
    if (!IsMap() && !IsNull()) return impl_->Mismatch(Where(), "a map", "a map to merge into");
    const ConfigNode source = overrides.Clone();
    if (!source.IsMap()) return Internal(overrides.Where() + ": cannot copy the overrides");
    // Replaced, not filled: an empty value may share its data with the document it was cloned
    // from.
    if (IsNull()) Replace(impl_->node, YAML::Node(YAML::NodeType::Map));
    Impl::MergeMaps(*impl_, *source.impl_);
    return Status::Ok();
  } catch (const std::exception& e) {
    return Internal(Where() + ": merging " + overrides.Where() + ": " + e.what());
  }
}

std::string ConfigNode::Dump() const {
  try {
    if (!IsDefined()) return "";
    YAML::Emitter out;
    out << impl_->node;
    return out.c_str();
  } catch (const std::exception&) {
    return "";
  }
}

ConfigNode ConfigNode::Clone() const {
  auto impl = std::make_shared<Impl>(*impl_);
  impl->doc = std::make_shared<Document>(*impl_->doc);
  try {
    // Documents only grow deeper than kMaxDepth through many Set() calls; such a copy fails
    // rather than overflow the stack, and the clone is then undefined.
    size_t budget = std::numeric_limits<size_t>::max();
    std::optional<YAML::Node> copy = Copy(impl_->node, 4 * kMaxDepth, &budget);
    impl->node.reset(copy ? *copy : YAML::Node(YAML::NodeType::Undefined));
  } catch (const std::exception&) {
    impl->node.reset(YAML::Node(YAML::NodeType::Undefined));
  }
  return ConfigNode(std::move(impl));
}

// ---------------------------------------------------------------------------------------------

struct ConfigReader::Impl {
  struct Error {
    uint64_t sequence;
    Status status;
  };

  ConfigNode node;
  std::vector<std::string> known;               // keys asked for, in order, for messages
  std::map<std::string, std::string> expected;  // what Read* expected, for Require()
  std::map<std::string, std::unique_ptr<ConfigReader>> sections;
  std::optional<Error> first_error;

  void Record(Status status) {
    if (!first_error) first_error = Error{g_error_sequence.fetch_add(1), std::move(status)};
  }

  void Know(const std::string& key, const std::string& what) {
    if (std::find(known.begin(), known.end(), key) == known.end()) known.push_back(key);
    if (!what.empty()) expected[key] = what;
  }

  // Reads `key` through `convert` (ConfigNode -> Result<T>). An absent key leaves *out alone.
  template <typename T, typename Convert>
  void ReadWith(const std::string& key, const std::string& what, T* out, Convert convert) {
    Know(key, what);
    const ConfigNode child = node.Child(key);
    if (!child.IsDefined()) return;
    Result<T> value = convert(child);
    if (!value.ok()) return Record(value.status());
    *out = std::move(*value);
  }

  // The earliest error of this reader and its sections.
  const Error* FirstError() const {
    const Error* first = first_error ? &*first_error : nullptr;
    for (const auto& [key, section] : sections) {
      const Error* error = section->impl_->FirstError();
      if (error && (!first || error->sequence < first->sequence)) first = error;
    }
    return first;
  }

  // Unknown, duplicate and non-name keys, in document order, sections included.
  Status CheckKeys() const {
    const ConfigNode::Impl& map = *node.impl_;
    if (!map.node.IsMap()) return Status::Ok();
    std::set<std::string> seen;
    for (const auto& entry : map.node) {
      if (!entry.first.IsScalar()) {
        return Problem(StatusCode::kInvalidArgument, node.Where(),
                       "has a key that is " +
                           std::string(entry.first.IsNull() ? "empty" : "not a name") +
                           ", expected plain key names");
      }
      const std::string key = entry.first.Scalar();
      const ConfigNode child = map.Entry(entry.first, entry.second);
      if (!seen.insert(key).second) {
        return Problem(StatusCode::kInvalidArgument, child.Where(),
                       "duplicate key, expected each key once");
      }
      if (std::find(known.begin(), known.end(), key) == known.end()) {
        return Problem(StatusCode::kInvalidArgument, child.Where(),
                       "unknown key (known: " + (known.empty() ? "none" : Join(known)) + ")");
      }
      auto section = sections.find(key);
      if (section != sections.end()) INSITU_RETURN_IF_ERROR(section->second->impl_->CheckKeys());
    }
    return Status::Ok();
  }
};

ConfigReader::ConfigReader(const ConfigNode& node) : impl_(std::make_unique<Impl>()) {
  impl_->node = node;
  // An empty value ("scan:" with everything commented out) reads as an empty map.
  if (node.IsDefined() && !node.IsMap() && !node.IsNull()) {
    impl_->Record(node.impl_->Mismatch(node.Where(), "a map", "a map"));
  }
}

ConfigReader::~ConfigReader() = default;

bool ConfigReader::Has(const std::string& key) const { return impl_->node.Child(key).IsDefined(); }

void ConfigReader::Read(const std::string& key, double* out) {
  impl_->ReadWith(key, "a number", out, [](const ConfigNode& n) { return n.AsDouble(); });
}

void ConfigReader::Read(const std::string& key, int* out) {
  impl_->ReadWith(key, "an integer", out, [](const ConfigNode& n) -> Result<int> {
    Result<int64_t> value = n.AsInt();
    if (!value.ok()) return value.status();
    constexpr int64_t kMin = std::numeric_limits<int>::min();
    constexpr int64_t kMax = std::numeric_limits<int>::max();
    if (*value < kMin || *value > kMax) {
      return Problem(StatusCode::kOutOfRange, n.Where(),
                     std::to_string(*value) + " is out of range, expected an integer from " +
                         std::to_string(kMin) + " to " + std::to_string(kMax));
    }
    return static_cast<int>(*value);
  });
}

void ConfigReader::Read(const std::string& key, bool* out) {
  impl_->ReadWith(key, "true or false", out, [](const ConfigNode& n) { return n.AsBool(); });
}

void ConfigReader::Read(const std::string& key, std::string* out) {
  impl_->ReadWith(key, "a string", out, [](const ConfigNode& n) { return n.AsString(); });
}

void ConfigReader::Read(const std::string& key, std::vector<double>* out) {
  impl_->ReadWith(key, "a list of numbers", out,
                  [](const ConfigNode& n) { return n.AsDoubleList(); });
}

void ConfigReader::ReadArray(const std::string& key, double* out, size_t n) {
  const std::string what = "a list of " + std::to_string(n) + " numbers";
  std::vector<double> values;
  impl_->ReadWith(key, what, &values, [&](const ConfigNode& node) -> Result<std::vector<double>> {
    Result<std::vector<double>> list = node.AsDoubleList();
    if (list.ok() && list->size() != n) {
      return Problem(StatusCode::kInvalidArgument, node.Where(),
                     "has " + std::to_string(list->size()) + " numbers, expected " + what);
    }
    return list;
  });
  if (values.size() == n) std::copy(values.begin(), values.end(), out);
}

void ConfigReader::ReadEnum(const std::string& key, std::string* out,
                            const std::vector<std::string>& allowed) {
  const std::string what = "one of: " + Join(allowed);
  impl_->ReadWith(key, what, out, [&](const ConfigNode& node) -> Result<std::string> {
    if (!node.IsScalar()) return node.impl_->Mismatch(node.Where(), what, what);
    Result<std::string> value = node.AsString();
    if (value.ok() && std::find(allowed.begin(), allowed.end(), *value) == allowed.end()) {
      return Problem(StatusCode::kInvalidArgument, node.Where(),
                     Quote(*value) + " is not allowed, expected " + what);
    }
    return value;
  });
}

void ConfigReader::Require(const std::string& key) {
  impl_->Know(key, "");
  const ConfigNode child = impl_->node.Child(key);
  if (child.IsDefined()) return;
  auto it = impl_->expected.find(key);
  impl_->Record(Problem(
      StatusCode::kNotFound, child.Where(),
      "missing, expected " + (it != impl_->expected.end() ? it->second : std::string("a value"))));
}

ConfigReader& ConfigReader::Section(const std::string& key) {
  auto it = impl_->sections.find(key);
  if (it != impl_->sections.end()) return *it->second;
  impl_->Know(key, "a map");
  auto section = std::make_unique<ConfigReader>(impl_->node.Child(key));
  return *impl_->sections.emplace(key, std::move(section)).first->second;
}

void ConfigReader::Skip(const std::string& key) { impl_->Know(key, ""); }

void ConfigReader::Fail(const std::string& key, const std::string& message) {
  impl_->Record(Problem(StatusCode::kInvalidArgument, impl_->node.Child(key).Where(), message));
}

void ConfigReader::FailFromValidate(const Status& status) {
  if (status.ok()) return;
  const std::string& message = status.message();
  // "exposure_ms must be positive" or "galvo.field_mm: too large": the first word names a key.
  std::string name = message.substr(0, message.find(' '));
  while (!name.empty() && (name.back() == ':' || name.back() == ',')) name.pop_back();
  ConfigNode target = impl_->node;
  bool found = !name.empty();
  for (size_t begin = 0; found;) {
    const size_t dot = name.find('.', begin);
    const std::string key = name.substr(begin, dot == std::string::npos ? dot : dot - begin);
    target = target.Child(key);
    found = !key.empty() && target.IsDefined();
    if (dot == std::string::npos) break;
    begin = dot + 1;
  }
  if (found) {
    impl_->Record(Status(status.code(), target.Where() + message.substr(name.size())));
  } else {
    impl_->Record(Problem(status.code(), impl_->node.Where(), message));
  }
}

bool ConfigReader::ok() const { return impl_->FirstError() == nullptr; }

Status ConfigReader::Finish() {
  if (const Impl::Error* error = impl_->FirstError()) return error->status;
  Status status = impl_->CheckKeys();
  if (!status.ok()) impl_->Record(status);
  return status;
}

const ConfigNode& ConfigReader::node() const { return impl_->node; }

}  // namespace insitu
