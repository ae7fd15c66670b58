#!/usr/bin/env bash
# The readers of outside files (SVG, DXF, HPGL, text, images) and their tests built with
# AddressSanitizer and UndefinedBehaviorSanitizer into build-asan/, and run: any finding fails
# the script. Fontconfig keeps a one-time allocation for the process's life, which
# LeakSanitizer would report at exit: suppressed by name (scripts/lsan.supp), nothing else.
set -euo pipefail
cd "$(dirname "$0")/.."
generator=()
command -v ninja >/dev/null 2>&1 && generator=(-G Ninja)
launcher=()
command -v ccache >/dev/null 2>&1 && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
if [ ! -f build-asan/CMakeCache.txt ]; then
  cmake -S . -B build-asan "${generator[@]}" "${launcher[@]}" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_CXX_FLAGS="-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer" \
    -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" >/dev/null
fi
tests=(pattern_svg pattern_dxf pattern_text pattern_vector pattern_raster)
cmake --build build-asan -j "${INSITU_JOBS:-2}" --target "${tests[@]/#/test_}"
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
export LSAN_OPTIONS=suppressions=$PWD/scripts/lsan.supp
for t in "${tests[@]}"; do
  echo "asan: $t"
  "build-asan/tests/test_$t" --gtest_brief=1
done
