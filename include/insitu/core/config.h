// Strict reading of YAML configuration (job files, world files, calibration files).
//
// ConfigNode is a node of a parsed YAML document that remembers where it came from (file and
// line, dotted key path), so every error names the file, the line and the key. ConfigReader
// reads the keys of one map into plain values and Options structs and, at Finish(), refuses
// any key it was never asked for ("unknown key"), so a typo in a job file is an error, not a
// silently ignored setting. yaml-cpp stays behind this header.
//
// Error messages have the form
//   "<file>:<line>: <dotted.key>: <what is wrong>, expected <what>"
// (line omitted where unknown, e.g. values set with --set, which are named "--set key=value").
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "insitu/core/status.h"

namespace insitu {

class ConfigNode {
 public:
  ConfigNode();  // an undefined node
  ~ConfigNode();
  ConfigNode(const ConfigNode&);
  ConfigNode& operator=(const ConfigNode&);

  // Parses a whole file. Errors: not_found (cannot open), parse_error (malformed YAML,
  // with the line).
  static Result<ConfigNode> LoadFile(const std::string& path);
  // Parses text; `origin` names it in messages (a file name, "--set", "<request>").
  static Result<ConfigNode> Parse(const std::string& text, const std::string& origin);

  bool IsDefined() const;  // false for a missing key
  bool IsMap() const;
  bool IsSequence() const;
  bool IsScalar() const;
  bool IsNull() const;

  // Child of a map (undefined node if absent or if this is not a map). Keeps origin and path.
  ConfigNode Child(const std::string& key) const;
  // Element of a sequence.
  ConfigNode At(size_t index) const;
  size_t size() const;                    // elements of a sequence or entries of a map
  std::vector<std::string> Keys() const;  // keys of a map, in document order

  // Scalar conversions; errors name the place and the expected type.
  Result<double> AsDouble() const;  // rejects nan/inf
  Result<int64_t> AsInt() const;
  Result<bool> AsBool() const;      // true/false only
  Result<std::string> AsString() const;
  Result<std::vector<double>> AsDoubleList() const;

  // "<file>:<line>: <path>" (or "<file>: <path>" when the line is unknown).
  std::string Where() const;
  const std::string& file() const;
  const std::string& path() const;  // dotted key path from the document root ("" for root)
  int line() const;                 // 1-based, 0 if unknown

  // Sets a value by dotted key ("world.camera.k1"), creating intermediate maps; `value_text`
  // is parsed as a YAML scalar or flow sequence ("[1, 2]"). The node is then reported as
  // "--set world.camera.k1=<value>". Errors: invalid_argument (empty key part, value
  // not parseable, a path going through a scalar or sequence).
  Status Set(const std::string& dotted_key, const std::string& value_text);

  // Copies every entry of `overrides` (a map) into this map, recursively for maps; scalars and
  // sequences replace. Origins of merged entries are kept.
  Status Merge(const ConfigNode& overrides);

  // This node as YAML text.
  std::string Dump() const;

  // Deep copy (Child() shares the underlying document; Clone() does not).
  ConfigNode Clone() const;

 private:
  struct Impl;
  explicit ConfigNode(std::shared_ptr<Impl> impl);
  std::shared_ptr<Impl> impl_;
  friend class ConfigReader;
};

// Reads one map strictly. All Read* calls leave *out unchanged when the key is absent (so
// Options defaults stay), and record the first error otherwise. Finish() returns that error,
// or an "unknown key" error for any key of this map (and of any Section() taken from it) that
// no Read*/Section call asked for.
class ConfigReader {
 public:
  explicit ConfigReader(const ConfigNode& node);
  ~ConfigReader();
  ConfigReader(const ConfigReader&) = delete;
  ConfigReader& operator=(const ConfigReader&) = delete;

  bool Has(const std::string& key) const;

  void Read(const std::string& key, double* out);
  void Read(const std::string& key, int* out);
  void Read(const std::string& key, bool* out);
  void Read(const std::string& key, std::string* out);
  void Read(const std::string& key, std::vector<double>* out);
  // A fixed-size list, e.g. a position [x, y, z].
  void ReadArray(const std::string& key, double* out, size_t n);
  // One of `allowed` (error lists them).
  void ReadEnum(const std::string& key, std::string* out, const std::vector<std::string>& allowed);
  // Records an error unless the key is present.
  void Require(const std::string& key);

  // A reader for a child map; its unknown keys are checked by this reader's Finish().
  // An absent child gives a reader over an empty map. A child that is not a map is an error.
  ConfigReader& Section(const std::string& key);
  // Marks a key as known without reading it (handled elsewhere).
  void Skip(const std::string& key);

  // Records an error about `key` ("<where>: <key>: <message>"); for range checks done by
  // the caller, or to attach a Validate() message to the right place.
  void Fail(const std::string& key, const std::string& message);
  // Attaches an Options::Validate() failure: if its message starts with the name of a key of
  // this map, the error points at that key's line; otherwise at the map.
  void FailFromValidate(const Status& status);

  bool ok() const;
  Status Finish();

  const ConfigNode& node() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace insitu
