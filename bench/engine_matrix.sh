#!/usr/bin/env bash
# Answers of every engine path, for a bitwise comparison of two builds (a
# refactor must not change one bit): traces ~80 configurations (each
# strategy, both brick structures and triangle tests, any-hit, small budgets
# with and without trace-ahead, the subtree tier, --reference) and serve +
# query over shared memory and over gRPC bytes, on the bunny and a small
# generated city. Compare two output folders with bench/compare_outputs.py.
#
# Usage: bench/engine_matrix.sh OUTCORE_BINARY OUT_DIR [WORK_DIR]
#   WORK_DIR (default build/bench-matrix) holds the stores and rays; reuse it
#   for both builds so they trace the same inputs.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BIN=$(realpath "$1"); OUT=$(realpath -m "$2"); W=$(realpath -m "${3:-$ROOT/build/bench-matrix}")
mkdir -p "$OUT" "$W"
PY="$ROOT/.venv/bin/python"; MR="$ROOT/bench/make_rays.py"
M="$ROOT/tests/data/models"
if [ ! -d "$W/bunny" ]; then
  "$BIN" pack $M/stanford-bunny.obj --brick-tris 2000 -o $W/bunny >/dev/null
  "$BIN" pack "gen:city?of=(gen:sphere?level=4)&copies=200" --brick-tris 8000 -o $W/city >/dev/null
  for s in bunny city; do
    "$BIN" info $W/$s --json > $W/$s.info.json
  done
fi
for s in bunny city; do
  for k in incoherent camera; do
    [ -f $W/$s-$k.npy ] || $PY $MR $W/$s.info.json $k 200000 $W/$s-$k.npy >/dev/null
  done
done
run() { # name scene rays args...
  local name=$1 s=$2 r=$3; shift 3
  "$BIN" trace $W/$s --rays $W/$s-$r.npy -o $OUT/$name.npy --threads 2 --stats-json $OUT/$name.stats.json "$@" >/dev/null 2>$OUT/$name.err
}
for s in bunny city; do for r in incoherent camera; do
  p=$s-$r
  run $p-default $s $r
  run $p-repeat $s $r --repeat 2
  run $p-nobrickset $s $r --no-brick-set --repeat 2
  run $p-queued $s $r --no-brick-set --no-in-cache-sweep --repeat 2
  run $p-seq $s $r --no-reorder
  run $p-small $s $r --cache-mb 8
  run $p-small-nta $s $r --cache-mb 8 --no-trace-ahead
  run $p-bvh $s $r --brick-accel bvh --repeat 2
  run $p-bvh-small $s $r --brick-accel bvh --cache-mb 8
  run $p-bvh-mt $s $r --brick-accel bvh --triangle-test mt
  run $p-bvh-double $s $r --brick-accel bvh --triangle-test double
  run $p-anyhit $s $r --any-hit --repeat 2
  run $p-anyhit-small $s $r --any-hit --cache-mb 8
  run $p-anyhit-seq $s $r --any-hit --no-reorder
  run $p-noproxy $s $r --no-proxies --cache-mb 8
  run $p-noavx $s $r --no-avx-upper --no-brick-set
  run $p-spawn $s $r --spawn-out $OUT/$p-spawn.origins.npy
  rm -rf $OUT/tier; run $p-tier $s $r --brick-accel bvh --cache-mb 8 --subtree-dir $OUT/tier --repeat 2
  run $p-lfu $s $r --cache-mb 8 --policy gdsf
  run $p-ref $s $r --reference --cache-mb 64 || true
done; done
# remote: serve + query, shm and bytes
PORTF=$W/port
for s in bunny city; do
  "$BIN" serve $W/$s --listen 127.0.0.1:0 --cache-mb 6 > $OUT/serve.log 2>&1 & SP=$!
  for i in $(seq 100); do grep -qo '127.0.0.1:[0-9]*' $OUT/serve.log && break; sleep 0.1; done
  ADDR=$(grep -o '127.0.0.1:[0-9][0-9]*' $OUT/serve.log | head -1)
  for r in incoherent camera; do
    "$BIN" query --server $ADDR --rays $W/$s-$r.npy -o $OUT/$s-$r-q-shm.npy >/dev/null
    "$BIN" query --server $ADDR --rays $W/$s-$r.npy -o $OUT/$s-$r-q-bytes.npy --no-shared-memory --chunk-rays 30000 >/dev/null
    "$BIN" query --server $ADDR --rays $W/$s-$r.npy -o $OUT/$s-$r-q-any.npy --any-hit >/dev/null
  done
  kill -INT $SP; wait $SP || true
done
rm -rf $OUT/tier; echo done
