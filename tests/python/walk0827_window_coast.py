#!/usr/bin/env python3
"""KF-GINS's inertial coasting in the canyon windows of `tests/tests/estimator/tight_walk.rs`.

  walk0827_window_coast.py --kf-gins BIN [--data DIR] [--work DIR] [--along W=N,E,D …]

The windows are tight_walk.rs's rule: four of 15 s (both ends included), the first 30 s after
the walk's first raw epoch (408639.75 s of week), each 10 s after the previous one ends. One
KF-GINS run per window with the receiver's fixes (`gnss.pos`) withheld in it, and one with all
of them, each with walk0827_bench.py's configuration (the dataset README's noise set E and
initial state). A window's cost is the horizontal distance at its end between its run and the
full run (as tight_walk.rs measures navsync's): the inertial coasting of a second INS on the
same IMU. `--along 1=-0.44,0.88,-0.20` also prints window 1's coasting along that NED
direction (tight_walk.rs prints, per window, the direction its 2 or 3 satellites leave
unmeasured), and its horizontal part. Needs numpy.
"""

import argparse
import math
import os
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import walk0827_bench as wb  # noqa: E402
from bench_common import run  # noqa: E402

FIRST_RAW_SOW = 408639.75
FIRST_AFTER_S, WINDOW_S, GAP_S, WINDOWS = 30.0, 15.0, 10.0, 4
EARTH_RADIUS_M = 6378137.0


def windows():
    first = FIRST_RAW_SOW + FIRST_AFTER_S
    return [(first + i * (WINDOW_S + GAP_S), first + i * (WINDOW_S + GAP_S) + WINDOW_S) for i in range(WINDOWS)]


def kf_gins(binary, data, work, tag, withheld):
    """Runs KF-GINS with the fixes in `withheld` ([start, end] sow, both included) left out;
    returns its navigation result rows (week, sow, lat°, lon°, h m, …)."""
    pos = os.path.join(work, f"gnss_{tag}.pos")
    # walk0827_bench.withhold takes half-open windows: half a 4 Hz interval past the end
    # keeps the window's last epoch in.
    wb.withhold(os.path.join(data, "gnss.pos"), pos, [(s, e + 0.125) for s, e in withheld])
    out = os.path.join(work, tag)
    os.makedirs(out, exist_ok=True)
    cfg = os.path.join(work, f"{tag}.yaml")
    wb.kf_gins_config(cfg, os.path.join(data, "imu.txt"), pos, out, data)
    run([binary, cfg], os.path.join(work, f"{tag}.log"))
    return np.loadtxt(wb.nav_file(out), ndmin=2)


def position_at(nav, sow):
    return [float(np.interp(sow, nav[:, 1], nav[:, c])) for c in (2, 3, 4)]


def main():
    ap = argparse.ArgumentParser(description="KF-GINS's coasting in tight_walk.rs's canyon windows")
    ap.add_argument("--kf-gins", required=True, help="KF-GINS binary")
    ap.add_argument("--data", default=wb.DEFAULT_DATA)
    ap.add_argument("--work", help="working directory (default: a temporary one)")
    ap.add_argument("--along", action="append", default=[], metavar="W=N,E,D",
                    help="window W's (1-based) coasting along this NED direction too")
    args = ap.parse_args()
    along = {}
    for a in args.along:
        try:
            w, d = a.split("=")
            v = [float(x) for x in d.split(",")]
            n = math.sqrt(sum(x * x for x in v))
            if len(v) != 3 or n == 0 or not 1 <= int(w) <= WINDOWS:
                raise ValueError
        except ValueError:
            sys.exit(f"--along {a}: expected W=N,E,D with W in 1..{WINDOWS} and a non-zero direction")
        along[int(w)] = [x / n for x in v]
    work = args.work or tempfile.mkdtemp(prefix="walk0827-coast-")
    os.makedirs(work, exist_ok=True)
    full = kf_gins(args.kf_gins, args.data, work, "full", [])
    print(f"KF-GINS (noise set E) in tight_walk.rs's windows, work dir {work}")
    for i, (start, end) in enumerate(windows()):
        nav = kf_gins(args.kf_gins, args.data, work, f"w{i + 1}", [(start, end)])
        a, b = position_at(nav, end), position_at(full, end)
        north = math.radians(a[0] - b[0]) * EARTH_RADIUS_M
        east = math.radians(a[1] - b[1]) * EARTH_RADIUS_M * math.cos(math.radians(a[0]))
        down = b[2] - a[2]
        line = f"  window {i + 1} [{start:.2f}, {end:.2f}]: cost {math.hypot(north, east):.2f} m " \
               f"(N {north:+.2f}, E {east:+.2f})"
        if i + 1 in along:
            d = along[i + 1]
            x = north * d[0] + east * d[1] + down * d[2]
            line += f"; along ({d[0]:+.2f}, {d[1]:+.2f}, {d[2]:+.2f}) {x:+.2f} m, " \
                    f"horizontal {abs(x) * math.hypot(d[0], d[1]):.2f} m"
        print(line)


if __name__ == "__main__":
    main()
