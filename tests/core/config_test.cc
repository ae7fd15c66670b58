#include "insitu/core/config.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

namespace insitu {
namespace {

::testing::AssertionResult Contains(const std::string& text, const std::string& part) {
  if (text.find(part) != std::string::npos) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << '"' << text << "\" does not contain \"" << part << '"';
}

ConfigNode MustParse(const std::string& text, const std::string& origin = "job.yaml") {
  Result<ConfigNode> parsed = ConfigNode::Parse(text, origin);
  EXPECT_TRUE(parsed.ok()) << parsed.status().ToString();
  return parsed.ok() ? *parsed : ConfigNode();
}

// The options of a scan, as a module would read them.
struct ScanOptions {
  double exposure_ms = 10;
  double line_spacing_mm = 0.1;
  int passes = 1;
  bool bidirectional = false;
  std::string mode = "raster";

  Status Validate() const {
    if (exposure_ms <= 0) {
      return OutOfRange("exposure_ms must be positive, got " + std::to_string(exposure_ms));
    }
    if (passes < 1) return OutOfRange("passes must be at least 1");
    return Status::Ok();
  }
};

void ReadScan(ConfigReader& reader, ScanOptions* options) {
  reader.Read("exposure_ms", &options->exposure_ms);
  reader.Read("line_spacing_mm", &options->line_spacing_mm);
  reader.Read("passes", &options->passes);
  reader.Read("bidirectional", &options->bidirectional);
  reader.ReadEnum("mode", &options->mode, {"raster", "vector"});
}

// --- Parsing ------------------------------------------------------------------------------------

TEST(ConfigParse, MalformedYamlIsParseErrorWithLine) {
  Result<ConfigNode> parsed = ConfigNode::Parse("a: 1\nb: [1, 2\nc: 3\n", "job.yaml");
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().code(), StatusCode::kParseError);
  EXPECT_EQ(parsed.status().message().rfind("job.yaml:", 0), 0u) << parsed.status().message();
  EXPECT_TRUE(Contains(parsed.status().message(), "expected valid YAML"));

  parsed = ConfigNode::Parse("a: 1\nb:\n  c: 1\n d: 2\n", "job.yaml");
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().message().rfind("job.yaml:4: ", 0), 0u) << parsed.status().message();
}

TEST(ConfigParse, SeveralDocumentsAreRefused) {
  Result<ConfigNode> parsed = ConfigNode::Parse("a: 1\n---\na: 2\n", "job.yaml");
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().code(), StatusCode::kParseError);
  EXPECT_TRUE(Contains(parsed.status().message(), "job.yaml: holds several YAML documents"));
}

TEST(ConfigParse, InputsThatStallYamlCppAreParseErrors) {
  Result<ConfigNode> parsed = ConfigNode::Parse(",", "job.yaml");
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().code(), StatusCode::kParseError);
  EXPECT_EQ(parsed.status().message().rfind("job.yaml:1: ", 0), 0u) << parsed.status().message();
  EXPECT_FALSE(MustParse("a: 1\n").Set("a", ",").ok());
}

TEST(ConfigParse, EmptyDocumentReadsAsEmptyMap) {
  ConfigNode root = MustParse("# nothing yet\n");
  EXPECT_TRUE(root.IsDefined());
  EXPECT_TRUE(root.IsNull());
  ConfigReader reader(root);
  double exposure_ms = 3;
  reader.Read("exposure_ms", &exposure_ms);
  EXPECT_EQ(exposure_ms, 3);
  EXPECT_TRUE(reader.Finish().ok());
}

TEST(ConfigParse, AliasCyclesAndBombsAreRefused) {
  Result<ConfigNode> cycle = ConfigNode::Parse("a: &x [1, *x]\n", "job.yaml");
  ASSERT_FALSE(cycle.ok());
  EXPECT_EQ(cycle.status().code(), StatusCode::kParseError);

  // Each level repeats the one before four times: 8 * 4^11 values from a few hundred bytes.
  std::string bomb = "a: &a [x, x, x, x, x, x, x, x]\n";
  for (char name = 'b'; name < 'm'; ++name) {
    const char prev = static_cast<char>(name - 1);
    const std::string reference = {'*', prev};
    bomb += {name, ':', ' ', '&', name, ' ', '['};
    bomb += reference + "," + reference + "," + reference + "," + reference + "]\n";
  }
  Result<ConfigNode> parsed = ConfigNode::Parse(bomb, "job.yaml");
  ASSERT_FALSE(parsed.ok());
  EXPECT_TRUE(Contains(parsed.status().message(), "job.yaml: "));
}

