#include "insitu/fit/field_data.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

namespace insitu::fit {
namespace {

// Values are compared with EXPECT_EQ against the same decimal literal: std::strtod and the
// compiler both round a decimal to the nearest double, so a correct parse is exact.

const std::string kHao2009 =
    std::string(INSITU_SOURCE_DIR) + "/data/measured/galvo_field_hao2009.csv";

TEST(FieldData, ShippedHao2009Parses) {
  const Result<FieldData> r = LoadFieldCsv(kHao2009);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const FieldData& d = *r;
  EXPECT_EQ(d.origin, kHao2009);
  ASSERT_EQ(d.points.size(), 15u);
  EXPECT_FALSE(d.has_z);
  EXPECT_FALSE(d.has_t);
  EXPECT_FALSE(d.has_v);
  EXPECT_TRUE(d.ReplicateGroups().empty());
  EXPECT_EQ(d.DistinctPositions(), 15);

  // Five comment lines, the header on line 6, data from line 7.
  EXPECT_EQ(d.points[0].line, 7);
  EXPECT_EQ(d.points[14].line, 21);
  // A table of moves from the field centre: its first row is their reference.
  EXPECT_EQ(d.reference, 0);
  EXPECT_EQ(d.points[0].cmd, Eigen::Vector2d(0.0, 0.0));
  EXPECT_EQ(d.points[6].cmd, Eigen::Vector2d(0.0, 6.0));
  EXPECT_EQ(d.points[6].meas, Eigen::Vector2d(-0.1224, 6.0430));
  EXPECT_EQ(d.points[14].cmd, Eigen::Vector2d(7.0, 0.0));
  EXPECT_EQ(d.points[14].meas, Eigen::Vector2d(6.9892, 0.1584));
  EXPECT_EQ(d.points[14].z_cmd_mm, 0.0);

  ASSERT_EQ(d.extra.size(), 5u);
  for (const char* name : {"px_x", "px_y", "comp_h_lsb", "comp_v_lsb", "move_reference"}) {
    ASSERT_TRUE(d.extra.count(name)) << name;
    EXPECT_EQ(d.extra.at(name).size(), 15u) << name;
  }
  EXPECT_EQ(d.extra.at("px_x")[0], 402.0);
  EXPECT_EQ(d.extra.at("px_y")[7], 246.0);
  EXPECT_EQ(d.extra.at("comp_h_lsb")[5], 110.0);
  EXPECT_EQ(d.extra.at("comp_v_lsb")[14], -193.0);
}

TEST(FieldData, ColumnsInAnyOrderWithCommentsBlanksSpacesAndCrlf) {
  const std::string text =
      "\xEF\xBB\xBF# exported from a spreadsheet\r\n"
      "\r\n"
      " y_meas_mm , note ,x_cmd_mm,\tx_meas_mm, y_cmd_mm \r\n"
      "2.5, a ,1,1.25,2\r\n"
      "   # a comment between rows\n"
      "\n"
      "-4e-1,7,-3,-3.5 , -0.5\n";
  const Result<FieldData> r = ParseFieldCsv(text, "order.csv");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const FieldData& d = *r;
  EXPECT_EQ(d.origin, "order.csv");
  ASSERT_EQ(d.points.size(), 2u);
  EXPECT_EQ(d.points[0].cmd, Eigen::Vector2d(1.0, 2.0));
  EXPECT_EQ(d.points[0].meas, Eigen::Vector2d(1.25, 2.5));
  EXPECT_EQ(d.points[0].line, 4);
  EXPECT_EQ(d.points[1].cmd, Eigen::Vector2d(-3.0, -0.5));
  EXPECT_EQ(d.points[1].meas, Eigen::Vector2d(-3.5, -0.4));
  EXPECT_EQ(d.points[1].line, 7);
  ASSERT_EQ(d.extra.size(), 1u);
  ASSERT_EQ(d.extra.count("note"), 1u);
  ASSERT_EQ(d.extra.at("note").size(), 2u);
  EXPECT_TRUE(std::isnan(d.extra.at("note")[0]));  // "a" is not a number: NaN, no error
  EXPECT_EQ(d.extra.at("note")[1], 7.0);
}

TEST(FieldData, OptionalColumns) {
  const std::string text =
      "t_s,vy_mm_s,x_cmd_mm,y_cmd_mm,z_cmd_mm,x_meas_mm,y_meas_mm,vx_mm_s,temp_C\n"
      "0.5,-20,1,2,-0.25,1.01,2.02,300,\n"
      "1.5,40,3,4,0.75,3.03,4.04,-100,nan\n";
  const Result<FieldData> r = ParseFieldCsv(text, "opt.csv");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const FieldData& d = *r;
  EXPECT_TRUE(d.has_z);
  EXPECT_TRUE(d.has_t);
  EXPECT_TRUE(d.has_v);
  ASSERT_EQ(d.points.size(), 2u);
  EXPECT_EQ(d.points[0].z_cmd_mm, -0.25);
  EXPECT_EQ(d.points[0].t_s, 0.5);
  EXPECT_EQ(d.points[0].v_mm_s, Eigen::Vector2d(300.0, -20.0));
  EXPECT_EQ(d.points[1].cmd, Eigen::Vector2d(3.0, 4.0));
  EXPECT_EQ(d.points[1].meas, Eigen::Vector2d(3.03, 4.04));
  EXPECT_EQ(d.points[1].z_cmd_mm, 0.75);
  EXPECT_EQ(d.points[1].t_s, 1.5);
  EXPECT_EQ(d.points[1].v_mm_s, Eigen::Vector2d(-100.0, 40.0));
  // Unused columns may be empty or NaN: they are kept, not checked.
  ASSERT_EQ(d.extra.size(), 1u);
  ASSERT_EQ(d.extra.at("temp_C").size(), 2u);
  EXPECT_TRUE(std::isnan(d.extra.at("temp_C")[0]));
  EXPECT_TRUE(std::isnan(d.extra.at("temp_C")[1]));
}

TEST(FieldData, OnlyRequiredColumns) {
  const Result<FieldData> r =
      ParseFieldCsv("x_cmd_mm,y_cmd_mm,x_meas_mm,y_meas_mm\n1,2,3,4\n", "min.csv");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_FALSE(r->has_z);
  EXPECT_FALSE(r->has_t);
  EXPECT_FALSE(r->has_v);
  EXPECT_TRUE(r->extra.empty());
  ASSERT_EQ(r->points.size(), 1u);
  EXPECT_EQ(r->points[0].z_cmd_mm, 0.0);
  EXPECT_EQ(r->points[0].t_s, 0.0);
  EXPECT_EQ(r->points[0].v_mm_s, Eigen::Vector2d::Zero());
}

TEST(FieldData, ReplicatesGroupedByFirstOccurrence) {
  // (0,0) three times, one of them 1e-10 mm off (within the 1e-9 mm tolerance); (1,0) twice;
  // (2,0) once; (1, 1e-6) is 1e-6 mm from (1,0), far outside the tolerance: its own position.
  const std::string text =
      "x_cmd_mm,y_cmd_mm,x_meas_mm,y_meas_mm\n"
      "1,0,1.01,0\n"            // 0
      "0,0,0.01,0\n"            // 1
      "0.0000000001,0,0,0\n"    // 2
      "2,0,2.02,0\n"            // 3
      "1,0,1.02,0\n"            // 4
      "1,0.000001,1,0\n"        // 5
      "0,-0.0000000001,0,0\n";  // 6
  const Result<FieldData> r = ParseFieldCsv(text, "rep.csv");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const std::vector<std::vector<int>> expected = {{0, 4}, {1, 2, 6}};
  EXPECT_EQ(r->ReplicateGroups(), expected);
  EXPECT_EQ(r->DistinctPositions(), 4);
}

TEST(FieldData, ReplicatesDistinguishZOnlyWhenPresent) {
  const std::string text =
      "x_cmd_mm,y_cmd_mm,z_cmd_mm,x_meas_mm,y_meas_mm\n"
      "1,1,0,1,1\n"
      "1,1,0.5,1,1\n"
      "1,1,0,1,1\n";
  const Result<FieldData> r = ParseFieldCsv(text, "z.csv");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->ReplicateGroups(), (std::vector<std::vector<int>>{{0, 2}}));
  EXPECT_EQ(r->DistinctPositions(), 2);

