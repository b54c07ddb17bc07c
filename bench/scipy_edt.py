#!/usr/bin/python3
"""The benchmark's peer: scipy's exact Euclidean distance transform, timed on the bench's own input.

Called by bench/engine_bench as a subprocess (use Debian's /usr/bin/python3, which has numpy and scipy):

    scipy_edt.py --mask MASK.npy --reps R [--out EDT.npy]

MASK.npy holds a uint8 array of shape (Z, Y, X); nonzero voxels are the seeds. The peer computes the distance of
every voxel to the nearest seed voxel centre, scipy.ndimage.distance_transform_edt(mask == 0), R times, and prints
one JSON line: {"peer": "scipy.ndimage.distance_transform_edt", "times_s": [...], "median_s": ..., "scipy": ver}.
Only the distance_transform_edt call is timed (the mask == 0 conversion and file I/O are not). scipy's EDT is
single-threaded. With --out, the (exact) result of the last repetition is written as float32.
"""
import argparse
import json
import statistics
import sys
import time

import numpy as np
import scipy
from scipy import ndimage


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mask", required=True, help="uint8 .npy of shape (Z, Y, X), nonzero = seed")
    parser.add_argument("--reps", type=int, default=3, help="repetitions; the median is reported")
    parser.add_argument("--out", help="write the distance field of the last repetition here (float32 .npy)")
    args = parser.parse_args()
    if args.reps < 1:
        print("--reps must be >= 1", file=sys.stderr)
        return 2
    try:
        mask = np.load(args.mask)
    except (OSError, ValueError) as err:
        print(f"cannot read mask {args.mask}: {err}", file=sys.stderr)
        return 2
    if mask.ndim != 3 or not mask.any():
        print(f"mask {args.mask} must be a 3-D array with at least one nonzero voxel", file=sys.stderr)
        return 2
    background = mask == 0
    times = []
    edt = None
    for _ in range(args.reps):
        edt = None  # release the previous result so the peak memory is one result, like the bench's
        t0 = time.perf_counter()
        edt = ndimage.distance_transform_edt(background)
        times.append(time.perf_counter() - t0)
    if args.out:
        np.save(args.out, edt.astype(np.float32))
    print(json.dumps({"peer": "scipy.ndimage.distance_transform_edt", "times_s": times,
                      "median_s": statistics.median(times), "scipy": scipy.__version__}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
