#!/usr/bin/env bash
# How much of `cargo xtask`'s build `cargo test --release --workspace` would build again: the
# README's two commands share one target directory, and a unit built with other features (or
# above one that is) is another artifact (docs/BENCHMARKS.md, "A fresh clone's set-up").
# Reads cargo's unit graphs (nightly's `--unit-graph`; nothing is built) and prints the count.
# Needs the nightly toolchain and jq.
set -euo pipefail
cd "$(dirname "$0")/.."
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cargo +nightly build --release -p xtask --unit-graph -Z unstable-options > "$tmp/xtask.json"
cargo +nightly test --release --workspace --no-run --unit-graph -Z unstable-options > "$tmp/tests.json"
jq -rn --slurpfile x "$tmp/xtask.json" --slurpfile t "$tmp/tests.json" '
  def id: {pkg_id, t: .target.name, k: .target.kind, mode, features, profile} | tojson;
  ($t[0].units | map(id) | INDEX(.)) as $built
  | $x[0].units as $units
  # A unit is built again when the test build has no unit like it, or one it depends on is.
  | [$units[] | (id | in($built)) | not] as $differs
  | def again($r):
      ([range(0; $units | length) as $i | $r[$i] or any($units[$i].dependencies[]; $r[.index])]) as $n
      | if $n == $r then $r else again($n) end;
  again($differs) as $again
  | "\($units | length) units in xtask'"'"'s build; \($differs | map(select(.)) | length) built with other features in the test build; \($again | map(select(.)) | length) built again by it"'
