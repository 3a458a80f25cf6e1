#!/usr/bin/env bash
# Byte-identity check of a refactor (issue 42, check 2): runs every scene
# of validation/ (the first STEPS steps, default 20; explicit scenes to
# t = END, default 1e-4 s) with two binaries, on 1 and on 2 threads, and
# compares their curve.csv byte by byte. (Restarts are checked by the test
# suite: a resumed run's curve is byte-identical to an uninterrupted one,
# tests/checkpoint_resume.rs.)
#
#   scripts/compare_curves.sh BASE_BINARY NEW_BINARY [OUT]
#   STEPS=50 scripts/compare_curves.sh /tmp/mpm-geo-base target/release/mpm-geo
#
# Prints one line per scene and thread count (`same`, `DIFFERENT` or
# `refused` when both binaries refuse the truncated scene alike) and exits
# non-zero if any curve differs or only one binary ran a scene.
set -uo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 BASE_BINARY NEW_BINARY [OUT]" >&2
  exit 2
fi
base="$(realpath "$1")"
new="$(realpath "$2")"
cd "$(dirname "$0")/.."
out="${3:-out/compare-curves}"
steps="${STEPS:-20}"
rm -rf "$out"
mkdir -p "$out"
status=0
run() { # binary label scene threads
  local dir="$out/$2/$4/${3//\//_}"
  mkdir -p "$out/$2/$4"
  RAYON_NUM_THREADS=$4 "$1" run "$3" --out "$dir" --quiet \
    --set "scene.steps=$steps" --set scene.end_time= >"$dir.log" 2>&1 ||
    # explicit scenes run to an end time (END s, default 1e-4 s)
    RAYON_NUM_THREADS=$4 "$1" run "$3" --out "$dir" --quiet --overwrite \
      --set "scene.end_time=${END:-1e-4}" >"$dir.log" 2>&1
}
for scene in $(find validation -name '*.toml' ! -name campaign.toml ! -path '*/studies/*' ! -path '*/reference/*' | sort); do
  for threads in 1 2; do
    run "$base" base "$scene" "$threads"
    a=$?
    run "$new" new "$scene" "$threads"
    b=$?
    key="${scene//\//_}"
    if [ $a -ne 0 ] && [ $b -ne 0 ]; then
      verdict=refused
    elif [ $a -ne 0 ] || [ $b -ne 0 ]; then
      verdict="DIFFERENT (exit $a against $b)"
      status=1
    elif cmp -s "$out/base/$threads/$key/curve.csv" "$out/new/$threads/$key/curve.csv"; then
      verdict=same
    else
      verdict=DIFFERENT
      status=1
    fi
    echo "$scene threads=$threads: $verdict"
  done
done
exit $status
