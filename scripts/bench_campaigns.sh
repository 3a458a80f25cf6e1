#!/usr/bin/env bash
# Times the paper's three campaigns (biaxial, footing, vertical cut) at the
# paper's resolutions and writes a table of the wall time per run and per
# stage (issue 15): OUT/timings.md and OUT/timings.csv, from every run's
# run.json profile, and OUT/bench.log with each campaign's elapsed time.
#
#   scripts/bench_campaigns.sh                    # all three, 2 runs at a time
#   JOBS=1 scripts/bench_campaigns.sh             # one run at a time (cleanest per-run figures)
#   CAMPAIGNS="biaxial footing" scripts/bench_campaigns.sh
#   scripts/bench_campaigns.sh --set scene.steps=5   # extra arguments go to every campaign
#   scripts/bench_campaigns.sh --set 'solver.linear_solver="multifrontal"'   # the multifrontal LU (issue 15)
#
# A campaign resumes what its output directory already holds (same scenes):
# delete OUT, or set OUT to a new directory, for a fresh timing.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${OUT:-out/bench-campaigns}"
jobs="${JOBS:-2}"
campaigns="${CAMPAIGNS:-biaxial footing vertical_cut}"
cargo build --release --quiet
mkdir -p "$out"
log="$out/bench.log"
{
  echo "# $(date -u +%FT%TZ) $(nproc) cores, load: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "# git $(git rev-parse --short HEAD 2>/dev/null || echo '?'), jobs $jobs, extra: $*"
} > "$log"
dirs=()
status=0
for c in $campaigns; do
  start=$SECONDS
  ./target/release/mpm-geo campaign "validation/$c" --out "$out/$c" --jobs "$jobs" "$@" || status=$?
  echo "$c: elapsed $((SECONDS - start)) s (exit $status), load after: $(cut -d' ' -f1-3 /proc/loadavg)" | tee -a "$log"
  dirs+=("$out/$c")
done
python3 scripts/campaign_timings.py --out "$out" "${dirs[@]}"
echo "tables: $out/timings.md, $out/timings.csv; elapsed: $log"
exit "$status"
