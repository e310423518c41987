#!/usr/bin/env bash
# Builds the isotope command of another commit, for `isotope bench --reference`: the commit's files
# exported (git archive) into DIR/src and built in Release into DIR/build, the command alone, with
# the packages the install-deps script installs. Prints the executable's path on its last line.
#
#   bench/build_reference.sh COMMIT [DIR]     DIR: $TMPDIR/isotope-reference-<commit> by default
#   build/tools/isotope bench --reference "$(bench/build_reference.sh 24e105d | tail -n 1)"
set -euo pipefail

if [[ $# -lt 1 || $# -gt 2 || $1 == -h || $1 == --help ]]; then
  sed -n '2,7p' "$0" | sed 's/^# \{0,1\}//'
  [[ $# -ge 1 && ($1 == -h || $1 == --help) ]] && exit 0
  exit 2
fi
repo=$(git -C "$(dirname "$0")" rev-parse --show-toplevel)
if ! sha=$(git -C "$repo" rev-parse --verify --quiet "$1^{commit}"); then
  echo "build_reference.sh: '$1' is not a commit of $repo" >&2
  exit 2
fi
dir=${2:-${TMPDIR:-/tmp}/isotope-reference-${sha:0:12}}
exe=$dir/build/tools/isotope
if [[ -x $exe && -f $dir/commit && $(cat "$dir/commit") == "$sha" ]]; then
  echo "$exe"  # built before
  exit 0
fi
rm -rf "$dir/src"
mkdir -p "$dir/src"
git -C "$repo" archive "$sha" | tar -x -C "$dir/src"
# The viewer's npm packages (the command embeds the viewer): this checkout's where the lock files
# agree, else installed from the reference's lock file as the install-deps script installs them.
viewer=$dir/src/viewer
if [[ -f $viewer/package-lock.json ]]; then
  if [[ -d $repo/viewer/node_modules ]] && cmp -s "$viewer/package-lock.json" "$repo/viewer/package-lock.json"; then
    ln -s "$repo/viewer/node_modules" "$viewer/node_modules"
  else
    npm ci --prefix "$viewer" --no-audit --no-fund > "$dir/npm.log" 2>&1 || { tail -n 20 "$dir/npm.log" >&2; exit 1; }
  fi
fi
echo "build_reference.sh: building ${sha:0:12} in $dir (logs: $dir/cmake.log, $dir/build.log)" >&2
cmake -S "$dir/src" -B "$dir/build" -DCMAKE_BUILD_TYPE=Release > "$dir/cmake.log" 2>&1 ||
  { tail -n 20 "$dir/cmake.log" >&2; exit 1; }
cmake --build "$dir/build" --target isotope -j "$(nproc)" > "$dir/build.log" 2>&1 ||
  { tail -n 20 "$dir/build.log" >&2; exit 1; }
echo "$sha" > "$dir/commit"
echo "$exe"
