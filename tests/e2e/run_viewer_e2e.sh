#!/usr/bin/env bash
# ctest's entry to the viewer's end-to-end test: makes the two stores it needs (a shared volume,
# hydrogen 64^3, and the paper's algebraic function at 257^3 for the latency check), then runs
# viewer_e2e.mjs in headless Chromium. Screenshots go to OUT (default build/e2e).
#   run_viewer_e2e.sh ISOTOPE_BINARY SHARED_DATA_DIR [OUT]
set -euo pipefail
isotope=$1
data=$2
out=${3:-$(dirname "$isotope")/../e2e}
here=$(cd "$(dirname "$0")" && pwd)
if [ ! -x /usr/bin/chromium ]; then
  echo "viewer e2e: /usr/bin/chromium is missing; scripts/install-deps.sh --tests installs it" >&2
  exit 1
fi
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
"$isotope" convert "$data/hydrogen_64x64x64_float32.raw" "$scratch/hydrogen.isotope" --quiet
"$isotope" generate algebraic --size 257 -o "$scratch/algebraic_257x257x257_float32.raw" --quiet
"$isotope" convert "$scratch/algebraic_257x257x257_float32.raw" "$scratch/algebraic257.isotope" --quiet
rm "$scratch/algebraic_257x257x257_float32.raw"
node "$here/viewer_e2e.mjs" --isotope "$isotope" --store "$scratch/hydrogen.isotope" \
  --latency-store "$scratch/algebraic257.isotope" --out "$out"
