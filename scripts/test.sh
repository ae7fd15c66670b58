#!/usr/bin/env bash
# Installs what is missing, builds, and runs every test of the default suite (ctest).
# Long tests carry the label `slow` and run only with INSITU_SLOW=1.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/build.sh
cd build
if [ "${INSITU_SLOW:-0}" = "1" ]; then
  ctest --output-on-failure -j 2
else
  ctest --output-on-failure -j 2 -LE slow
fi
cd ..
# The fuzz targets for a short fixed time (when clang is installed).
scripts/fuzz.sh
