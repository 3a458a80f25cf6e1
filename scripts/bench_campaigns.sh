#!/usr/bin/env bash
# Times the paper's campaigns (biaxial, footing, vertical cut and its late
# reading: every mesh and family, the cut with both integrators) at the
# paper's resolutions, and with BASE set, times a base binary on the same
# runs in the same sitting, interleaved (issue 43):
#
#   scripts/bench_campaigns.sh                                  # this build alone
#   BASE=/tmp/mpm-geo-base scripts/bench_campaigns.sh           # against a base binary
#   CAMPAIGNS="biaxial footing" JOBS=1 scripts/bench_campaigns.sh
#   scripts/bench_campaigns.sh --set scene.steps=5              # extra arguments go to every campaign
#
# Each campaign is cut into shards of JOBS runs (default 2: two runs at a
# time, each with a thread pool of all the cores, so the last run left
# keeps both busy); shard k runs with this build and then with BASE, the
# order swapped every other shard so that a drift of the machine's speed
# falls on both alike. Then each binary collects its campaign's report.
# Writes OUT/new/<campaign>/ and OUT/base/<campaign>/ (the campaigns'
# outputs), OUT/bench.log (elapsed time per shard and binary, load) and,
# from every run's run.json, OUT/timings.csv and OUT/timings.md: wall time
# per run and per stage, and with BASE the ratio base/new of each.
#
# A campaign resumes what its output directory already holds (same scenes):
# delete OUT, or set OUT to a new directory, for a fresh timing.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${OUT:-out/bench-campaigns}"
jobs="${JOBS:-2}"
campaigns="${CAMPAIGNS:-biaxial footing vertical_cut vertical_cut_late}"
cargo build --release --quiet
mkdir -p "$out"
new="$out/mpm-geo-new"
cp target/release/mpm-geo "$new"
base="${BASE:+$(realpath "$BASE")}"
log="$out/bench.log"
{
  echo "# $(date -u +%FT%TZ) $(nproc) cores, load: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "# new: git $(git rev-parse --short HEAD 2>/dev/null || echo '?'); base: ${base:-none}; jobs $jobs; extra: $*"
} > "$log"

# runs of a campaign: its scene files times its integrators
runs_of() {
  local dir="validation/$1" scenes integrators
  scenes=$(find "$dir" -maxdepth 1 -name '*.toml' ! -name campaign.toml | wc -l)
  integrators=$(grep -o '"[a-z_]*"' <(grep '^integrators' "$dir/campaign.toml" || true) | wc -l)
  echo $((scenes * (integrators > 0 ? integrators : 1)))
}

# one shard of a campaign with one binary: binary label campaign shard count extra...
shard() {
  local binary=$1 label=$2 c=$3 k=$4 n=$5 start=$SECONDS code=0
  shift 5
  "$binary" campaign "validation/$c" --out "$out/$label/$c" --jobs "$jobs" \
    --shard "$k/$n" "$@" >>"$out/$label-$c.log" 2>&1 || code=$?
  echo "$c shard $k/$n $label: $((SECONDS - start)) s (exit $code), load $(cut -d' ' -f1-3 /proc/loadavg)" | tee -a "$log"
  elapsed[$label]=$((${elapsed[$label]:-0} + SECONDS - start))
}
declare -A elapsed

status=0
dirs=()
for c in $campaigns; do
  runs=$(runs_of "$c")
  count=$(((runs + jobs - 1) / jobs))
  for k in $(seq 1 "$count"); do
    if [ -z "$base" ]; then
      shard "$new" new "$c" "$k" "$count" "$@"
    elif [ $((k % 2)) -eq 1 ]; then
      shard "$new" new "$c" "$k" "$count" "$@"
      shard "$base" base "$c" "$k" "$count" "$@"
    else
      shard "$base" base "$c" "$k" "$count" "$@"
      shard "$new" new "$c" "$k" "$count" "$@"
    fi
  done
  "$new" campaign "validation/$c" --out "$out/new/$c" --collect "$@" >>"$out/new-$c.log" 2>&1 || status=1
  dirs+=("$out/new/$c")
  if [ -n "$base" ]; then
    "$base" campaign "validation/$c" --out "$out/base/$c" --collect "$@" >>"$out/base-$c.log" 2>&1 || status=1
  fi
done
if [ -n "$base" ]; then
  python3 scripts/campaign_timings.py --out "$out" --base "$out/base" "${dirs[@]}"
else
  python3 scripts/campaign_timings.py --out "$out" "${dirs[@]}"
fi
for label in "${!elapsed[@]}"; do
  echo "elapsed $label: ${elapsed[$label]} s" | tee -a "$log"
done
echo "tables: $out/timings.md, $out/timings.csv; elapsed: $log"
exit "$status"
