#!/usr/bin/env bash
# Builds the libFuzzer targets with clang (when clang++ is installed) into build-fuzz/ and runs
# each for a short fixed time from its seed corpus: the protocol line parser, job files, the
# config reader, the galvo field CSV reader, a run request's set (insitud's confinement), and
# the SVG, DXF and HPGL readers and pattern images. A crash fails the script and leaves the
# reproducer (crash-*) in build-fuzz/fuzz/. Longer runs: INSITU_FUZZ_SECONDS=600 scripts/fuzz.sh
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v clang++ >/dev/null 2>&1; then
  echo "fuzz: clang++ not installed; the fuzz targets need clang's libFuzzer (skipped)"
  exit 0
fi
seconds="${INSITU_FUZZ_SECONDS:-15}"
targets=(protocol job_file config field_csv run_set svg dxf hpgl image)
generator=()
command -v ninja >/dev/null 2>&1 && generator=(-G Ninja)
if [ ! -f build-fuzz/CMakeCache.txt ]; then
  cmake -S . -B build-fuzz "${generator[@]}" -DCMAKE_BUILD_TYPE=Release \
    -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ >/dev/null
fi
cmake --build build-fuzz -j "${INSITU_JOBS:-2}" --target "${targets[@]/#/fuzz_}"
for t in "${targets[@]}"; do
  scratch="build-fuzz/fuzz/${t}_corpus"
  mkdir -p "$scratch"
  echo "fuzz: $t for ${seconds} s"
  log="build-fuzz/fuzz/$t.log"
  # Fontconfig (reached by SVG and DXF text) keeps a one-time allocation for the process's
  # life, which the leak checker would report at exit: not insitu's.
  if ! (cd build-fuzz/fuzz && ASAN_OPTIONS=detect_leaks=0 "./fuzz_$t" -max_total_time="$seconds" -seed=1 \
          -print_final_stats=1 "${t}_corpus" "../../tests/fuzz/${t}_corpus") >"$log" 2>&1; then
    tail -40 "$log" >&2
    echo "fuzz: $t failed (reproducer: build-fuzz/fuzz/crash-*; log: $log)" >&2
    exit 1
  fi
  grep -E "^(Done|stat::number_of_executed_units)" "$log" || true
done
