#!/usr/bin/env bash
# The insitu demo on the simulated cell: installs what is missing, builds (Release), calibrates
# the machine as an operator would (camera, galvo-to-camera pose, height lookup), then runs the
# in-situ job config/jobs/insitu_demo.yaml: scan the arc where it lies, place a QR code (40 um
# hatch) and a plate (120 um hatch) on the measured surface, mark them in focus, verify.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/build.sh
out="${1:-out/demo}"
mkdir -p "$out"
# The demo job reads its calibration from out/calib/machine.yaml (written by the calibrate job).
if [ ! -f out/calib/machine.yaml ]; then
  build/bin/insitu run config/jobs/calibrate.yaml --out "$out/calibrate"
fi
build/bin/insitu run config/jobs/insitu_demo.yaml --out "$out/mark"
python3 - "$out/mark/report.json" <<'PY' || true
import json, sys
m = json.load(open(sys.argv[1]))["metrics"]
def show(key, fmt):
    if key in m:
        print(("  %-28s " + fmt) % (key, m[key]))
print("demo measurements:")
for key, fmt in [("line_spacing_40_um", "%.2f um"), ("line_spacing_std_40_um", "%.2f um"),
                 ("line_spacing_120_um", "%.2f um"), ("line_width_120_um", "%.1f um"),
                 ("placement_error_mm", "%.3f mm"), ("pattern_size_error_pct", "%.2f %%"),
                 ("focus_error_max_mm", "%.3f mm"), ("points_without_surface", "%.0f")]:
    show(key, fmt)
PY
echo
echo "demo results:"
echo "  calibration:  out/calib/machine.yaml"
echo "  point cloud:  $out/mark/cloud.ply"
echo "  galvo list:   $out/mark/galvo_list.txt"
echo "  marks:        $out/mark/mark.png (side camera, design over it), $out/mark/coaxial.png"
echo "  report:       $out/mark/report.json"