  FieldData no_z = *r;
  no_z.has_z = false;  // the same x, y without a focus column are all one position
  EXPECT_EQ(no_z.ReplicateGroups(), (std::vector<std::vector<int>>{{0, 1, 2}}));
  EXPECT_EQ(no_z.DistinctPositions(), 1);
}

struct Malformed {
  const char* name;
  std::string text;
  StatusCode code;
  std::string where;                 // "bad.csv:<line>: ", the message's start
  std::vector<std::string> mention;  // the column(s) the message must name
};

class FieldDataMalformed : public ::testing::TestWithParam<Malformed> {};

TEST_P(FieldDataMalformed, ErrorNamesOriginLineAndColumn) {
  const Malformed& m = GetParam();
  const Result<FieldData> r = ParseFieldCsv(m.text, "bad.csv");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), m.code) << r.status().ToString();
  const std::string& msg = r.status().message();
  EXPECT_EQ(msg.rfind(m.where, 0), 0u) << msg;
  for (const std::string& s : m.mention)
    EXPECT_NE(msg.find(s), std::string::npos) << s << ": " << msg;
}

const std::string kHeader = "x_cmd_mm,y_cmd_mm,x_meas_mm,y_meas_mm";
const std::string kComments = "# comment\n\n";  // data and errors start at line 3

