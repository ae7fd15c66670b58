// The scan: the galvo sweeps its pointer as a line at x = x_i (i = 0, 1, ...) along y, the
// camera takes one frame per line, the stripe centres are extracted and triangulated against
// the line's light plane (seed 000 sec. 2.1 method 1), giving a point cloud in the galvo frame.
#pragma once

#include <atomic>
#include <array>
#include <functional>
#include <string>
#include <memory>

#include "insitu/calib/calibration.h"
#include "insitu/core/frame.h"
#include "insitu/core/status.h"
#include "insitu/geometry/cloud.h"
#include "insitu/hw/machine.h"
#include "insitu/vision/image.h"
#include "insitu/vision/stripe.h"

namespace insitu::job {

struct ScanOptions {
  double x_start_mm = -14.0;       // first line
  double x_end_mm = 14.0;          // last line (inclusive when on the spacing grid)
  double line_spacing_mm = 0.5;    // seed 000 sec. 3.2
  double y_start_mm = -50.0;       // line ends
  double y_end_mm = 50.0;
  double focus_z_mm = 0.0;         // pointer focus height
  // seed 000 sec. 3.2; with a software trigger the nearest speed at which the exposure holds a
  // whole number of back-and-forth sweeps (every point of the line passed equally often).
  double speed_mm_per_s = 5000.0;
  double settle_ms = 5.0;          // wait after starting a line before exposing
  double exposure_ms = 50.0;       // seed 000 sec. 3.2
  // Before the scan, pre-shots on its first, middle and last lines set the exposure so the
  // brightest stripe columns reach ~60 % of full scale and none saturates, starting from
  // exposure_ms: the line's length, the part's albedo and the room light all change how
  // bright the stripe is (a short line is swept more often per exposure).
  bool auto_exposure = false;
  // A scan that finds the stripe in fewer than this fraction of the columns its lines cover
  // fails, saying whether it saturated or was too dark (0: never). A part much smaller than
  // the lines on a table the camera cannot see needs a lower one.
  double min_stripe_fraction = 0.1;
  // Before the lines (after auto exposure, at the scan's exposure, gain and region), the mean
  // of this many frames with the pointer off is taken off every line's frame: the room's light
  // on the part and its walls, which would otherwise widen and pull the stripe (vision/
  // background.h). 0 (the default): the frames are used as the camera gives them; the step
  // gauge's accuracy job and the cell's diagnosis take 2.
  int background_frames = 0;
  double gain_db = 0.0;
  int binning = 1;
  // 1: camera + light plane (seed 000 method 1); 2: method 1's ray, height from the
  // calibration's height lookup (seed 000 method 2).
  int method = 1;
  // Grabbing and processing overlap: frames wait for the processing thread in a queue of at
  // most queue_frames; a full queue stops the scan with an error (a line is never dropped).
  // false: each line is processed before the next starts (the machine waits for the computer).
  bool streaming = true;
  int queue_frames = 8;
  // The camera reads only the band of rows the stripe can occupy: the lines' points at every
  // height of height_range_mm (galvo z, mm) projected through the calibration, plus a margin.
  // A camera without regions reads its whole sensor (a warning says so).
  bool region = true;
  std::array<double, 2> height_range_mm{-20.0, 20.0};
  // A directory for each line's frame as the camera gave it (line_NNNN.png) and the
  // extraction drawn over the plane it read, over the window's span (line_NNNN_stripe.png: the
  // light plane's window in blue, valid centres in green, refused scan lines marked by status
  // just above the window);
  // empty: none. The scan job's `output.save_frames` sets it to the job's `frames/`.
  std::string frames_dir;

