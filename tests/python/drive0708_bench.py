#!/usr/bin/env python3
"""The drive0708 outage benchmark, end to end: navsync (and optionally KF-GINS) on the same files.

  drive0708_bench.py [--navsync BIN] [--data DIR] [--work DIR] [--windows N]
                     [--config YAML] [--kf-gins BIN] [--json OUT] [-- REPLAY FLAGS…]

1. Withholds the GNSS epochs of the benchmark's windows (score_outages.py; the dataset README,
   "Outage benchmark") from the receiver's position/velocity file (gnss_posvel.txt, KF-GINS-Matlab
   layout) and, for KF-GINS, from gnss.pos.
2. Writes the KF-GINS configuration (default kfgins_configs/drive0708.yaml: the README's
   suggested IMU noise, the lever arm, the initial state; see its header) with this run's paths;
   with --windows N < 11 the data end 30 s after the N-th window (a shortened run).
3. `navsync import kf-gins --gnss-layout matlab --kf-gins-config …`: the same configuration goes
   into the recording; `navsync replay --estimate --format kf-gins` with its defaults (plus
   any REPLAY FLAGS).
4. Scores the result (and KF-GINS's, with --kf-gins) with score_outages.score and prints them
   side by side; --json writes them with navsync's summary (fixes, rejections, Δ).
Exits non-zero when a step fails or a result is missing. Needs numpy.
"""

import argparse
import json
import os
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import score_outages  # noqa: E402
from bench_common import run  # noqa: E402

REPO = os.path.dirname(os.path.dirname(HERE))
DEFAULT_DATA = os.environ.get(
    "NAVSYNC_DRIVE0708_DIR",
    os.path.join(os.path.dirname(REPO), "shared", "datasets", "rtklibexplorer-drive0708"))
if not os.path.isdir(DEFAULT_DATA) and os.environ.get("NAVSYNC_SHARED_DIR"):
    DEFAULT_DATA = os.path.join(os.environ["NAVSYNC_SHARED_DIR"], "datasets", "rtklibexplorer-drive0708")


def windows_args(n, data):
    return argparse.Namespace(first=243296.5, outage=15.0, period=45.0, windows=n, data=data,
                              lever=[0.0, -0.05, 0.0], settle=1.0)


def withhold(src, dst, wins, end_sow):
    kept = 0
    with open(src) as fi, open(dst, "w") as fo:
        for line in fi:
            f = line.split()
            if not f or line.lstrip().startswith(("#", "%")):
                continue
            t = float(f[0])
            if t > end_sow or score_outages.window_index(np.array([t]), wins)[0] >= 0:
                continue
            fo.write(line)
            kept += 1
    return kept


def write_config(template, dst, imu, gnss, out_dir, end_sow):
    """The KF-GINS YAML with this run's paths and end time (the keys are rewritten in place)."""
    keys = {"imupath": f'"{imu}"', "gnsspath": f'"{gnss}"', "outputpath": f'"{out_dir}"',
            "endtime": f"{end_sow:.3f}" if end_sow is not None else "-1"}
    with open(template) as fi, open(dst, "w") as fo:
        for line in fi:
            key = line.split(":", 1)[0].strip()
            if key in keys and not line.lstrip().startswith("#"):
                fo.write(f"{key}: {keys.pop(key)}\n")
            else:
                fo.write(line)
        for key, value in keys.items():
            fo.write(f"{key}: {value}\n")


def score(result, wargs):
    if not os.path.exists(result) or os.path.getsize(result) == 0:
        sys.exit(f"no result in {result}")
    a = argparse.Namespace(**vars(wargs), result=result)
    return score_outages.score(a)


