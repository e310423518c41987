#!/usr/bin/env bash
# Fresh machine to the paper's Table 1: dependencies, Release build, isotope demo.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/install-deps.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release
cmake --build build --target isotope -j "$(nproc)"
build/tools/isotope demo --out demo_out
