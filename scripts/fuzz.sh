#!/usr/bin/env bash
# Builds the libFuzzer targets of fuzz/ with clang-14 under ASan+UBSan (build-fuzz) and runs each
# one for a bounded time from its seed corpus (fuzz/corpus/TARGET, copied: the repository is not
# changed), one target per core at a time. A finding (crash, sanitizer report, leak, timeout, out-of-memory) fails the script and
# leaves its reproducer in build-fuzz/findings; add it to tests/golden (docs/RELIABILITY.md) once
# fixed. CI runs this after the tests (the test script beside this one).
#
#   scripts/fuzz.sh [--seconds N] [--stats FILE] [--no-build] [TARGET...]
#
# --seconds: per target (default 60); --stats: one line per target, "TARGET EXECUTIONS SECONDS",
# for the reliability script beside this one.
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=60 stats="" build=1 targets=()
while [ $# -gt 0 ]; do
  case "$1" in
    --seconds) seconds="$2"; shift 2 ;;
    --stats) stats="$2"; shift 2 ;;
    --no-build) build=0; shift ;;
    -h|--help) sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    -*) echo "fuzz.sh: unknown option $1" >&2; exit 2 ;;
    *) targets+=("$1"); shift ;;
  esac
done
[ ${#targets[@]} -gt 0 ] || targets=(store nrrd raw_name tiff serve_request serve_http)

if [ "$build" = 1 ]; then
  cmake -S . -B build-fuzz -DCMAKE_C_COMPILER=clang-14 -DCMAKE_CXX_COMPILER=clang++-14 -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DISOTOPE_FUZZ=ON -DISOTOPE_SANITIZE=address,undefined -DISOTOPE_WERROR=ON > /dev/null
  cmake --build build-fuzz -j "$(nproc)"
fi

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p build-fuzz/findings
[ -z "$stats" ] || : > "$stats"
for t in "${targets[@]}"; do
  [ -d "fuzz/corpus/$t" ] || { echo "fuzz.sh: no corpus fuzz/corpus/$t" >&2; exit 2; }
done
# One target per core at a time: each gets its whole time on a core of its own, and the run takes
# the sum of the times divided by the cores.
fuzz_one() {
  local t="$1"
  mkdir -p "$work/$t"
  cp fuzz/corpus/"$t"/* "$work/$t/"
  # -timeout: one input taking 10 s is a hang; -rss_limit_mb: memory must stay bounded whatever
  # the input says (a store of 64 KB may not make the reader allocate gigabytes).
  ASAN_OPTIONS="detect_leaks=1" UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1" \
    "build-fuzz/fuzz/fuzz_$t" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -max_len=65536 \
    -print_final_stats=1 -artifact_prefix="build-fuzz/findings/$t-" "$work/$t" > "$work/$t.log" 2>&1
}
cores=$(nproc)
for ((first = 0; first < ${#targets[@]}; first += cores)); do
  batch=("${targets[@]:first:cores}")
  pids=()
  for t in "${batch[@]}"; do
    echo "== fuzz_$t for ${seconds} s"
    fuzz_one "$t" &
    pids+=($!)
  done
  for i in "${!batch[@]}"; do
    t="${batch[$i]}"
    log="$work/$t.log"
    if ! wait "${pids[$i]}"; then
      grep -A40 -E "ERROR|WARNING|runtime error|Deadly|timeout|out-of-memory" "$log" | head -80 >&2 || tail -40 "$log" >&2
      echo "fuzz.sh: fuzz_$t found a failure; reproducer in build-fuzz/findings/" >&2
      kill "${pids[@]}" 2> /dev/null || true
      exit 1
    fi
    runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")
    echo "fuzz_$t: $runs executions in ${seconds} s, no finding"
    [ -z "$stats" ] || echo "$t $runs $seconds" >> "$stats"
  done
done
