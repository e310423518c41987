#!/usr/bin/env bash
# Installs what building isotope needs on Debian/Ubuntu. Does nothing (and needs no network)
# when every package is already installed.
set -euo pipefail

packages=(
  g++ cmake make pkg-config
  libtbb-dev libhdf5-dev libcli11-dev nlohmann-json3-dev
  libgtest-dev libgmock-dev googletest libbenchmark-dev
  libzstd-dev libxxhash-dev zlib1g-dev
  libplplot-dev plplot-driver-cairo
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg -s "$p" 2>/dev/null | grep -q '^Status: install ok installed'; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

sudo=()
if [ "$(id -u)" -ne 0 ]; then sudo=(sudo); fi
echo "install-deps: installing ${missing[*]}"
"${sudo[@]}" apt-get update
"${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}"
