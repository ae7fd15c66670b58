// The machine state: the laser only while Running, explicit arm and disarm, every change an
// event, and no transition that skips arming.
#include "insitu/daemon/machine_state.h"

#include <gtest/gtest.h>

#include <atomic>
#include <thread>
#include <vector>

namespace insitu::daemon {
namespace {

TEST(MachineState, TheLaserOnlyWhileRunning) {
  StateMachine m;
  std::vector<std::string> events;
  m.AddListener([&](MachineState from, MachineState to, const std::string& why) {
    events.push_back(std::string(StateName(from)) + ">" + StateName(to) +
                     (why.empty() ? "" : ":" + why));
  });
  EXPECT_EQ(m.state(), MachineState::kIdle);
  EXPECT_FALSE(m.laser_allowed());
  EXPECT_EQ(m.Start().code(), StatusCode::kFailedPrecondition);  // never without arming
  ASSERT_TRUE(m.Arm().ok());
  EXPECT_FALSE(m.laser_allowed());  // armed is not running
  ASSERT_TRUE(m.Start().ok());
  EXPECT_TRUE(m.laser_allowed());
  EXPECT_EQ(m.Arm().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(m.Disarm().code(), StatusCode::kFailedPrecondition);
  ASSERT_TRUE(m.Finish(JobOutcome::kFaulted, "camera timeout").ok());
  EXPECT_FALSE(m.laser_allowed());
  EXPECT_EQ(m.last_reason(), "camera timeout");
  EXPECT_EQ(m.Start().code(), StatusCode::kFailedPrecondition);  // re-arm first
  EXPECT_EQ(m.Finish(JobOutcome::kDone).code(), StatusCode::kFailedPrecondition);
  ASSERT_TRUE(m.Arm().ok());
  ASSERT_TRUE(m.Start().ok());
  ASSERT_TRUE(m.Finish(JobOutcome::kCancelled, "operator").ok());
  ASSERT_TRUE(m.Disarm().ok());
  ASSERT_TRUE(m.Disarm().ok());  // idempotent, no event
  const std::vector<std::string> expected{
      "idle>armed",    "armed>running", "running>faulted:camera timeout",
      "faulted>armed", "armed>running", "running>cancelled:operator",
      "cancelled>idle"};
  EXPECT_EQ(events, expected);
}

TEST(MachineState, ConcurrentStartsRunOneJob) {
  // Many threads race to start after one arm: exactly one wins, the rest are refused.
  for (int round = 0; round < 50; ++round) {
    StateMachine m;
    ASSERT_TRUE(m.Arm().ok());
    std::atomic<int> started{0};
    std::vector<std::thread> threads;
    for (int t = 0; t < 8; ++t) {
      threads.emplace_back([&] { started += m.Start().ok(); });
    }
    for (auto& t : threads) t.join();
    EXPECT_EQ(started.load(), 1);
  }
}

}  // namespace
}  // namespace insitu::daemon
