#!/usr/bin/env bash
# The paper's biaxial mesh study (Figs. 3-5): all eight scenes of
# validation/biaxial, two at a time, then the report. Extra arguments are
# passed to `mpm-geo campaign` (e.g. --set nonlocal.length_scale=0.008 is
# refused for local scenes; use --jobs 1 for timing figures).
set -euo pipefail
cd "$(dirname "$0")/.."
out="${OUT:-out/campaign-biaxial}"
cargo run --release -- campaign validation/biaxial --out "$out" "$@" || status=$?
echo "report: $out/report.md (plots: $out/curves.png, $out/fields_local.png, $out/fields_nonlocal.png)"
exit "${status:-0}"
