#!/usr/bin/env bash
# `embodied bench mbm` as a SLURM array job, one shard per task, then the merged report as a
# job that starts when every task has succeeded.
#
#   examples/batch/slurm.sh URDF SRDF PROBLEMS [N]     (N: default 16 tasks)
#
# OUT (default ./mbm-shards, on a file system every node sees) receives shard-K.jsonl from
# task K and report.txt from the merge job.
set -euo pipefail
urdf=$(realpath "$1")
srdf=$(realpath "$2")
problems=$(realpath "$3")
n=${4:-16}
out=$(realpath -m "${OUT:-mbm-shards}")
mkdir -p "$out"
# Task K (SLURM_ARRAY_TASK_ID, 1..N) plans shard K of N on one core.
job=$(sbatch --parsable --job-name=embodied-mbm --array=1-"$n" --ntasks=1 --cpus-per-task=1 \
    --time=01:00:00 --output="$out/slurm-%a.out" \
    --wrap "embodied bench mbm --urdf '$urdf' --srdf '$srdf' --problems '$problems' \
--shard \$SLURM_ARRAY_TASK_ID/$n --jsonl '$out'/shard-\$SLURM_ARRAY_TASK_ID.jsonl")
echo "array job $job: $n shards"
sbatch --parsable --job-name=embodied-mbm-merge --dependency=afterok:"$job" --output="$out/report.txt" \
    --wrap "embodied bench merge '$out'/shard-*.jsonl"
