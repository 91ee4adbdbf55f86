#!/usr/bin/env bash
# Generate one weft dataset as a Slurm job array: task i computes shard i of n.
#
#   cargo build --release -p xtask                      # once, on a login node
#   JOB=$(sbatch --parsable --array=0-7 docs/jobs/slurm-dataset.sh sheet-ms paper /shared/weft/sheet-ms)
#   sbatch --dependency=afterok:$JOB docs/jobs/slurm-merge.sh /shared/weft/sheet-ms
#
# A task that is pre-empted or re-queued continues where it stopped (--resume). The same
# script runs outside Slurm for testing: SLURM_ARRAY_TASK_ID=0 SLURM_ARRAY_TASK_COUNT=2 ...
#SBATCH --job-name=weft-dataset
#SBATCH --cpus-per-task=2
#SBATCH --mem=4G
#SBATCH --time=04:00:00
#SBATCH --requeue
#SBATCH --output=weft-dataset-%A_%a.log
set -euo pipefail
name=${1:?dataset name, e.g. sheet-ms}
size=${2:-paper}
out=${3:?output directory on a shared filesystem}
repo=${WEFT_REPO:-$(cd "$(dirname "$0")/../.." && pwd)}
i=${SLURM_ARRAY_TASK_ID:?run as an array job (or set SLURM_ARRAY_TASK_ID)}
n=${SLURM_ARRAY_TASK_COUNT:?run as an array job (or set SLURM_ARRAY_TASK_COUNT)}
nice -n 10 "$repo/target/release/xtask" dataset "$name" --size "$size" --shard "$i/$n" --out "$out" --resume --quiet