def main():
    ap = argparse.ArgumentParser(description="drive0708 outage benchmark, navsync vs KF-GINS")
    ap.add_argument("--navsync", default=os.path.join(REPO, "target", "release", "navsync"))
    ap.add_argument("--data", default=DEFAULT_DATA)
    ap.add_argument("--work", help="working directory (default: a temporary one)")
    ap.add_argument("--windows", type=int, default=11, help="outage windows (11: the whole drive)")
    ap.add_argument("--config", default=os.path.join(HERE, "kfgins_configs", "drive0708.yaml"))
    ap.add_argument("--kf-gins", help="KF-GINS binary: run it on the same files")
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("replay_flags", nargs="*", help="extra `navsync replay` flags (after --)")
    args = ap.parse_args()
    for f in ("imu.txt", "gnss.pos", "gnss_posvel.txt", "gnss_q.txt"):
        if not os.path.exists(os.path.join(args.data, f)):
            sys.exit(f"{args.data}/{f} is missing (set --data or NAVSYNC_DRIVE0708_DIR)")
    work = args.work or tempfile.mkdtemp(prefix="drive0708-")
    os.makedirs(work, exist_ok=True)
    wargs = windows_args(args.windows, args.data)
    wins = score_outages.windows(wargs)
    end_sow = wins[-1][1] + 30.0 if args.windows < 11 else None
    last = end_sow if end_sow is not None else float("inf")

    posvel = os.path.join(work, "gnss_posvel_outages.txt")
    pos = os.path.join(work, "gnss_outages.pos")
    kept = withhold(os.path.join(args.data, "gnss_posvel.txt"), posvel, wins, last)
    withhold(os.path.join(args.data, "gnss.pos"), pos, wins, last)
    imu = os.path.join(args.data, "imu.txt")
    results = {"windows": args.windows, "gnss_epochs_given": kept, "end_sow": end_sow}

    cfg = os.path.join(work, "navsync-kf-gins.yaml")
    write_config(args.config, cfg, imu, posvel, work, end_sow)
    rec = os.path.join(work, "drive0708.mcap")
    run([args.navsync, "import", "kf-gins", "--imu", imu, "--gnss", posvel, "--gnss-layout",
         "matlab", "--kf-gins-config", cfg, "--out", rec], os.path.join(work, "import.log"))
    out = os.path.join(work, "navsync")
    os.makedirs(out, exist_ok=True)
    summary = os.path.join(out, "summary.json")
    run([args.navsync, "replay", rec, "--estimate", "--format", "kf-gins", "--out", out + "/",
         "--summary-json", summary, *args.replay_flags], os.path.join(work, "replay.log"))
    with open(summary) as f:
        s = json.load(f)
    navs = [os.path.join(out, n) for n in os.listdir(out) if n.endswith(".nav")]
    if not navs:
        sys.exit(f"navsync wrote no .nav file into {out}")
    r = score(navs[0], wargs)
    r["gnss_fixes"] = s.get("gnss_fixes")
    r["rejected_fixes"] = s.get("rejected_fixes")
    r["gnss_delay_est_s"] = s.get("gnss_delay_est_s")
    r["measurement_counters"] = s.get("measurement_counters")
    results["navsync"] = r

    if args.kf_gins:
        kdir = os.path.join(work, "kf-gins")
        os.makedirs(kdir, exist_ok=True)
        kcfg = os.path.join(work, "kf-gins.yaml")
        write_config(args.config, kcfg, imu, pos, kdir, end_sow)
        run([args.kf_gins, kcfg], os.path.join(work, "kf-gins.log"))
        results["kf_gins"] = score(os.path.join(kdir, "KF_GINS_Navresult.nav"), wargs)

    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)

    def fmt(x, p=2):
        return "n/a" if x is None else f"{x:.{p}f}"
    print(f"drive0708 outage benchmark: {args.windows} windows of 15 s, work dir {work}")
    print(f"{'filter':10} {'end mean m':>10} {'end max m':>10} {'outage RMS m':>13} "
          f"{'with GNSS RMS m (settled)':>26} {'rejected':>9}")
    for name in ("navsync", "kf_gins"):
        if name not in results:
            continue
        x = results[name]
        rej = (f"{x['rejected_fixes']}/{x['gnss_fixes']}" if "rejected_fixes" in x else "n/a")
        print(f"{name:10} {fmt(x['outage_end_mean_m']):>10} {fmt(x['outage_end_max_m']):>10} "
              f"{fmt(x['outage_rms_m']):>13} {fmt(x['with_gnss_settled_rms_m'], 3):>26} "
              f"{rej:>9}")
        print(f"{'':10} window ends: "
              + " ".join(fmt(w.get('end_error_m'), 1) for w in x["per_window"]))
    if results["navsync"]["windows_scored"] < args.windows:
        sys.exit("navsync: some windows were not scored (no output there)")


if __name__ == "__main__":
    main()
