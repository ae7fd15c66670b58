#include "insitu/core/status.h"

#include <gtest/gtest.h>

#include <memory>
#include <string>

namespace insitu {
namespace {

TEST(Status, DefaultIsOk) {
  Status status;
  EXPECT_TRUE(status.ok());
  EXPECT_EQ(status.code(), StatusCode::kOk);
  EXPECT_EQ(status.ToString(), "ok");
  EXPECT_TRUE(Status::Ok().ok());
}

TEST(Status, ToStringNamesTheCode) {
  EXPECT_EQ(InvalidArgument("x").ToString(), "invalid_argument: x");
  EXPECT_EQ(NotFound("job.yaml: cannot open").ToString(), "not_found: job.yaml: cannot open");
  EXPECT_EQ(ParseError("x").ToString(), "parse_error: x");
  EXPECT_EQ(OutOfRange("x").ToString(), "out_of_range: x");
  EXPECT_EQ(FailedPrecondition("x").ToString(), "failed_precondition: x");
  EXPECT_EQ(DeviceError("x").ToString(), "device_error: x");
  EXPECT_EQ(Internal("x").ToString(), "internal: x");
  EXPECT_EQ(Status(StatusCode::kCancelled, "stop").ToString(), "cancelled: stop");
}

TEST(Status, CodeNames) {
  EXPECT_STREQ(StatusCodeName(StatusCode::kOk), "ok");
  EXPECT_STREQ(StatusCodeName(StatusCode::kInvalidArgument), "invalid_argument");
  EXPECT_STREQ(StatusCodeName(StatusCode::kNotFound), "not_found");
  EXPECT_STREQ(StatusCodeName(StatusCode::kParseError), "parse_error");
  EXPECT_STREQ(StatusCodeName(StatusCode::kOutOfRange), "out_of_range");
  EXPECT_STREQ(StatusCodeName(StatusCode::kFailedPrecondition), "failed_precondition");
  EXPECT_STREQ(StatusCodeName(StatusCode::kDeviceError), "device_error");
  EXPECT_STREQ(StatusCodeName(StatusCode::kCancelled), "cancelled");
  EXPECT_STREQ(StatusCodeName(StatusCode::kInternal), "internal");
}

TEST(Status, PrefixedKeepsTheCode) {
  Status status = DeviceError("no reply").Prefixed("galvo");
  EXPECT_EQ(status.code(), StatusCode::kDeviceError);
  EXPECT_EQ(status.message(), "galvo: no reply");
  EXPECT_EQ(status.Prefixed("job 7").message(), "job 7: galvo: no reply");
  EXPECT_TRUE(Status::Ok().Prefixed("galvo").ok());
  EXPECT_EQ(Status::Ok().Prefixed("galvo").message(), "");
}

TEST(Result, HoldsAValueOrAStatus) {
  Result<int> value = 42;
  ASSERT_TRUE(value.ok());
  EXPECT_EQ(*value, 42);
  EXPECT_EQ(value.value(), 42);

  Result<int> error = NotFound("scan.exposure_ms: missing");
  EXPECT_FALSE(error.ok());
  EXPECT_EQ(error.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(error.status().message(), "scan.exposure_ms: missing");

  Result<std::string> text = std::string("galvo");
  EXPECT_EQ(text->size(), 5u);
  text->append("0");
  EXPECT_EQ(*text, "galvo0");
}

TEST(Result, MovesOutMoveOnlyValues) {
  Result<std::unique_ptr<int>> result = std::make_unique<int>(7);
  ASSERT_TRUE(result.ok());
  std::unique_ptr<int> owned = std::move(result).value();
  ASSERT_NE(owned, nullptr);
  EXPECT_EQ(*owned, 7);
}

Result<int> ParsePositive(int x) {
  if (x <= 0) return OutOfRange("x must be positive, got " + std::to_string(x));
  return x;
}

Result<int> Doubled(int x) {
  INSITU_ASSIGN_OR_RETURN(int value, ParsePositive(x));
  return 2 * value;
}

Result<int> SumOfDoubled(int a, int b) {
  int sum = 0;
  INSITU_ASSIGN_OR_RETURN(int first, Doubled(a));
  INSITU_ASSIGN_OR_RETURN(sum, Doubled(b));  // assigns to an existing variable, same scope
  return first + sum;
}

Result<std::unique_ptr<int>> MakeBox(int x) {
  INSITU_ASSIGN_OR_RETURN(int value, ParsePositive(x));
  return std::make_unique<int>(value);
}

Result<int> Unbox(int x) {
  INSITU_ASSIGN_OR_RETURN(std::unique_ptr<int> box, MakeBox(x));
  return *box;
}

TEST(StatusMacros, AssignOrReturn) {
  EXPECT_EQ(*Doubled(4), 8);
  Result<int> failed = Doubled(-1);
  ASSERT_FALSE(failed.ok());
  EXPECT_EQ(failed.status().code(), StatusCode::kOutOfRange);
  EXPECT_EQ(failed.status().message(), "x must be positive, got -1");

  EXPECT_EQ(*SumOfDoubled(1, 2), 6);
  EXPECT_EQ(SumOfDoubled(1, -2).status().message(), "x must be positive, got -2");

  EXPECT_EQ(*Unbox(3), 3);
  EXPECT_FALSE(Unbox(0).ok());
}

Status CheckPositive(int x) {
  return x > 0 ? Status::Ok() : OutOfRange("x must be positive, got " + std::to_string(x));
}

Status CheckAll(int a, int b, int* checked) {
  INSITU_RETURN_IF_ERROR(CheckPositive(a));
  ++*checked;
  INSITU_RETURN_IF_ERROR(b > 0 ? Status::Ok() : InvalidArgument("b"));
  ++*checked;
  return Status::Ok();
}

TEST(StatusMacros, ReturnIfError) {
  int checked = 0;
  EXPECT_TRUE(CheckAll(1, 1, &checked).ok());
  EXPECT_EQ(checked, 2);
  checked = 0;
  EXPECT_EQ(CheckAll(1, 0, &checked).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(checked, 1);
  checked = 0;
  EXPECT_EQ(CheckAll(0, 1, &checked).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(checked, 0);
}

}  // namespace
}  // namespace insitu
