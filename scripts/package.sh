#!/usr/bin/env bash
# Builds the Debian package insitu_<version>_<arch>.deb (Release, no tests or benchmarks, CPack
# DEB) and checks it without installing it: the control file has its dependencies and conffile,
# the extracted insitud and insitu run, and the extracted daemon, with the installed config
# pointed at a scratch folder, serves a shipped job from the installed jobs folder. Prints the
# .deb's path last. Exits non-zero on any failure. README.md, "Install".
#   scripts/package.sh                    # in build-pkg/
#   scripts/package.sh out/pkg            # or INSITU_PKG_BUILD_DIR=out/pkg
set -euo pipefail
cd "$(dirname "$0")/.."
"$(dirname "$0")/setup.sh"
build="${1:-${INSITU_PKG_BUILD_DIR:-build-pkg}}"

generator=()
if [ ! -f "$build/CMakeCache.txt" ] && command -v ninja >/dev/null 2>&1; then
  generator=(-G Ninja)
fi
cmake -S . -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release -DCMAKE_INSTALL_PREFIX=/usr \
  -DINSITU_BUILD_TESTS=OFF -DINSITU_BUILD_BENCH=OFF >/dev/null
cmake --build "$build" -j "${INSITU_JOBS:-2}" --target insitu insitud

rm -f "$build"/insitu_*.deb
(cd "$build" && cpack -G DEB >/dev/null)
debs=("$build"/insitu_*_"$(dpkg --print-architecture)".deb)
if [ ${#debs[@]} -ne 1 ] || [ ! -f "${debs[0]}" ]; then
  echo "package: expected one insitu_*.deb in $build, found: ${debs[*]}" >&2
  exit 1
fi
deb="${debs[0]}"

fail() {
  echo "package: $deb: $*" >&2
  exit 1
}
control="$(dpkg-deb -f "$deb")"
echo "$control" | grep -E '^(Package|Version|Architecture|Depends):'
echo "$control" | grep -q '^Depends: .*libaravis' || fail "Depends lacks the shared libraries"
echo "$control" | grep -q '^Depends: .*adduser' || fail "Depends lacks adduser"
dpkg-deb -I "$deb" conffiles | grep -qx /etc/insitu/insitud.yaml ||
  fail "/etc/insitu/insitud.yaml is not a conffile"

tmp="$(mktemp -d)"
daemon=""
cleanup() {
  if [ -n "$daemon" ]; then kill "$daemon" 2>/dev/null || true; fi
  rm -rf "$tmp"
}
trap cleanup EXIT
dpkg-deb -x "$deb" "$tmp/root"
root="$tmp/root"
for f in usr/bin/insitu usr/bin/insitud etc/insitu/insitud.yaml \
         usr/lib/systemd/system/insitud.service usr/lib/udev/rules.d/99-insitu-lmc.rules \
         usr/share/insitu/config/jobs/scan_step_gauge.yaml usr/share/doc/insitu/README.md; do
  [ -e "$root/$f" ] || fail "no /$f"
done
"$root/usr/bin/insitud" --version || fail "insitud --version failed"
"$root/usr/bin/insitu" --help >/dev/null || fail "insitu --help failed"

# The installed config, its two folders moved into the scratch folder and any free port: the
# extracted daemon runs a shipped job by its documented name (the job's ../worlds and
# ../../calib resolve inside the installed tree), then stops on SIGTERM.
sed -e "s|^results_dir: /var/lib/insitu/results|results_dir: $tmp/results|" \
    -e "s|^jobs_dir: /usr/share/insitu|jobs_dir: $root/usr/share/insitu|" \
    -e 's|^port: 7450|port: 0|' "$root/etc/insitu/insitud.yaml" >"$tmp/insitud.yaml"
grep -q "^results_dir: $tmp/results" "$tmp/insitud.yaml" || fail "results_dir is not the expected"
grep -q "^jobs_dir: $root/" "$tmp/insitud.yaml" || fail "jobs_dir is not the expected"
"$root/usr/bin/insitud" --config "$tmp/insitud.yaml" >"$tmp/insitud.log" 2>&1 &
daemon=$!
port=""
for _ in $(seq 100); do
  port="$(sed -n 's/^insitud: listening on .*:\([0-9]*\)$/\1/p' "$tmp/insitud.log")"
  [ -n "$port" ] && break
  kill -0 "$daemon" 2>/dev/null || break
  sleep 0.1
done
if [ -z "$port" ]; then
  cat "$tmp/insitud.log" >&2
  fail "the extracted insitud did not start with the installed config"
fi
if ! python3 "$root/usr/share/doc/insitu/docs/insitu_client.py" --port "$port" \
       config/jobs/scan_step_gauge.yaml --set scan.x_start_mm=-3 --set scan.x_end_mm=-2 \
       >"$tmp/client.log" 2>&1; then
  cat "$tmp/client.log" "$tmp/insitud.log" >&2
  fail "the extracted insitud did not run config/jobs/scan_step_gauge.yaml"
fi
kill -TERM "$daemon"
wait "$daemon" || fail "the extracted insitud did not stop cleanly on SIGTERM"
daemon=""
echo "package: the extracted insitud ran config/jobs/scan_step_gauge.yaml"
echo "$deb"