TEST(ConfigParse, AliasesBecomeIndependentCopies) {
  ConfigNode root = MustParse("defaults: &d {speed: 1}\nfast: *d\n");
  ASSERT_TRUE(root.Set("fast.speed", "5").ok());
  EXPECT_EQ(*root.Child("fast").Child("speed").AsInt(), 5);
  EXPECT_EQ(*root.Child("defaults").Child("speed").AsInt(), 1);
}

TEST(ConfigParse, LoadFileNamesTheFile) {
  const std::string path = ::testing::TempDir() + "/insitu_config_test_job.yaml";
  {
    std::ofstream out(path);
    out << "scan:\n  exposure_ms: abc\n";
  }
  Result<ConfigNode> loaded = ConfigNode::LoadFile(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(loaded->file(), path);
  Result<double> exposure = loaded->Child("scan").Child("exposure_ms").AsDouble();
  ASSERT_FALSE(exposure.ok());
  EXPECT_EQ(exposure.status().message(),
            path + ":2: scan.exposure_ms: \"abc\" is not a number, expected a number");
  std::filesystem::remove(path);
}

TEST(ConfigParse, LoadFileMissingIsNotFound) {
  Result<ConfigNode> loaded = ConfigNode::LoadFile("/nonexistent/job.yaml");
  ASSERT_FALSE(loaded.ok());
  EXPECT_EQ(loaded.status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(Contains(loaded.status().message(), "/nonexistent/job.yaml: cannot open"));

  loaded = ConfigNode::LoadFile(::testing::TempDir());
  ASSERT_FALSE(loaded.ok());
  EXPECT_EQ(loaded.status().code(), StatusCode::kNotFound);
}

// --- Navigation ---------------------------------------------------------------------------------

TEST(ConfigNode, ChildKeepsFileLineAndPath) {
  ConfigNode root = MustParse("name: demo\nscan:\n  exposure_ms: 5\n  lines: [1, 2]\n");
  EXPECT_EQ(root.Where(), "job.yaml");
  ConfigNode exposure = root.Child("scan").Child("exposure_ms");
  EXPECT_EQ(exposure.file(), "job.yaml");
  EXPECT_EQ(exposure.path(), "scan.exposure_ms");
  EXPECT_EQ(exposure.line(), 3);
  EXPECT_EQ(exposure.Where(), "job.yaml:3: scan.exposure_ms");
  EXPECT_EQ(root.Child("scan").Where(), "job.yaml:2: scan");
  EXPECT_EQ(root.Child("scan").Child("lines").At(1).Where(), "job.yaml:4: scan.lines[1]");
}

TEST(ConfigNode, MissingChildIsUndefinedAndPlacedAtItsMap) {
  ConfigNode root = MustParse("scan:\n  exposure_ms: 5\n");
  ConfigNode missing = root.Child("scan").Child("passes");
  EXPECT_FALSE(missing.IsDefined());
  EXPECT_EQ(missing.Where(), "job.yaml:1: scan.passes");
  EXPECT_FALSE(root.Child("scan").Child("exposure_ms").Child("x").IsDefined());
  EXPECT_FALSE(root.Child("scan").At(0).IsDefined());
  Result<double> value = missing.AsDouble();
  ASSERT_FALSE(value.ok());
  EXPECT_EQ(value.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(value.status().message(), "job.yaml:1: scan.passes: missing, expected a number");
}

TEST(ConfigNode, KeysAndSizes) {
  ConfigNode root = MustParse("zeta: 1\nalpha: 2\nmid: [1, 2, 3]\nempty:\n");
  EXPECT_EQ(root.Keys(), (std::vector<std::string>{"zeta", "alpha", "mid", "empty"}));
  EXPECT_EQ(root.size(), 4u);
  EXPECT_EQ(root.Child("mid").size(), 3u);
  EXPECT_EQ(root.Child("zeta").size(), 0u);
  EXPECT_TRUE(root.Child("empty").IsNull());
  EXPECT_TRUE(root.Child("mid").IsSequence());
  EXPECT_TRUE(root.Child("zeta").IsScalar());
  EXPECT_TRUE(root.IsMap());
}

// --- Conversions --------------------------------------------------------------------------------

TEST(ConfigNode, AsDouble) {
  ConfigNode root = MustParse("a: 5\nb: -0.08\nc: 1e-3\nd: +2.5\ne: abc\nf: [1]\ng:\n");
  EXPECT_EQ(*root.Child("a").AsDouble(), 5);
  EXPECT_EQ(*root.Child("b").AsDouble(), -0.08);
  EXPECT_EQ(*root.Child("c").AsDouble(), 1e-3);
  EXPECT_EQ(*root.Child("d").AsDouble(), 2.5);
  EXPECT_EQ(root.Child("e").AsDouble().status().message(),
            "job.yaml:5: e: \"abc\" is not a number, expected a number");
  EXPECT_EQ(root.Child("f").AsDouble().status().message(),
            "job.yaml:6: f: is a list, expected a number");
  EXPECT_EQ(root.Child("g").AsDouble().status().message(),
            "job.yaml:7: g: is empty, expected a number");
}

TEST(ConfigNode, AsDoubleRejectsNanAndInfinity) {
  for (const char* text : {".nan", ".NaN", "nan", ".inf", "-.inf", "+.Inf", "inf", "-infinity"}) {
    ConfigNode root = MustParse(std::string("x: ") + text + "\n");
    Result<double> value = root.Child("x").AsDouble();
    ASSERT_FALSE(value.ok()) << text;
    EXPECT_TRUE(Contains(value.status().message(), "job.yaml:1: x: "));
    EXPECT_TRUE(Contains(value.status().message(), "is not finite, expected a finite number"));
  }
  Result<double> huge = MustParse("x: 1e999\n").Child("x").AsDouble();
  ASSERT_FALSE(huge.ok());
  EXPECT_EQ(huge.status().code(), StatusCode::kOutOfRange);
}

TEST(ConfigNode, AsInt) {
  ConfigNode root = MustParse("a: 42\nb: -7\nc: 1.5\nd: 0x10\ne: 99999999999999999999\nf: 010\n");
  EXPECT_EQ(*root.Child("a").AsInt(), 42);
  EXPECT_EQ(*root.Child("b").AsInt(), -7);
  EXPECT_EQ(root.Child("c").AsInt().status().message(),
            "job.yaml:3: c: \"1.5\" is not an integer, expected an integer");
  EXPECT_FALSE(root.Child("d").AsInt().ok());
  EXPECT_EQ(root.Child("e").AsInt().status().code(), StatusCode::kOutOfRange);
  EXPECT_EQ(*root.Child("f").AsInt(), 10);  // decimal, as YAML 1.2 reads it
}

TEST(ConfigNode, AsBoolTakesOnlyTrueAndFalse) {
  ConfigNode root = MustParse("a: true\nb: false\n");
  EXPECT_TRUE(*root.Child("a").AsBool());
  EXPECT_FALSE(*root.Child("b").AsBool());
  for (const char* text : {"yes", "no", "on", "off", "True", "1", "y"}) {
    Result<bool> value = MustParse(std::string("x: ") + text + "\n").Child("x").AsBool();
    ASSERT_FALSE(value.ok()) << text;
    EXPECT_EQ(value.status().message(), std::string("job.yaml:1: x: \"") + text +
                                            "\" is not true or false, expected true or false");
  }
}

TEST(ConfigNode, AsString) {
  ConfigNode root = MustParse("a: hello world\nb: 5\nc: {d: 1}\n");
  EXPECT_EQ(*root.Child("a").AsString(), "hello world");
  EXPECT_EQ(*root.Child("b").AsString(), "5");
  EXPECT_EQ(root.Child("c").AsString().status().message(),
            "job.yaml:3: c: is a map, expected a string");
}

TEST(ConfigNode, AsDoubleList) {
  ConfigNode root = MustParse("a: [1, 2.5, -3]\nb: []\nc:\n  - 1\n  - abc\nd: 5\ne: [1, .nan]\n");
  EXPECT_EQ(*root.Child("a").AsDoubleList(), (std::vector<double>{1, 2.5, -3}));
  EXPECT_TRUE(root.Child("b").AsDoubleList()->empty());
  EXPECT_EQ(root.Child("c").AsDoubleList().status().message(),
            "job.yaml:5: c[1]: \"abc\" is not a number, expected a number");
  EXPECT_EQ(root.Child("d").AsDoubleList().status().message(),
            "job.yaml:6: d: \"5\" is not a list, expected a list of numbers");
  EXPECT_FALSE(root.Child("e").AsDoubleList().ok());
}

TEST(ConfigNode, LongAndOddScalarsAreShortenedInMessages) {
  const std::string text = "x: \"" + std::string(100, 'z') + "\\n\"\n";
  Result<double> value = MustParse(text).Child("x").AsDouble();
  ASSERT_FALSE(value.ok());
  EXPECT_TRUE(Contains(value.status().message(), "zzz...\" is not a number"));
  EXPECT_LT(value.status().message().size(), 120u);
}

// --- ConfigReader -------------------------------------------------------------------------------

TEST(ConfigReader, ReadsValuesAndKeepsDefaultsForAbsentKeys) {
  ConfigNode root = MustParse(
      "exposure_ms: 2.5\npasses: 3\nbidirectional: true\nmode: vector\n"
      "origin: [1, 2, 3]\nname: cube\nweights: [0.5]\n");
  ConfigReader reader(root);
  ScanOptions options;
  ReadScan(reader, &options);
  double origin[3] = {0, 0, 0};
  reader.ReadArray("origin", origin, 3);
  std::string name;
  reader.Read("name", &name);
  std::vector<double> weights;
  reader.Read("weights", &weights);
  ASSERT_TRUE(reader.Finish().ok()) << reader.Finish().ToString();
  EXPECT_EQ(options.exposure_ms, 2.5);
  EXPECT_EQ(options.line_spacing_mm, 0.1);  // absent: default stays
  EXPECT_EQ(options.passes, 3);
  EXPECT_TRUE(options.bidirectional);
  EXPECT_EQ(options.mode, "vector");
  EXPECT_EQ(origin[2], 3);
  EXPECT_EQ(name, "cube");
  EXPECT_EQ(weights, std::vector<double>{0.5});
  EXPECT_TRUE(reader.Has("name"));
  EXPECT_FALSE(reader.Has("line_spacing_mm"));
}

TEST(ConfigReader, UnknownKeyListsTheKnownOnes) {
  ConfigNode root = MustParse("scan:\n  exposure_ms: 5\n  line_spacing_mm: 0.1\n  exposre_ms: 4\n");
  ConfigReader reader(root);
  ConfigReader& scan = reader.Section("scan");
  double exposure_ms = 0;
  double line_spacing_mm = 0;
  scan.Read("exposure_ms", &exposure_ms);
  scan.Read("line_spacing_mm", &line_spacing_mm);
  EXPECT_TRUE(reader.ok());
  Status status = reader.Finish();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(status.message(),
            "job.yaml:4: scan.exposre_ms: unknown key (known: exposure_ms, line_spacing_mm)");
  EXPECT_FALSE(reader.ok());
  EXPECT_EQ(exposure_ms, 5);
}

TEST(ConfigReader, WrongTypeLeavesValueAndFinishReturnsFirstError) {
  ConfigNode root = MustParse("exposure_ms: abc\npasses: 1.5\nbidirectional: yes\nextra: 1\n");
  ConfigReader reader(root);
  ScanOptions options;
  ReadScan(reader, &options);
  EXPECT_FALSE(reader.ok());
  EXPECT_EQ(options.exposure_ms, 10);
  EXPECT_EQ(options.passes, 1);
  EXPECT_FALSE(options.bidirectional);
  Status status = reader.Finish();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(status.message(),
            "job.yaml:1: exposure_ms: \"abc\" is not a number, expected a number");
  EXPECT_EQ(reader.Finish().message(), status.message());  // stable
}

TEST(ConfigReader, IntRangeArraySizeAndEnum) {
  ConfigNode root = MustParse("passes: 3000000000\norigin: [1, 2]\nmode: fast\n");
  {
    ConfigReader reader(root);
    int passes = 1;
    reader.Read("passes", &passes);
    EXPECT_EQ(passes, 1);
    EXPECT_EQ(reader.Finish().message(),
              "job.yaml:1: passes: 3000000000 is out of range, expected an integer from "
              "-2147483648 to 2147483647");
  }
  {
    ConfigReader reader(root);
    double origin[3] = {7, 7, 7};
    reader.ReadArray("origin", origin, 3);
    EXPECT_EQ(origin[0], 7);
    EXPECT_EQ(reader.Finish().message(),
              "job.yaml:2: origin: has 2 numbers, expected a list of 3 numbers");
  }
  {
    ConfigReader reader(root);
    std::string mode = "raster";
    reader.ReadEnum("mode", &mode, {"raster", "vector"});
    EXPECT_EQ(mode, "raster");
    EXPECT_EQ(reader.Finish().message(),
              "job.yaml:3: mode: \"fast\" is not allowed, expected one of: raster, vector");
  }
}

TEST(ConfigReader, RequireNamesTheExpectedType) {
  ConfigNode root = MustParse("scan:\n  passes: 2\n");
  ConfigReader reader(root);
  ConfigReader& scan = reader.Section("scan");
  double exposure_ms = 0;
  scan.Read("exposure_ms", &exposure_ms);
  scan.Require("exposure_ms");
  scan.Skip("passes");
  Status status = reader.Finish();
  EXPECT_EQ(status.code(), StatusCode::kNotFound);
  EXPECT_EQ(status.message(), "job.yaml:1: scan.exposure_ms: missing, expected a number");

  ConfigReader empty(MustParse("{}"));
  ConfigReader& galvo = empty.Section("galvo");
  galvo.Require("field_mm");
  EXPECT_EQ(empty.Finish().message(), "job.yaml: galvo.field_mm: missing, expected a value");
}

TEST(ConfigReader, SectionsNestAndCheckTheirKeys) {
  ConfigNode root = MustParse(
      "world:\n"
      "  camera:\n"
      "    k1: 0.1\n"
      "    k9: 0.2\n"
      "  stage: {travel_mm: 100}\n"
      "job: {}\n");
  ConfigReader reader(root);
  ConfigReader& world = reader.Section("world");
  ConfigReader& camera = world.Section("camera");
  EXPECT_EQ(&world.Section("camera"), &camera);
  EXPECT_EQ(&reader.Section("world"), &world);
  double k1 = 0;
  camera.Read("k1", &k1);
  double travel_mm = 0;
  world.Section("stage").Read("travel_mm", &travel_mm);
  reader.Skip("job");
  EXPECT_EQ(camera.node().path(), "world.camera");
  EXPECT_TRUE(reader.ok());
  EXPECT_EQ(reader.Finish().message(), "job.yaml:4: world.camera.k9: unknown key (known: k1)");
  EXPECT_EQ(camera.Finish().message(), "job.yaml:4: world.camera.k9: unknown key (known: k1)");
  EXPECT_EQ(k1, 0.1);
  EXPECT_EQ(travel_mm, 100);
}

TEST(ConfigReader, UnknownKeysAreReportedInDocumentOrder) {
  ConfigNode root = MustParse("a:\n  typo: 1\nb: 2\ntypo2: 3\n");
  ConfigReader reader(root);
  reader.Section("a");
  int b = 0;
  reader.Read("b", &b);
  EXPECT_EQ(reader.Finish().message(), "job.yaml:2: a.typo: unknown key (known: none)");
}

TEST(ConfigReader, ErrorsComeInCallOrderAcrossSections) {
  ConfigNode root = MustParse("a:\n  x: abc\nb: abc\n");
  ConfigReader reader(root);
  double value = 0;
  reader.Read("b", &value);
  reader.Section("a").Read("x", &value);
  EXPECT_EQ(reader.Finish().message(), "job.yaml:3: b: \"abc\" is not a number, expected a number");
  EXPECT_FALSE(reader.Section("a").ok());
}

TEST(ConfigReader, SectionShapes) {
  ConfigNode root = MustParse("list: [1, 2]\nempty:\n");
  ConfigReader reader(root);
  double x = 4;
  reader.Section("absent").Read("x", &x);
  reader.Section("empty").Read("x", &x);
  EXPECT_EQ(x, 4);
  EXPECT_TRUE(reader.ok());
  reader.Section("list").Read("x", &x);
  EXPECT_FALSE(reader.ok());
  EXPECT_EQ(reader.Finish().message(), "job.yaml:1: list: is a list, expected a map");

  ConfigReader top(MustParse("[1, 2]"));
  EXPECT_EQ(top.Finish().message(), "job.yaml: is a list, expected a map");
}

TEST(ConfigReader, DuplicateAndOddKeys) {
  ConfigReader duplicate(MustParse("a: 1\nb: 2\na: 3\n"));
  duplicate.Skip("a");
  duplicate.Skip("b");
  EXPECT_EQ(duplicate.Finish().message(), "job.yaml:3: a: duplicate key, expected each key once");

  ConfigReader odd(MustParse("? [1, 2]\n: 3\n"));
  EXPECT_TRUE(Contains(odd.Finish().message(), "job.yaml: has a key that is not a name"));
}

TEST(ConfigReader, Fail) {
  ConfigNode root = MustParse("scan:\n  speed: 900\n");
  ConfigReader reader(root);
  ConfigReader& scan = reader.Section("scan");
  double speed = 0;
  scan.Read("speed", &speed);
  scan.Fail("speed", "900 is above the galvo limit, expected at most 500");
  EXPECT_EQ(reader.Finish().message(),
            "job.yaml:2: scan.speed: 900 is above the galvo limit, expected at most 500");
}

TEST(ConfigReader, FailFromValidatePointsAtTheKey) {
  ConfigNode root = MustParse("scan:\n  mode: raster\n  exposure_ms: -5\n");
  ConfigReader reader(root);
  ConfigReader& scan = reader.Section("scan");
  ScanOptions options;
  ReadScan(scan, &options);
  scan.FailFromValidate(options.Validate());
  Status status = reader.Finish();
  EXPECT_EQ(status.code(), StatusCode::kOutOfRange);  // the code of Validate()
  EXPECT_EQ(status.message(), "job.yaml:3: scan.exposure_ms must be positive, got -5.000000");
}

TEST(ConfigReader, FailFromValidateFallsBackToTheMap) {
  ConfigNode root = MustParse("scan:\n  mode: raster\n");
  ConfigReader reader(root);
  ConfigReader& scan = reader.Section("scan");
  ScanOptions options;
  options.passes = 0;  // a bad default, not from the file
  ReadScan(scan, &options);
  scan.FailFromValidate(options.Validate());
  EXPECT_EQ(reader.Finish().message(), "job.yaml:1: scan: passes must be at least 1");

  ConfigReader top(MustParse("galvo:\n  field_mm: 400\n"));
  top.Skip("galvo");
  top.FailFromValidate(OutOfRange("galvo.field_mm: 400 is larger than the lens"));
  EXPECT_EQ(top.Finish().message(), "job.yaml:2: galvo.field_mm: 400 is larger than the lens");

  ConfigReader ok_reader(MustParse("a: 1\n"));
  ok_reader.Skip("a");
  ok_reader.FailFromValidate(Status::Ok());
  EXPECT_TRUE(ok_reader.Finish().ok());
}

// --- Set, Merge, Clone --------------------------------------------------------------------------

TEST(ConfigSet, CreatesPathsAndReportsTheSetOrigin) {
  ConfigNode root = MustParse("world:\n  camera:\n    k1: 0.1\n");
  ASSERT_TRUE(root.Set("world.camera.k2", "-0.08").ok());
  ASSERT_TRUE(root.Set("world.stage.origin", "[1, 2, 3]").ok());
  ASSERT_TRUE(root.Set("world.camera.k1", "abc").ok());
  ASSERT_TRUE(root.Set("laser.armed", "true").ok());

  ConfigNode camera = root.Child("world").Child("camera");
  EXPECT_EQ(*camera.Child("k2").AsDouble(), -0.08);
  EXPECT_EQ(camera.Child("k2").Where(), "--set world.camera.k2=-0.08: world.camera.k2");
  EXPECT_EQ(camera.Child("k2").line(), 0);
  EXPECT_EQ(camera.Where(), "job.yaml:2: world.camera");  // untouched entries keep their line
  EXPECT_EQ(*root.Child("world").Child("stage").Child("origin").AsDoubleList(),
            (std::vector<double>{1, 2, 3}));
  EXPECT_TRUE(*root.Child("laser").Child("armed").AsBool());

  ConfigReader reader(root);
  double k1 = 0;
  reader.Section("world").Section("camera").Read("k1", &k1);
  EXPECT_EQ(reader.Finish().message(),
            "--set world.camera.k1=abc: world.camera.k1: \"abc\" is not a number, "
            "expected a number");
}

TEST(ConfigSet, UnknownKeyFromSetNamesTheSet) {
  ConfigNode root = MustParse("scan:\n  exposure_ms: 5\n");
  ASSERT_TRUE(root.Set("scan.exposre_ms", "4").ok());
  ConfigReader reader(root);
  double exposure_ms = 0;
  reader.Section("scan").Read("exposure_ms", &exposure_ms);
  EXPECT_EQ(reader.Finish().message(),
            "--set scan.exposre_ms=4: scan.exposre_ms: unknown key (known: exposure_ms)");
}

TEST(ConfigSet, Errors) {
  ConfigNode root = MustParse("a: 1\nb: [1, 2]\nc:\n");
  const std::string before = root.Dump();
  for (const char* key : {"a..b", "", ".a", "a."}) {
    Status status = root.Set(key, "1");
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << key;
    EXPECT_TRUE(Contains(status.message(), "has an empty key part")) << key;
  }
  Status through_scalar = root.Set("a.x", "1");
  EXPECT_EQ(through_scalar.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(through_scalar.message(), "--set a.x=1: a is a scalar, expected a map to set x in");
  EXPECT_TRUE(Contains(root.Set("b.x.y", "1").message(), "b is a list"));
  Status bad_value = root.Set("d", "[1, 2");
  EXPECT_EQ(bad_value.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Contains(bad_value.message(), "--set d=[1, 2:"));
  EXPECT_EQ(root.Dump(), before);  // failed Sets change nothing

  EXPECT_TRUE(root.Set("c.x", "1").ok());  // an empty value becomes a map
  EXPECT_EQ(*root.Child("c").Child("x").AsInt(), 1);
  EXPECT_EQ(root.Child("a").Set("x", "1").message(),
            "--set x=1: job.yaml:1: a: \"1\" is not a map, expected a map to set keys in");
}

TEST(ConfigMerge, MergesRecursively) {
  ConfigNode base = MustParse(
      "scan:\n  exposure_ms: 5\n  passes: 2\n  origin: [0, 0, 0]\nname: base\n", "world.yaml");
  ConfigNode overrides = MustParse(
      "scan:\n  passes: 3\n  origin: [1, 1]\n  extra:\n    deep: true\nlabel: x\n", "job.yaml");
  ASSERT_TRUE(base.Merge(overrides).ok());
  ConfigNode scan = base.Child("scan");
  EXPECT_EQ(*scan.Child("exposure_ms").AsDouble(), 5);
  EXPECT_EQ(*scan.Child("passes").AsInt(), 3);
  EXPECT_EQ(*scan.Child("origin").AsDoubleList(), (std::vector<double>{1, 1}));
  EXPECT_TRUE(*scan.Child("extra").Child("deep").AsBool());
  EXPECT_EQ(*base.Child("label").AsString(), "x");
  EXPECT_EQ(base.Keys(), (std::vector<std::string>{"scan", "name", "label"}));
  EXPECT_EQ(scan.Keys(), (std::vector<std::string>{"exposure_ms", "passes", "origin", "extra"}));

  // Origins are kept: merged entries point into the overrides, the others into the base.
  EXPECT_EQ(scan.Child("exposure_ms").Where(), "world.yaml:2: scan.exposure_ms");
  EXPECT_EQ(scan.Child("passes").Where(), "job.yaml:2: scan.passes");
  EXPECT_EQ(scan.Child("extra").Child("deep").Where(), "job.yaml:5: scan.extra.deep");
  EXPECT_EQ(base.Child("label").Where(), "job.yaml:6: label");

  // The overrides are copied, not shared.
  ASSERT_TRUE(base.Set("scan.passes", "9").ok());
  EXPECT_EQ(*overrides.Child("scan").Child("passes").AsInt(), 3);
}

TEST(ConfigMerge, KeepsSetOriginsOfTheOverrides) {
  ConfigNode base = MustParse("a: {b: 1}\n", "world.yaml");
  ConfigNode overrides = MustParse("{}", "job.yaml");
  ASSERT_TRUE(overrides.Set("a.c", "2").ok());
  ASSERT_TRUE(base.Merge(overrides).ok());
  EXPECT_EQ(base.Child("a").Child("c").Where(), "--set a.c=2: a.c");
  EXPECT_EQ(base.Child("a").Child("b").Where(), "world.yaml:1: a.b");
}

TEST(ConfigMerge, IntoAChildAndErrors) {
  ConfigNode base = MustParse("world:\n  camera: {k1: 1}\nlist: [1]\n", "world.yaml");
  ConfigNode overrides = MustParse("camera: {k1: 2}\n", "job.yaml");
  ASSERT_TRUE(base.Child("world").Merge(overrides).ok());
  EXPECT_EQ(*base.Child("world").Child("camera").Child("k1").AsInt(), 2);
  EXPECT_EQ(base.Child("world").Child("camera").Child("k1").Where(), "job.yaml:1: world.camera.k1");

  Status not_a_map = base.Merge(MustParse("[1, 2]", "job.yaml"));
  EXPECT_EQ(not_a_map.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(not_a_map.message(), "job.yaml: is a list, expected a map of overrides");
  EXPECT_EQ(base.Child("list").Merge(overrides).code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(base.Merge(ConfigNode()).ok());
}

TEST(ConfigMerge, IntoAnEmptyValueSeenThroughTheRoot) {
  ConfigNode root = MustParse("a:\n");
  ConfigNode a = root.Child("a");
  ASSERT_TRUE(a.Set("x", "1").ok());
  ASSERT_TRUE(a.Merge(MustParse("y: 2\n", "more.yaml")).ok());
  EXPECT_EQ(*root.Child("a").Child("x").AsInt(), 1);
  EXPECT_EQ(*root.Child("a").Child("y").AsInt(), 2);
  EXPECT_EQ(root.Child("a").Child("y").Where(), "more.yaml:1: a.y");
}

TEST(ConfigClone, IsDeepAndKeepsLines) {
  ConfigNode original = MustParse("scan:\n  exposure_ms: 5\n  origin: [1, 2]\nempty:\n");
  ConfigNode copy = original.Clone();
  ConfigNode shared = original.Child("scan");
  ASSERT_TRUE(copy.Set("scan.exposure_ms", "7").ok());
  ASSERT_TRUE(copy.Set("scan.new", "1").ok());
  ASSERT_TRUE(copy.Set("empty.x", "1").ok());
  EXPECT_EQ(*original.Child("scan").Child("exposure_ms").AsDouble(), 5);
  EXPECT_FALSE(original.Child("scan").Child("new").IsDefined());
  EXPECT_TRUE(original.Child("empty").IsNull());
  EXPECT_EQ(copy.Child("scan").Child("origin").At(1).Where(), "job.yaml:3: scan.origin[1]");
  ASSERT_TRUE(copy.Merge(MustParse("scan: {exposure_ms: 9, origin: [0]}", "more.yaml")).ok());
  EXPECT_EQ(*original.Child("scan").Child("origin").AsDoubleList(), (std::vector<double>{1, 2}));

  // Child() shares the document.
  ASSERT_TRUE(shared.Set("exposure_ms", "8").ok());
  EXPECT_EQ(*original.Child("scan").Child("exposure_ms").AsDouble(), 8);
}

TEST(ConfigNode, DumpRoundTrips) {
  ConfigNode root = MustParse("a: 1\nb: [1, 2]\nc: {d: text}\n");
  ConfigNode again = MustParse(root.Dump());
  EXPECT_EQ(*again.Child("c").Child("d").AsString(), "text");
  EXPECT_EQ(*again.Child("b").AsDoubleList(), (std::vector<double>{1, 2}));
  EXPECT_EQ(ConfigNode().Dump(), "");
}

// Ways to read scan.x, for the test below.
template <typename T>
void ReadX(ConfigReader& reader) {
  T value{};
  reader.Section("scan").Read("x", &value);
}
void ReadArrayX(ConfigReader& reader) {
  double values[2] = {};
  reader.Section("scan").ReadArray("x", values, 2);
}
void ReadEnumX(ConfigReader& reader) {
  std::string value;
  reader.Section("scan").ReadEnum("x", &value, {"a"});
}
void RequireX(ConfigReader& reader) { reader.Section("scan").Require("x"); }
void IgnoreX(ConfigReader& reader) { reader.Section("scan"); }
void SectionX(ConfigReader& reader) { reader.Section("scan").Section("x"); }
void FailX(ConfigReader& reader) { reader.Section("scan").Fail("x", "bad"); }
void ValidateX(ConfigReader& reader) {
  reader.Section("scan").FailFromValidate(InvalidArgument("x bad"));
}

// Every error names the file and the dotted key.
TEST(ConfigErrors, NameFileAndKey) {
  const std::pair<const char*, void (*)(ConfigReader&)> cases[] = {
      {"scan: {x: abc}", ReadX<double>},
      {"scan: {x: 1.5}", ReadX<int>},
      {"scan: {x: maybe}", ReadX<bool>},
      {"scan: {x: {y: 1}}", ReadX<std::string>},
      {"scan: {x: [a]}", ReadX<std::vector<double>>},
      {"scan: {x: [1]}", ReadArrayX},
      {"scan: {x: q}", ReadEnumX},
      {"scan: {y: 1}", RequireX},
      {"scan: {x: 1}", IgnoreX},
      {"scan: {x: 1}", SectionX},
      {"scan: {x: 1}", FailX},
      {"scan: {x: 1}", ValidateX},
  };
  for (const auto& [yaml, read] : cases) {
    ConfigReader reader(MustParse(yaml, "job.yaml"));
    read(reader);
    Status status = reader.Finish();
    EXPECT_FALSE(status.ok()) << yaml;
    EXPECT_TRUE(Contains(status.message(), "job.yaml")) << yaml;
    EXPECT_TRUE(Contains(status.message(), "scan.x")) << yaml;
  }
}

}  // namespace
}  // namespace insitu
