#include "insitu/hw/operator.h"

#include <utility>

namespace insitu::hw {
namespace {

class PersonOperator : public Operator {
 public:
  PersonOperator(std::function<Status(const std::string&)> ask, std::unique_ptr<Operator> hands)
      : ask_(std::move(ask)), hands_(std::move(hands)) {}

  Status PlaceBoard(int view, int views) override {
    INSITU_RETURN_IF_ERROR(Ask("Hold the calibration board in a new pose (view " +
                               std::to_string(view + 1) + " of " + std::to_string(views) +
                               "): tilted, covering a part of the camera's image the earlier "
                               "views did not, then confirm."));
    return hands_ ? hands_->PlaceBoard(view, views) : Status::Ok();
  }
  Status RemoveBoard() override {
    INSITU_RETURN_IF_ERROR(Ask("Take the calibration board away, then confirm."));
    return hands_ ? hands_->RemoveBoard() : Status::Ok();
  }
  Status PlaceBoardOnPlate() override {
    INSITU_RETURN_IF_ERROR(Ask("Lay the calibration board flat on the stage plate near the "
                               "field's centre, printed side up, then confirm."));
    return hands_ ? hands_->PlaceBoardOnPlate() : Status::Ok();
  }
  Status FreshPlate() override {
    INSITU_RETURN_IF_ERROR(Ask("Put a fresh sacrificial plate (anodised aluminium) on the "
                               "stage, then confirm. The laser will mark it."));
    return hands_ ? hands_->FreshPlate() : Status::Ok();
  }
  Status ClearTable() override {
    INSITU_RETURN_IF_ERROR(Ask("Take every part off the stage plate, then confirm."));
    return hands_ ? hands_->ClearTable() : Status::Ok();
  }

 private:
  Status Ask(const std::string& request) {
    const Status answered = ask_(request);
    if (answered.ok() || answered.code() == StatusCode::kCancelled) return answered;
    return Status(answered.code(), "asking the operator: " + answered.message());
  }

  std::function<Status(const std::string&)> ask_;
  std::unique_ptr<Operator> hands_;
};

}  // namespace

std::unique_ptr<Operator> MakePersonOperator(std::function<Status(const std::string&)> ask,
                                             std::unique_ptr<Operator> hands) {
  return std::make_unique<PersonOperator>(std::move(ask), std::move(hands));
}

}  // namespace insitu::hw