  Status Validate() const;
  int line_count() const;
  double line_x(int i) const { return x_start_mm + i * line_spacing_mm; }
};

struct ScanStats {
  int lines = 0;
  int64_t scan_lines_examined = 0;  // columns (or rows) over all frames
  int64_t valid = 0, none = 0, saturated = 0, two_peaks = 0, too_wide = 0, bad_shape = 0;
  int64_t rejected_geometry = 0;     // valid centre whose ray misses the light plane
  int64_t outside_lookup = 0;        // method 2: centre outside the calibrated volume
  double machine_time_s = 0.0;       // on the machine's clock: first line to last frame taken
  int max_queued_frames = 0;         // streaming: the most frames that waited for processing
  int region_first_row = 0;          // the camera's band of full-sensor rows
  int region_rows = 0;
  std::string region_note;           // why the band is not used, when it is not
  std::string trigger;               // "software" (a grab per line) or "head" (its pulses)
  double exposure_ms = 0.0;          // the exposure the lines were taken at
  int auto_exposure_shots = 0;       // pre-shot frames auto exposure took (0: off)
  std::string exposure_note;         // auto exposure did not settle, and what it kept
  // Columns (rows) the lines cover in the image, from the calibration: what a part filling
  // the lines would give. A scan with centres in under a tenth of them fails.
  int64_t expected_columns = 0;
  double extract_time_ms = 0.0;      // wall time in the stripe extractor, all frames
  // The pointer's speed on the lines: the job's, or the nearest at which the exposure holds a
  // whole number of back-and-forth sweeps (the line evenly lit; software trigger only).
  double pointer_speed_mm_per_s = 0.0;
  int background_frames = 0;         // frames averaged into the background (0: none taken)
  double background_level = 0.0;     // the background's mean, gray levels of the frames
};

struct ScanOutput {
  geometry::Cloud cloud;
  geometry::Cloud cloud_method1;  // method 2 only: the same centres reconstructed by method 1
  ScanStats stats;
};

// Where line i's stripe can lie in a frame of width x height binned pixels whose first pixel is
// (offset_x, offset_y) of the binned sensor: per scan line of `direction` (kColumns: each
// column's rows), the span of the line's light plane over height_range_mm, projected through
// the calibration, with a margin for the pointer's landing off the calibrated plane (~8
// full-sensor pixels). The extraction takes no peak outside it for the stripe.
vision::StripeWindow LineStripeWindow(const ScanOptions& o, const calib::CalibrationSet& cal,
                                      vision::StripeDirection direction, int i, int width,
                                      int height, int offset_x, int offset_y);

// The pointer sweeps its line back and forth: every point of it is passed twice a period,
// 2 length / speed, so an exposure of whole periods gives the whole line the same dose wherever
// the sweep was when the exposure began. Any other exposure leaves a stretch of the line swept
// once more than the rest: a step in the stripe's brightness that falls anywhere along it,
// and moves the fade where a line leaves a surface (a gauge's end) by a fraction of a pixel.
// Returns the speed nearest `speed` at which `exposure_ms` holds a whole number of periods (at
// least one), or `speed` itself when that would be more than 4 times faster (an exposure far
// shorter than a sweep: the dose cannot be even).
double EvenSweepSpeed(double speed, double length_mm, double exposure_ms);

// Auto exposure: the stripe's brightest lit columns (98th percentile of the valid peaks) at
// 55 % of full scale. Pre-shots on the first, middle and last lines (software trigger), each
// rescaling the exposure by target / level until within 15 % of it (the sensor is linear:
// stripe and room light both scale with the exposure). A percentile that saturates tells no
// level, nor does a frame without a stripe: the exposure is cut by 3 or raised by 4, or,
// once both are known, set between them (geometric mean). Columns still saturated after such
// a cut, while the rest went dark, are glints (a specular face): excused, and the exposure set
// for the rest. It never goes above 8 times the job's exposure: no stripe there is no stripe
// (a missing part, the pointer off), and the job's exposure is kept. Not converging in 8
// rounds keeps the last exposure whose level was measured. *note says what went wrong (empty
// when it converged) and names the glints it excused. Returns the exposure (ms) it set, and
// counts its frames in *shots. Errors: the devices', cancelled.
Result<double> AutoExpose(hw::Machine& machine, const ScanOptions& options,
                          const vision::StripeOptions& stripe_options,
                          const calib::CalibrationSet& calibration, const std::atomic<bool>* cancel,
                          int* shots, std::string* note);

// The per-frame path of a scan, as the scan runs it and bench/scan_pipeline_bench times it:
// stripe centres (seed 000 eq. 7), undistorted rays, the line's light plane (eq. 1-4), method
// 2's height lookup, appended to the cloud. One per thread (it keeps the extractor's buffers).
class FrameProcessor {
 public:
  // Errors: the options' and the extraction's (invalid_argument); method 2 without a lookup.
  static Result<std::unique_ptr<FrameProcessor>> Create(const ScanOptions& options,
                                                        const vision::StripeOptions& stripe,
                                                        const calib::CalibrationSet& calibration);
  ~FrameProcessor();
  // Line `line`'s frame (at options.line_x(line)) into out->cloud (and cloud_method1), its
  // columns counted in out->stats; extraction wall time in out->stats.extract_time_ms.
  Status Process(const Frame& frame, int line, ScanOutput* out);
  // The view with the pointer off (vision::AverageFrames of a few), taken off every later
  // frame before extraction; an empty image: none. Errors: invalid_argument when a later
  // frame differs from it in size or depth (Process says which line).
  void SetBackground(vision::Image background);

 private:
  FrameProcessor() = default;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The view with the pointer off: the pointer stopped, then the mean of `frames` grabs at the
// camera's present exposure, gain and region (vision::AverageFrames). Errors: the devices'
// (prefixed "background"), cancelled.
Result<vision::Image> GrabBackground(hw::Machine& machine, int frames,
                                     const std::atomic<bool>* cancel = nullptr);

// Runs the scan on `machine` (the pointer is stopped on every exit path). `progress(done,
// total)` is called on the caller's thread after each line taken (done: lines processed);
// `cancel` stops between lines with status cancelled. Streaming (options.streaming), the lines
// are processed on a second thread while the next are taken.
Result<ScanOutput> RunScan(hw::Machine& machine, const ScanOptions& options,
                           const vision::StripeOptions& stripe,
                           const calib::CalibrationSet& calibration,
                           const std::function<void(int, int)>& progress = {},
                           const std::atomic<bool>* cancel = nullptr);

}  // namespace insitu::job
