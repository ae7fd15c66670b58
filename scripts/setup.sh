#!/usr/bin/env bash
# Installs every Debian package insitu needs to build, test and benchmark.
# Idempotent: packages already present are skipped; safe to run again.
# Needs root (or sudo) on Debian 12; the only network it uses is the package mirror.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build ccache pkg-config git
  libeigen3-dev libopencv-dev libaravis-dev aravis-tools libpcl-dev libflann-dev
  libceres-dev libusb-1.0-0-dev
  libyaml-cpp-dev nlohmann-json3-dev libspdlog-dev libcli11-dev libasio-dev
  libqrencode-dev libdmtx-dev libzbar-dev libtinyxml2-dev
  libfreetype-dev libfontconfig-dev fonts-dejavu-core hershey-fonts-data
  libgtest-dev libgmock-dev libbenchmark-dev
  python3
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "setup: all ${#PACKAGES[@]} packages present"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
    echo "setup: missing packages (${missing[*]}) and not root; rerun as root" >&2
    exit 1
  fi
fi

echo "setup: installing ${#missing[@]} packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
echo "setup: done"
