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
# The readers of outside files and their tests under AddressSanitizer and UBSan.
scripts/asan.sh
# The Debian package built in build-pkg/ and checked: its binaries and its daemon run from the
# extracted package (scripts/package.sh; ccache makes the second build mostly links).
scripts/package.sh
