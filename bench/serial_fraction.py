#!/usr/bin/env python3
"""serial_fraction.py: Amdahl's serial fraction of a 1-thread run, from a frame-pointer perf profile.

The scaling goal is >= 12x from 1 to 16 threads; without a 16-core machine the argument is a profile. This
reads `perf script` output of a 1-thread run of a binary built with frame pointers (scripts in docs/benchmarks.md,
"Scaling") and sorts every sample into:

  parallel  a frame of its call chain is a TBB parallel body instantiated in our code (start_for, start_reduce,
            parallel_sort's bodies, task_group tasks, parallel_invoke) - work that 16 threads share;
  serial    everything else under the measured region - work one thread does while the others wait.

Samples outside the region (process start-up, the peer, reading inputs) are dropped: only chains through one of
the --region symbols count. Kernel samples (page faults, zeroing pages) are classified by their user-space chain,
which frame pointers make reliable (DWARF unwinding loses most of them, and so overcounts serial work).
GCC 12 gives leaf functions no frame even with -mno-omit-leaf-frame-pointer, so a sample in a leaf loses the leaf's
caller: when the frame right above the leaf is inside libtbb, that caller was a TBB task body (our code is entered
from libtbb only through tasks), and the sample counts as parallel.

Then S(n) = 1 / (s + (1 - s) / n) for n = 2 and 16, the predicted 1 -> 2 speedup to compare with the measured one,
and the serial symbols that cost most. It is a bound from above: it ignores memory bandwidth, load imbalance inside
parallel loops and fork/join overhead (counted separately by the caller from the number of parallel regions).

Usage: perf script -i perf.data | bench/serial_fraction.py --region BandRun::run [--region ...] [--top 12]
"""
import argparse
import collections
import re
import sys

PARALLEL_MARKERS = (
    "tbb::detail::d1::start_for<",
    "tbb::detail::d1::start_reduce<",
    "tbb::detail::d1::start_deterministic_reduce<",
    "tbb::detail::d1::quick_sort_pretest_body<",
    "tbb::detail::d1::quick_sort_body<",
    "tbb::detail::d1::function_task<",
    "tbb::detail::d1::function_invoker<",
    "tbb::detail::d1::invoke_subroot_task<",
    "tbb::detail::d1::start_parallel_for_each<",
)


def samples(stream, with_dso=False):
    """Yields each sample's frames (symbol names, or (symbol, dso) pairs; innermost first)."""
    frames = []
    in_sample = False
    for line in stream:
        if not line.strip():
            if in_sample:
                yield frames
            frames, in_sample = [], False
            continue
        if not line.startswith((" ", "\t")):
            in_sample = True  # the header line: comm pid time event
            continue
        m = re.match(r"\s+[0-9a-f]+\s+(.*?)\s+\((.*)\)\s*$", line)
        if m:
            frames.append((m.group(1), m.group(2)) if with_dso else m.group(1))
    if in_sample:
        yield frames


def called_by_a_task(frames):
    """The innermost user-space frame's next frame is in libtbb: a frameless leaf called by a task body."""
    user = [i for i, (_, dso) in enumerate(frames) if "kernel.kallsyms" not in dso]
    return len(user) >= 2 and "libtbb" in frames[user[1]][1] and "libtbb" not in frames[user[0]][1]


def short(symbol):
    symbol = re.sub(r"\+0x[0-9a-f]+$", "", symbol)
    return symbol if len(symbol) < 110 else symbol[:107] + "..."


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--region", action="append", required=True,
                    help="a substring of a symbol whose calls make up the measured region (repeatable)")
    ap.add_argument("--top", type=int, default=12)
    ap.add_argument("--measured-speedup", type=float, help="the measured 1 -> 2 speedup, to compare with")
    args = ap.parse_args()

    total = serial = dropped = 0
    serial_leaf = collections.Counter()
    serial_owner = collections.Counter()
    for framed in samples(sys.stdin, with_dso=True):
        frames = [f for f, _ in framed]
        in_region = [i for i, f in enumerate(frames) if any(r in f for r in args.region)]
        if not in_region:
            dropped += 1
            continue
        total += 1
        outer = in_region[-1]  # the outermost region frame: everything inside it counts
        inner = frames[:outer + 1]
        if any(any(m in f for m in PARALLEL_MARKERS) for f in inner) or called_by_a_task(framed):
            continue
        serial += 1
        serial_leaf[short(frames[0])] += 1
        # The first frame of our own code above the leaf: which phase is serial.
        owner = next((f for f in inner if "distband::" in f), frames[0])
        serial_owner[short(owner)] += 1
    if total == 0:
        sys.exit("serial_fraction: no sample under the region symbols " + ", ".join(args.region))
    s = serial / total

    def amdahl(n):
        return 1.0 / (s + (1.0 - s) / n)

    print(f"samples in the region: {total} (dropped outside it: {dropped})")
    print(f"serial samples: {serial} -> s = {100 * s:.2f} %")
    print(f"Amdahl: S(2) = {amdahl(2):.2f}x, S(16) = {amdahl(16):.1f}x (12x needs s <= 2.2 %)")
    if args.measured_speedup:
        print(f"measured 1 -> 2 speedup: {args.measured_speedup:.2f}x")
    print(f"\nserial samples by the innermost distband frame (top {args.top}):")
    for name, n in serial_owner.most_common(args.top):
        print(f"  {n:6d}  {100 * n / total:5.2f} %  {name}")
    print(f"\nserial samples by leaf symbol (top {args.top}):")
    for name, n in serial_leaf.most_common(args.top):
        print(f"  {n:6d}  {100 * n / total:5.2f} %  {name}")


if __name__ == "__main__":
    main()
