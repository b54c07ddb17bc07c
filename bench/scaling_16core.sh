#!/bin/bash
# 1 -> 16 thread scaling of the mesh band and the separable volume paths (docs/benchmarks.md#thread-scaling).
# Usage: bench/scaling_16core.sh OUT_DIR [BUILD_DIR] [MESH]   (on a machine with >= 16 cores; about 9 minutes)
# Writes OUT_DIR/run.log (every table), scaling_armadillo_512_hw20.json and the label suite's JSON.
set -u
out=${1:?OUT_DIR}; build=${2:-build}; mesh=${3:-../shared/data/meshes/armadillo.off}
mkdir -p "$out"; log=$out/run.log
step() { echo "== $(date -u +%H:%M:%S) $*" | tee -a "$log"; }
{ nproc; lscpu | grep -E 'Model name|^CPU\(s\)|Thread|Core|Socket|NUMA|L3'; cat /proc/loadavg; } >> "$log" 2>&1
step scaling_bench
"$build"/bench/scaling_bench --mesh "$mesh" --resolution 512 --half-width 20 --threads 1,2,4,8,16 --reps 3 \
  --serial-fraction 0.007 --json "$out/scaling_armadillo_512_hw20.json" >> "$log" 2>&1
for c in "sphere shell, full domain" "two points (point seeds), full domain" "random blobs, limit 5 voxels"; do
  step edt_peer_bench "$c"
  "$build"/bench/edt_peer_bench --suite seeds --case "$c" --reps 3 --threads 1 2 4 8 16 --compare-band false >> "$log" 2>&1
done
step "edt_peer_bench labels: distband at 16 threads, edt at its best of 1 and 16"
"$build"/bench/edt_peer_bench --suite labels --reps 3 --threads 1 16 --exact-n 32 --label-n 512 \
  --json "$out/edt_labels_16.json" >> "$log" 2>&1
step "edt_peer_bench labels: distband at 1 thread"
"$build"/bench/edt_peer_bench --suite labels --reps 3 --threads 1 --peer false --exact-n 32 --label-n 512 \
  --json "$out/edt_labels_1.json" >> "$log" 2>&1
step done
