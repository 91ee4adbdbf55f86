#!/usr/bin/env bash
# Two `embed` models training at once in one `evaluate` process, under each setting of the
# two process-wide variables `cargo xtask evaluate` sets when it trains more than one model
# at once (crates/weft-experiments/src/evaluate/concurrent_env.rs, CONCURRENT_ENV): candle's elementwise pool
# (CANDLE_NUM_THREADS) and mimalloc's purging of freed memory (MIMALLOC_PURGE_DELAY).
#
# Each setting starts a fresh standard `embed` evaluation in a temporary directory whose
# first scene (`sheet-ms`) is restored from SRC's scene file and whose `sheet-ms-holes`
# dataset is SRC's (linked, read only), so the process goes straight to training that
# scene's `no-pb` seeds 0 and 1 at once. After both have run EPOCHS stage-1 epochs the
# process is stopped; the table gives the median (min–max) of both models' `train_seconds`
# per epoch, leaving out each model's first SKIP epochs (warm-up).
#
# "neither" keeps both libraries' defaults while still counting as set, so `evaluate` does
# not re-execute itself: CANDLE_NUM_THREADS=0 means "as many as rayon" to candle 0.11, and
# 10 ms is mimalloc 2's default purge delay.
#
# Usage: benches/concurrent_env.sh [SRC]     (SRC: default out/evaluate-standard)
#   XTASK (default target/release/xtask), EPOCHS (default 10), SKIP (default 2),
#   KEEP=1 keeps each setting's log under out/concurrent-env/.
# Run it on an otherwise idle machine; it takes about a minute and a half per setting.
set -euo pipefail

SRC=${1:-out/evaluate-standard}
XTASK=${XTASK:-target/release/xtask}
EPOCHS=${EPOCHS:-10}
SKIP=${SKIP:-2}
for need in "$XTASK" "$SRC/embed/scenes/sheet-ms.json" "$SRC/embed/data/sheet-ms-holes/manifest.json"; do
    [[ -e $need ]] || { echo "concurrent_env: $need is missing (a standard embed evaluation's sheet-ms scene and sheet-ms-holes dataset are needed)" >&2; exit 2; }
done
SRC=$(cd "$SRC" && pwd)
XTASK=$(cd "$(dirname "$XTASK")" && pwd)/$(basename "$XTASK")
logs=out/concurrent-env
mkdir -p "$logs"

settings=(
    "neither|CANDLE_NUM_THREADS=0 MIMALLOC_PURGE_DELAY=10"
    "MIMALLOC_PURGE_DELAY=-1|CANDLE_NUM_THREADS=0 MIMALLOC_PURGE_DELAY=-1"
    "CANDLE_NUM_THREADS=1|CANDLE_NUM_THREADS=1 MIMALLOC_PURGE_DELAY=10"
    "both|CANDLE_NUM_THREADS=1 MIMALLOC_PURGE_DELAY=-1"
)

# `train_seconds` of the epochs after SKIP, both models, from an evaluate log.
epoch_seconds() {
    sed -nE 's/^\[no-pb\/seed-[01]\] embed\/sheet-ms-holes stage 1: epoch ([0-9]+)\/[0-9]+: .*, ([0-9.]+) s \+ [0-9.]+ s validation$/\1 \2/p' "$1" |
        awk -v skip="$SKIP" '$1 > skip { print $2 }'
}

echo "| environment | epochs | median epoch | min–max |"
echo "|---|---|---|---|"
for s in "${settings[@]}"; do
    name=${s%%|*}
    vars=${s#*|}
    tmp=$(mktemp -d)
    mkdir -p "$tmp/embed/scenes" "$tmp/embed/data"
    cp "$SRC/embed/scenes/sheet-ms.json" "$tmp/embed/scenes/"
    ln -s "$SRC/embed/data/sheet-ms-holes" "$tmp/embed/data/sheet-ms-holes"
    log="$logs/$(echo "$name" | tr -c 'A-Za-z0-9\n' '-').log"
    # setsid: the evaluation and its threads form one group, stopped together.
    env $vars setsid "$XTASK" evaluate --size standard --only embed --jobs 2 --out "$tmp" >"$log" 2>&1 &
    pid=$!
    while kill -0 "$pid" 2>/dev/null; do
        n0=$(grep -cE "^\[no-pb/seed-0\] embed/sheet-ms-holes stage 1: epoch [0-9]+/" "$log" || true)
        n1=$(grep -cE "^\[no-pb/seed-1\] embed/sheet-ms-holes stage 1: epoch [0-9]+/" "$log" || true)
        ((n0 >= EPOCHS && n1 >= EPOCHS)) && break
        if grep -qE "^\[[^]]+\] embed/sheet-ms stage" "$log"; then
            kill -- "-$pid" 2>/dev/null || true
            echo "concurrent_env: $SRC's sheet-ms scene was made under another configuration, so the evaluation trains sheet-ms first; use a standard run of this version" >&2
            exit 2
        fi
        sleep 1
    done
    kill -- "-$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
    rm -rf "$tmp"
    mapfile -t t < <(epoch_seconds "$log" | sort -g)
    if ((${#t[@]} == 0)); then
        echo "concurrent_env: no epochs under $name; see $log" >&2
        exit 1
    fi
    median=$(printf '%s\n' "${t[@]}" | awk '{ a[NR] = $1 } END { print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2 }')
    echo "| $name | ${#t[@]} | $median s | ${t[0]}–${t[-1]} s |"
    [[ ${KEEP:-0} == 1 ]] || rm -f "$log"
done