INSTANTIATE_TEST_SUITE_P(
    Cases, FieldDataMalformed,
    ::testing::Values(
        Malformed{"MissingRequiredColumn",
                  kComments + "x_cmd_mm,y_cmd_mm,x_meas_mm,px\n1,2,3,4\n",
                  StatusCode::kParseError,
                  "bad.csv:3: ",
                  {"'y_meas_mm'", "x_cmd_mm, y_cmd_mm, x_meas_mm, y_meas_mm"}},
        Malformed{"TwoMissingColumns",
                  kComments + "y_cmd_mm,x_meas_mm\n1,2\n",
                  StatusCode::kParseError,
                  "bad.csv:3: ",
                  {"'x_cmd_mm'", "'y_meas_mm'"}},
        Malformed{"ColumnTwice",
                  kComments + kHeader + ", x_cmd_mm\n1,2,3,4,5\n",
                  StatusCode::kParseError,
                  "bad.csv:3: ",
                  {"'x_cmd_mm'", "twice"}},
        Malformed{"ExtraColumnTwice",
                  kComments + kHeader + ",px,px\n1,2,3,4,5,6\n",
                  StatusCode::kParseError,
                  "bad.csv:3: ",
                  {"'px'", "twice"}},
        Malformed{"UnnamedColumn",
                  kComments + kHeader + ",\n1,2,3,4,5\n",
                  StatusCode::kParseError,
                  "bad.csv:3: ",
                  {"column 5"}},
        Malformed{"TooFewCells",
                  kComments + kHeader + "\n1,2,3,4\n# c\n1,2,3\n",
                  StatusCode::kParseError,
                  "bad.csv:6: ",
                  {"'y_meas_mm'", "3 cells"}},
        Malformed{"TooFewCellsForExtra",
                  kComments + kHeader + ",px\n1,2,3,4\n",
                  StatusCode::kParseError,
                  "bad.csv:4: ",
                  {"'px'"}},
        Malformed{"TooManyCells",
                  kComments + kHeader + "\n1,2,3,4,5\n",
                  StatusCode::kParseError,
                  "bad.csv:4: ",
                  {"column 5", "5 cells"}},
        Malformed{"NotANumber",
                  kComments + kHeader + "\n1,2,3,4\n1,2,abc,4\n",
                  StatusCode::kParseError,
                  "bad.csv:5: ",
                  {"'x_meas_mm'", "'abc'"}},
        Malformed{"TrailingUnit",
                  kComments + kHeader + "\n1.5mm,2,3,4\n",
                  StatusCode::kParseError,
                  "bad.csv:4: ",
                  {"'x_cmd_mm'", "'1.5mm'"}},
        Malformed{"EmptyCell",
                  kComments + kHeader + "\n1,,3,4\n",
                  StatusCode::kParseError,
                  "bad.csv:4: ",
                  {"'y_cmd_mm'", "empty"}},
        Malformed{"NaN",
                  kComments + kHeader + "\n1,2,3,NaN\n",
                  StatusCode::kParseError,
                  "bad.csv:4: ",
                  {"'y_meas_mm'", "finite"}},
        Malformed{"Inf",
                  kComments + "x_cmd_mm,y_cmd_mm,x_meas_mm,y_meas_mm,z_cmd_mm\n1,2,3,4,-inf\n",
                  StatusCode::kParseError,
                  "bad.csv:4: ",
                  {"'z_cmd_mm'", "finite"}},
        Malformed{"Overflow",
                  kComments + "t_s," + kHeader + "\n1e999,1,2,3,4\n",
                  StatusCode::kParseError,
                  "bad.csv:4: ",
                  {"'t_s'", "finite"}},
        Malformed{"VelocityNotNumber",
                  kComments + kHeader + ",vx_mm_s,vy_mm_s\n1,2,3,4,5,fast\n",
                  StatusCode::kParseError,
                  "bad.csv:4: ",
                  {"'vy_mm_s'", "'fast'"}},
        Malformed{"VxWithoutVy",
                  kComments + kHeader + ",vx_mm_s\n1,2,3,4,5\n",
                  StatusCode::kInvalidArgument,
                  "bad.csv:3: ",
                  {"'vx_mm_s'", "'vy_mm_s'"}},
        Malformed{"VyWithoutVx",
                  kComments + "vy_mm_s," + kHeader + "\n5,1,2,3,4\n",
                  StatusCode::kInvalidArgument,
                  "bad.csv:3: ",
                  {"'vy_mm_s'", "'vx_mm_s'"}},
        Malformed{"NoDataRows",
                  kComments + kHeader + "\n# only comments\n\n",
                  StatusCode::kInvalidArgument,
                  "bad.csv:5: ",
                  {"line 3", "x_cmd_mm"}},
        Malformed{"NoHeader",
                  kComments + "# nothing else\n",
                  StatusCode::kParseError,
                  "bad.csv:3: ",
                  {"no header", "x_cmd_mm, y_cmd_mm, x_meas_mm, y_meas_mm"}},
        Malformed{"EmptyText", "", StatusCode::kParseError, "bad.csv:1: ", {"no header"}}),
    [](const ::testing::TestParamInfo<Malformed>& info) { return std::string(info.param.name); });

