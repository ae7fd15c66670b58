// The exposure for a view lit by the room alone (the operator's chessboard held up or laid on
// the plate): room light differs from cell to cell and hour to hour, and a board whose white
// squares clip loses the edges its corners are found on; one too dark loses the board.
#pragma once

#include <atomic>
#include <string>

#include "insitu/core/status.h"
#include "insitu/hw/camera.h"
#include "insitu/vision/targets.h"

namespace insitu::job {

struct RoomExposure {
  double exposure_ms = 0.0;  // what the camera is left at
  int shots = 0;             // frames taken to find it
  double white_fraction = 0.0;  // the board's white level at it, of full scale (0: not seen)
  std::string note;          // empty when it settled; else what was kept and why
};

// Frames of the board as it lies now, from `start_ms`, each rescaling the exposure so the
// board's white squares (the 95th percentile of the gray levels inside its outer corners) sit
// at about 65 % of full scale: within 15 % of that, and no more than 0.5 % of the board's
// pixels clipped. The sensor is linear (room light scales with the exposure). A board not found
// is looked for at a third of the exposure when the frame clips, three times it when the frame
// is dark (its 95th percentile under a quarter of full scale; lit and never clipped, once more
// at three times, then the board is not in view: the search stops); once
// an exposure too dark and one clipped are both known, between them (geometric mean). The
// exposure stays within [min_ms, max_ms] and within what the camera accepts (an out_of_range
// from it ends the search there). Stops after 8 frames keeping the last exposure the board was
// measured at unclipped (a note says so), or `start_ms` when it never was. Errors: the
// camera's; cancelled.
Result<RoomExposure> ExposeForBoard(hw::Camera& camera, double start_ms, double min_ms,
                                    double max_ms, const vision::ChessboardOptions& board,
                                    const std::atomic<bool>* cancel = nullptr);

}  // namespace insitu::job
