#!/usr/bin/env bash
# `embodied bench mbm` as N shards on one host with GNU parallel, then the merged report.
#
#   examples/batch/parallel.sh URDF SRDF PROBLEMS [N]     (N: default the number of cores)
#
# Shard K of N plans the problems i (families and problems sorted) with i mod N = K - 1 and
# writes them as JSON Lines; `bench merge` joins the shards into the report one process gives.
# OUT (default mbm-shards) holds the shards' files and OMPL logs (Planner Arena).
set -euo pipefail
urdf=$1
srdf=$2
problems=$3
n=${4:-$(nproc)}
out=${OUT:-mbm-shards}
mkdir -p "$out"
parallel --halt now,fail=1 \
    embodied bench mbm --urdf "$urdf" --srdf "$srdf" --problems "$problems" \
    --shard {}/"$n" --jsonl "$out"/shard-{}.jsonl --ompl-log "$out"/ompl \
    ::: $(seq 1 "$n") >"$out"/shards.txt
embodied bench merge "$out"/shard-*.jsonl