TEST(FieldData, TheReferenceOfATableOfMovesIsOneRow) {
  const std::string head = "x_cmd_mm,y_cmd_mm,x_meas_mm,y_meas_mm,move_reference\n";
  auto ok = ParseFieldCsv(head + "0,0,0,0,0\n1,0,1.01,0,1\n2,0,2.0,0,0\n", "t.csv");
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_EQ(ok->reference, 1);
  auto none = ParseFieldCsv("x_cmd_mm,y_cmd_mm,x_meas_mm,y_meas_mm\n0,0,0,0\n", "t.csv");
  ASSERT_TRUE(none.ok());
  EXPECT_EQ(none->reference, -1);
  auto two = ParseFieldCsv(head + "0,0,0,0,1\n1,0,1,0,1\n", "t.csv");
  ASSERT_FALSE(two.ok());
  EXPECT_NE(two.status().message().find("t.csv:3"), std::string::npos) << two.status().message();
  EXPECT_NE(two.status().message().find("line 2"), std::string::npos) << two.status().message();
  auto bad = ParseFieldCsv(head + "0,0,0,0,yes\n", "t.csv");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("'move_reference'"), std::string::npos);
}

TEST(FieldData, FirstBadRowIsReported) {
  const std::string text = kHeader + "\n1,2,3,4\n1,x,3,4\n1,2,y,4\n";
  const Result<FieldData> r = ParseFieldCsv(text, "bad.csv");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message().rfind("bad.csv:3: column 'y_cmd_mm'", 0), 0u)
      << r.status().message();
}

TEST(FieldData, LoadMissingFileIsNotFound) {
  const std::string path = std::string(INSITU_SOURCE_DIR) + "/data/measured/no_such_field.csv";
  const Result<FieldData> r = LoadFieldCsv(path);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_NE(r.status().message().find(path), std::string::npos) << r.status().message();
}

TEST(FieldData, LoadDirectoryIsNotFound) {
  const std::string path = std::string(INSITU_SOURCE_DIR) + "/data/measured";
  const Result<FieldData> r = LoadFieldCsv(path);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_NE(r.status().message().find("directory"), std::string::npos) << r.status().message();
}

}  // namespace
}  // namespace insitu::fit
