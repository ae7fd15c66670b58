// Where the spot of one marking pulse lands for a command on the simulated head (the crater's
// centre): the simulator standing in for a field-measuring instrument in tests.
#pragma once

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <vector>

#include "insitu/sim/world.h"

namespace insitu::testing {

inline Eigen::Vector2d LandedSpot(const sim::WorldOptions& o, const Eigen::Vector2d& cmd) {
  sim::SimWorld w(o);
  sim::MarkingParams p;
  p.jump_delay_us = 3000;     // the mirrors settle on the point
  p.laser_off_delay_us = 40;  // about one pulse at 30 kHz, at rest on the point
  const std::vector<sim::ListMove> moves{{sim::ListMove::Kind::kJump, {cmd.x(), cmd.y(), 0.0}},
                                         {sim::ListMove::Kind::kMark, {cmd.x(), cmd.y(), 0.0}}};
  EXPECT_TRUE(w.ExecuteMarkingList(moves, p).ok());
  EXPECT_FALSE(w.mark_pulses().empty());
  return w.mark_pulses().empty() ? cmd
                                 : Eigen::Vector2d(w.mark_pulses().back().point_in_world.head<2>());
}

}  // namespace insitu::testing
