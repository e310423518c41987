#!/usr/bin/env bash
# Installs what building isotope needs on Debian/Ubuntu, and the viewer's npm packages
# (viewer/package-lock.json). With --tests, also what the tests need: Chromium, for the viewer's
# end-to-end test, scikit-image, the peer the bench runs, clang-14 with libFuzzer, pytest, VTK's
# Python readers, the glTF validator (tests/formats/package-lock.json) and Open MPI. Does nothing (and needs no network) when everything is already installed.
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(
  g++ cmake make pkg-config
  libtbb-dev libhdf5-dev libcli11-dev nlohmann-json3-dev
  libgtest-dev libgmock-dev googletest libbenchmark-dev
  libzstd-dev libxxhash-dev zlib1g-dev
  libplplot-dev plplot-driver-cairo
  libcpp-httplib-dev
  libtiff-dev
  python3-dev python3-venv python3-pip python3-setuptools python3-wheel python3-numpy pybind11-dev python3-pybind11
)
# Node.js bundles the viewer (esbuild) and drives the browser test; a machine that has node and
# npm already (e.g. from NodeSource) keeps them.
if ! command -v node > /dev/null || ! command -v npm > /dev/null; then packages+=(nodejs npm); fi
# python3-skimage: the peer that isotope bench (and its test) times beside ours. clang-14 and its
# runtime libraries (libFuzzer, the sanitizers): the fuzz targets (the fuzz script beside this one).
# clang-format: the style check (format.sh --check beside this one). python3-pytest, python3-vtk9 (VTK's
# readers: the mesh formats read back by the tests) and python3-tifffile (TIFF stacks written by
# the Python tests). libopenmpi-dev and openmpi-bin: the build finds MPI and makes `mpirun -n R
# isotope` share its work (optional: without them the command runs as one process), which
# the MPI tests check. hdf5-filter-plugin: HDF5 datasets compressed by filter plugins (lz4, bzip2),
# which the command reads with its static HDF5 beside the plugins' shared one (a volume-reading test).
if [ "${1:-}" = "--tests" ]; then
  packages+=(chromium python3-skimage clang-14 libclang-rt-14-dev clang-format python3-pytest python3-vtk9 python3-tifffile
    libopenmpi-dev openmpi-bin hdf5-filter-plugin)
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg -s "$p" 2>/dev/null | grep -q '^Status: install ok installed'; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
else
  sudo=()
  if [ "$(id -u)" -ne 0 ]; then sudo=(sudo); fi
  echo "install-deps: installing ${missing[*]}"
  "${sudo[@]}" apt-get update
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}"
fi

# The exact versions of the lock files; each skipped when its lock file has not changed since: the
# viewer's, and with --tests the Khronos glTF validator (tests/formats).
npm_folders=(viewer)
if [ "${1:-}" = "--tests" ]; then npm_folders+=(tests/formats); fi
for folder in "${npm_folders[@]}"; do
  stamp=$folder/node_modules/.isotope-lock-stamp
  if ! cmp -s "$folder/package-lock.json" "$stamp" 2>/dev/null; then
    echo "install-deps: npm ci ($folder)"
    npm ci --prefix "$folder" --no-audit --no-fund --loglevel=error
    cp "$folder/package-lock.json" "$stamp"
  fi
done
