#!/usr/bin/env bash
# Join the shards a slurm-dataset.sh array wrote into DIR, verifying every checksum.
#SBATCH --job-name=weft-merge
#SBATCH --cpus-per-task=1
#SBATCH --mem=2G
#SBATCH --time=00:30:00
#SBATCH --output=weft-merge-%j.log
set -euo pipefail
dir=${1:?the directory the shards were written to}
repo=${WEFT_REPO:-$(cd "$(dirname "$0")/../.." && pwd)}
"$repo/target/release/xtask" dataset merge --out "$dir" "$dir"
