#!/usr/bin/env bash
# What CI runs: a warnings-as-errors Release build with every test, then the tests again
# under AddressSanitizer and UndefinedBehaviorSanitizer, then the parallel tests under
# ThreadSanitizer. Fails on the first error.
set -euo pipefail
cd "$(dirname "$0")/.."

jobs=$(nproc)
bash scripts/install-deps.sh
log=$(mktemp)
trap 'rm -f "$log"' EXIT
run_ctest() { ctest "$@" | tee -a "$log"; }

echo "== Release, -Werror (build-ci)"
cmake -S . -B build-ci -DCMAKE_BUILD_TYPE=Release -DISOTOPE_WERROR=ON
cmake --build build-ci -j "$jobs"
run_ctest --test-dir build-ci --output-on-failure -j2

echo "== RelWithDebInfo, address,undefined sanitizers (build-asan)"
# Assertions stay on here (no NDEBUG): they check the traversal's invariants on every test.
cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g" -DISOTOPE_WERROR=ON \
  -DISOTOPE_SANITIZE=address,undefined -DISOTOPE_BUILD_BENCH=OFF
cmake --build build-asan -j "$jobs"
# The bounded-memory tests (label "slow") measure the Release binary's RSS; under ASan they would
# take most of the CI budget and measure the sanitizer's shadow memory instead. The paged = in-memory
# sweep over the four shared volumes (two minutes under ASan) and the store = in-memory sweep over
# every volume, mode and indicator (70 s) run in Release only, and so do the paged closed shapes (65 s:
# closedness is checked in memory under ASan by test_crack_free); the same code paths run under ASan through
# the synthetic sweep, the round trips and the threads x budgets test.
run_ctest --test-dir build-asan --output-on-failure -j2 -LE slow \
  -E 'PagedEqualsInMemory\.SharedVolumes|Store\.ExtractionFromStoreEqualsInMemory|PagedExtract\.ClosedShapes'

# The parallel paths under ThreadSanitizer (engine/parallel.h runs them on std::threads there).
echo "== RelWithDebInfo, thread sanitizer (build-tsan): parallel tests"
cmake -S . -B build-tsan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g" -DISOTOPE_WERROR=ON \
  -DISOTOPE_SANITIZE=thread -DISOTOPE_BUILD_BENCH=OFF
cmake --build build-tsan --target test_determinism test_store test_paged_extract test_exact_full_resolution -j "$jobs"
TSAN_OPTIONS="halt_on_error=1" run_ctest --test-dir build-tsan --output-on-failure \
  -R 'Determinism|Store\.(FileDoesNotDependOnThreadsOrMemoryBudget|RoundTripIsExactOnOddDimensions|CancelledConvert)|PagedParallel\.|FullResolutionSlabs\.'

# One closing line over the three runs (each ctest above has already failed the script on error).
total=0
for n in $(sed -n 's/.*tests failed out of \([0-9]*\).*/\1/p' "$log"); do total=$((total + n)); done
echo "== all tests passed (Release, ASan+UBSan, TSan)"
echo "$total passed, 0 failed"
