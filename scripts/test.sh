#!/usr/bin/env bash
# What CI runs: a warnings-as-errors Release build with every test, then the tests again
# under AddressSanitizer and UndefinedBehaviorSanitizer. Fails on the first error.
set -euo pipefail
cd "$(dirname "$0")/.."

jobs=$(nproc)
bash scripts/install-deps.sh

echo "== Release, -Werror (build-ci)"
cmake -S . -B build-ci -DCMAKE_BUILD_TYPE=Release -DISOTOPE_WERROR=ON
cmake --build build-ci -j "$jobs"
ctest --test-dir build-ci --output-on-failure -j2

echo "== RelWithDebInfo, address,undefined sanitizers (build-asan)"
cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DISOTOPE_WERROR=ON \
  -DISOTOPE_SANITIZE=address,undefined -DISOTOPE_BUILD_BENCH=OFF
cmake --build build-asan -j "$jobs"
ctest --test-dir build-asan --output-on-failure -j2

echo "== all tests passed"
