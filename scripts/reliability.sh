#!/usr/bin/env bash
# Regenerates docs/RELIABILITY.md: builds isotope (build/, Release) and the fuzz targets
# (build-fuzz/), fuzzes every parser for a bounded time (fuzz.sh), then tries the command and the
# server as a hostile user would (reliability.py) and writes the table. Fails when a row does not
# hold. CI (the test script) runs the same with --out to a scratch file.
#
#   scripts/reliability.sh [--fuzz-seconds N] [--out FILE] [--isotope BIN] [--python PY] [--no-fuzz-build]
#
# --python: a Python with the isotope module installed (the test script passes its venv's), for
# the module's rows; without it they do not hold.
set -euo pipefail
cd "$(dirname "$0")/.."

fuzz_seconds=60 out=docs/RELIABILITY.md isotope="" python="" fuzz_build=()
while [ $# -gt 0 ]; do
  case "$1" in
    --fuzz-seconds) fuzz_seconds="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --isotope) isotope="$2"; shift 2 ;;
    --python) python="$2"; shift 2 ;;
    --no-fuzz-build) fuzz_build=(--no-build); shift ;;
    -h|--help) sed -n '2,11p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "reliability.sh: unknown argument $1" >&2; exit 2 ;;
  esac
done

if [ -z "$isotope" ]; then
  cmake -S . -B build -DCMAKE_BUILD_TYPE=Release > /dev/null
  cmake --build build -j "$(nproc)" --target isotope
  isotope=build/tools/isotope
fi
stats=$(mktemp)
trap 'rm -f "$stats"' EXIT
bash scripts/fuzz.sh "${fuzz_build[@]}" --seconds "$fuzz_seconds" --stats "$stats"
/usr/bin/python3 scripts/reliability.py --isotope "$isotope" --python "$python" --fuzz-stats "$stats" \
  --fuzz-seconds "$fuzz_seconds" --out "$out"
