// The person at the machine, as jobs see them: asked to put the calibration board in a new
// pose, or to take it away. On a real cell this asks a person and waits (MakePersonOperator);
// on the simulator the world's scripted poses stand in for the operator's hands.
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "insitu/core/status.h"

namespace insitu::hw {

class Operator {
 public:
  Operator() = default;
  virtual ~Operator() = default;
  Operator(const Operator&) = delete;
  Operator& operator=(const Operator&) = delete;

  // "Hold the board in a new pose (view k of n), tilted, covering a new part of the image."
  // Errors: failed_precondition if the cell has no board, cancelled if the operator aborts.
  virtual Status PlaceBoard(int view, int views) = 0;
  virtual Status RemoveBoard() = 0;
  // "Lay the board flat on the stage plate, near the field centre, printed side up."
  virtual Status PlaceBoardOnPlate() = 0;
  // "Put a fresh sacrificial plate on the stage (anodised aluminium), top at the plate's
  // height": the field calibration marks its targets on it.
  virtual Status FreshPlate() = 0;
  // "Take every part off the stage": calibrations that need the bare plate ask for this.
  virtual Status ClearTable() = 0;
};

// An operator who is a person: each step is put to them as a request (`ask` shows it and
// returns when they have done it, or cancelled), and then, when the cell has `hands` (the
// simulator's, rehearsing a real cell's procedure), those do it.
std::unique_ptr<Operator> MakePersonOperator(std::function<Status(const std::string&)> ask,
                                             std::unique_ptr<Operator> hands);

}  // namespace insitu::hw
