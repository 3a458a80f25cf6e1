#!/usr/bin/env bash
# Spread one mpm-geo campaign (or study) over a Slurm cluster: a job array with
# one shard per task, then a collect job that runs when every task has ended
# and builds the report from the runs the shards left.
#
#   scripts/slurm_campaign.sh campaign validation/footing 6 out/campaign-footing
#   scripts/slurm_campaign.sh study validation/studies/biaxial_nonlocal.toml 4 out/study-biaxial
#
# Arguments: the command (campaign or study), its directory or spec, the
# number of shards N, the output directory (on a file system every node sees).
# Extra sbatch options go in SBATCH_ARGS (e.g. SBATCH_ARGS="--partition=short
# --time=02:00:00"); MPM_GEO names the binary (default target/release/mpm-geo,
# built first with `cargo build --release`).
#
# Each task runs `mpm-geo <command> <input> --shard K/N --out <out>`; runs
# already finished in <out> (same scene) are not run again, so a failed or
# timed-out task is simply resubmitted. The collect job runs
# `mpm-geo <command> <input> --collect --out <out>`. A campaign's tasks run
# their scenes two at a time (--jobs 2, the default); a study's runs one at a
# time so their timings do not compete (give its tasks whole nodes, or read
# its wall times as machine-dependent).
set -euo pipefail

if [ $# -ne 4 ]; then
    sed -n '2,22p' "$0" | sed 's/^# \{0,1\}//'
    exit 2
fi
command=$1 input=$2 shards=$3 out=$4
case "$command" in
    campaign | study) ;;
    *) echo "error: the command is campaign or study, not '$command'" >&2; exit 2 ;;
esac
if ! [[ "$shards" =~ ^[1-9][0-9]*$ ]]; then
    echo "error: the number of shards must be a positive integer, not '$shards'" >&2
    exit 2
fi
binary=${MPM_GEO:-target/release/mpm-geo}
if [ ! -x "$binary" ]; then
    echo "error: $binary not found: run 'cargo build --release' or set MPM_GEO" >&2
    exit 2
fi
mkdir -p "$out/slurm"
read -r -a extra <<< "${SBATCH_ARGS:-}"

array_job=$(sbatch --parsable "${extra[@]}" \
    --job-name="mpm-geo-$command" \
    --array="1-$shards" \
    --output="$out/slurm/shard-%a.log" \
    --wrap="'$binary' $command '$input' --shard \${SLURM_ARRAY_TASK_ID}/$shards --out '$out'")
collect_job=$(sbatch --parsable "${extra[@]}" \
    --job-name="mpm-geo-collect" \
    --dependency="afterany:$array_job" \
    --output="$out/slurm/collect.log" \
    --wrap="'$binary' $command '$input' --collect --out '$out'")
echo "submitted shards: job $array_job (array 1-$shards); collect: job $collect_job"
echo "logs in $out/slurm/; report in $out/report.md once job $collect_job has run"
