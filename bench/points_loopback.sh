#!/bin/bash
# points_loopback.sh: `distband at` in-process against `distband at --server` on loopback (QueryPoints), the same mesh
# and N query points (float32, uniform in the mesh's box grown by 10 % a side); both outputs must be byte-identical.
# Prints each side's "done:" line, the throughput ratio and the server's peak RSS (VmHWM) after the stream.
#   bench/points_loopback.sh [MESH.off] [N] [THREADS] [remote-only]     (run from the repository root, after a build)
# remote-only: the bounded-memory check for huge N (issue 23: 10^8 points) — no in-process side; prints the server's
# RSS before the stream (started, nothing uploaded), its peak after, the difference, and the client's peak RSS.
set -euo pipefail
mesh=${1:-/work/shared/data/meshes/armadillo.off}
n=${2:-10000000}
threads=${3:-2}
remote_only=${4:-}
dir=$(mktemp -d)
trap 'kill $server 2>/dev/null || true; rm -rf "$dir"' EXIT
/usr/bin/python3 - "$mesh" "$n" "$dir/q.npy" <<'PY'
import sys, numpy as np
lines = open(sys.argv[1]).read().split('\n')
i = 1
while not lines[i].strip() or lines[i].startswith('#'): i += 1
nv = int(lines[i].split()[0])
v = np.loadtxt(lines[i + 1:i + 1 + nv])
lo, s = v.min(0), v.max(0) - v.min(0)
p = (lo - 0.1 * s + 1.2 * s * np.random.default_rng(5).random((int(sys.argv[2]), 3))).astype(np.float32)
np.save(sys.argv[3], p)
PY
if [ "$remote_only" = remote-only ]; then
  build/server/distband-server --listen 127.0.0.1:50791 --threads "$threads" > "$dir/server.log" 2>&1 &
  server=$!
  sleep 1
  idle_kb=$(awk '/VmRSS/ {print $2}' "/proc/$server/status")
  /usr/bin/time -f "client peak RSS: %M kB" -o "$dir/client.rss" \
    build/client/distband at --server 127.0.0.1:50791 --mesh "$mesh" --at "$dir/q.npy" --out "$dir/remote.npy" |
    grep '^done:'
  peak_kb=$(awk '/VmHWM/ {print $2}' "/proc/$server/status")
  kill -TERM $server; wait $server || true
  grep -o 'QueryPoints.*' "$dir/server.log" | cut -c1-200
  echo "server RSS before the stream: $((idle_kb / 1024)) MiB; peak: $((peak_kb / 1024)) MiB; difference: $(((peak_kb - idle_kb) / 1024)) MiB"
  cat "$dir/client.rss"
  echo "query file: $(($(stat -c %s "$dir/q.npy") / 1048576)) MiB; output: $(($(stat -c %s "$dir/remote.npy") / 1048576)) MiB"
  exit 0
fi
local_line=$(build/client/distband at --mesh "$mesh" --at "$dir/q.npy" --out "$dir/local.npy" --threads "$threads" | grep '^done:')
build/server/distband-server --listen 127.0.0.1:50791 --threads "$threads" > "$dir/server.log" 2>&1 &
server=$!
sleep 1
remote_line=$(build/client/distband at --server 127.0.0.1:50791 --mesh "$mesh" --at "$dir/q.npy" --out "$dir/remote.npy" | grep '^done:')
grep VmHWM "/proc/$server/status" | sed 's/^/server peak RSS: /'
kill -TERM $server; wait $server || true
cmp "$dir/local.npy" "$dir/remote.npy" && echo "outputs byte-identical"
echo "in-process: $local_line"
echo "loopback:   $remote_line"
python3 -c "import re,sys; a=float(re.search(r'\(([0-9.e+]+) points/s',sys.argv[1]).group(1)); b=float(re.search(r'\(([0-9.e+]+) points/s',sys.argv[2]).group(1)); print(f'loopback / in-process throughput: {b/a:.2f}')" "$local_line" "$remote_line"
