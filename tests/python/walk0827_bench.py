#!/usr/bin/env python3
"""The walk0827 outage benchmark (the dataset README, "Benchmark"), navsync with its defaults
and optionally KF-GINS with its best noise set and the initial state given.

  walk0827_bench.py [--navsync BIN] [--data DIR] [--work DIR] [--kf-gins BIN] [--json OUT]
                    [-- REPLAY FLAGS…]

Two runs, one per phase of 15 s outages every 45 s (phase A from sow 408667, phase B from
408689.5): the GNSS epochs of the phase's windows are withheld, the rest given. navsync gets
the receiver's positions and Doppler velocities (gnss_posvel.txt) and only the antenna lever
arm (`--lever-arm 0,-0.05,0`): no IMU model, no initial state. KF-GINS (with --kf-gins) gets
positions only (it reads no velocity), the README's noise set E and the initial state from the
static start, computed here as the README describes it.

Scored (score_outages.score): the horizontal antenna error at the end of each window against
the withheld RTK-fixed epochs; windows A1, A2, B1 end in fixed data (A3 and B2 lie in the
float part: not scored). Also the with-GNSS RMS over the fixed epochs given, and the share of
them whose north and east errors lie within 2 sigma of the result's own (KF_GINS_STD.txt).
Exits non-zero when a step fails, a window has no output, or any output row is NaN.
Needs numpy.
"""

import argparse
import json
import math
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
    "NAVSYNC_WALK0827_DIR",
    os.path.join(os.path.dirname(REPO), "shared", "datasets", "rtklibexplorer-walk0827"))
if not os.path.isdir(DEFAULT_DATA) and os.environ.get("NAVSYNC_SHARED_DIR"):
    DEFAULT_DATA = os.path.join(os.environ["NAVSYNC_SHARED_DIR"], "datasets", "rtklibexplorer-walk0827")

LEVER = [0.0, -0.05, 0.0]
PHASES = {"A": (408667.0, 3), "B": (408689.5, 2)}
# The windows that end in RTK-fixed data (README): A1, A2, B1.
SCORED = [("A", 0), ("A", 1), ("B", 0)]


def phase_args(name, data):
    first, n = PHASES[name]
    return argparse.Namespace(first=first, outage=15.0, period=45.0, windows=n, data=data,
                              lever=LEVER, settle=1.0)


def withhold(src, dst, wins):
    with open(src) as fi, open(dst, "w") as fo:
        for line in fi:
            f = line.split()
            if not f or line.lstrip().startswith(("#", "%")):
                continue
            if score_outages.window_index(np.array([float(f[0])]), wins)[0] >= 0:
                continue
            fo.write(line)


def initial_state(data):
    """KF-GINS's initial state as the README gives it: roll/pitch -0.97/+0.40 deg from 2.5 s of
    levelling, yaw -133.6 deg, the mean of the static fixes moved to the IMU, at the IMU's
    second sample."""
    imu = np.loadtxt(os.path.join(data, "imu.txt"), ndmin=2)
    g = np.loadtxt(os.path.join(data, "gnss.pos"), ndmin=2)
    t0 = imu[1, 0]
    static = g[(g[:, 0] >= g[0, 0]) & (g[:, 0] <= t0 + 2.5)]
    lat, lon, h = (float(np.mean(static[:, i])) for i in (1, 2, 3))
    roll, pitch, yaw = -0.97, 0.40, -133.6
    r, p, y = (math.radians(a) for a in (roll, pitch, yaw))
    lx, ly, lz = LEVER
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    n = cp * cy * lx + (-cr * sy + sr * sp * cy) * ly + (sr * sy + cr * sp * cy) * lz
    e = cp * sy * lx + (cr * cy + sr * sp * sy) * ly + (-sr * cy + cr * sp * sy) * lz
    d = -sp * lx + sr * cp * ly + cr * cp * lz
    rm, rn = score_outages.radii(math.radians(lat))
    lat -= math.degrees(n / (rm + h))
    lon -= math.degrees(e / ((rn + h) * math.cos(math.radians(lat))))
    h += d
    return t0, [lat, lon, h], [roll, pitch, yaw % 360.0]


def kf_gins_config(path, imu, gnss, out_dir, data):
    t0, pos, att = initial_state(data)
    with open(path, "w") as f:
        f.write(f"""# KF-GINS on rtklibexplorer walk0827, the dataset README's noise set E and initial state
imupath: "{imu}"
gnsspath: "{gnss}"
outputpath: "{out_dir}"
imudatalen: 7
imudatarate: 100
starttime: {t0:.5f}
endtime: -1
initpos: [ {pos[0]:.10f}, {pos[1]:.10f}, {pos[2]:.4f} ]
initvel: [ 0.0, 0.0, 0.0 ]
initatt: [ {att[0]}, {att[1]}, {att[2]} ]
initgyrbias: [ 0, 0, 0 ]
initaccbias: [ 0, 0, 0 ]
initgyrscale: [ 0, 0, 0 ]
initaccscale: [ 0, 0, 0 ]
initposstd: [ 0.05, 0.05, 0.05 ]
initvelstd: [ 0.05, 0.05, 0.05 ]
initattstd: [ 1.0, 1.0, 10.0 ]
initbgstd: [ 720, 720, 720 ]
initbastd: [ 20000, 20000, 20000 ]
initsgstd: [ 1000, 1000, 1000 ]
initsastd: [ 1000, 1000, 1000 ]
imunoise:
  arw: [ 2, 2, 2 ]
  vrw: [ 0.8, 0.8, 0.8 ]
  gbstd: [ 50, 50, 50 ]
  abstd: [ 2000, 2000, 2000 ]
  gsstd: [ 1000, 1000, 1000 ]
  asstd: [ 1000, 1000, 1000 ]
  corrtime: 1.0
antlever: [ {LEVER[0]}, {LEVER[1]}, {LEVER[2]} ]
""")


def nav_file(out):
    navs = [os.path.join(out, n) for n in os.listdir(out) if n.endswith(".nav")]
    if not navs:
        sys.exit(f"no .nav file in {out}")
    nav = np.loadtxt(navs[0], ndmin=2)
    if not np.isfinite(nav).all():
        sys.exit(f"{navs[0]}: {int((~np.isfinite(nav)).any(axis=1).sum())} rows with NaN")
    return navs[0]


def combine(reps):
    """The scored windows (A1, A2, B1) of the phases' reports."""
    ends, per = [], []
    for ph, k in SCORED:
        w = reps[ph]["per_window"][k]
        per.append(w)
        if "end_error_m" in w:
            ends.append(w["end_error_m"])
    return {
        "window_ends_m": [w.get("end_error_m") for w in per],
        "outage_end_mean_m": float(np.mean(ends)) if len(ends) == len(SCORED) else None,
        "outage_end_max_m": float(np.max(ends)) if len(ends) == len(SCORED) else None,
        "with_gnss_rms_m": {ph: reps[ph]["with_gnss_rms_m"] for ph in reps},
        "with_gnss_within_2sigma": {ph: reps[ph].get("with_gnss_within_2sigma") for ph in reps},
        "phases": reps,
    }


def main():
    ap = argparse.ArgumentParser(description="walk0827 outage benchmark, navsync vs KF-GINS")
    ap.add_argument("--navsync", default=os.path.join(REPO, "target", "release", "navsync"))
    ap.add_argument("--data", default=DEFAULT_DATA)
    ap.add_argument("--work", help="working directory (default: a temporary one)")
    ap.add_argument("--kf-gins", help="KF-GINS binary: run it on the same files")
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("replay_flags", nargs="*", help="extra `navsync replay` flags (after --)")
    args = ap.parse_args()
    for f in ("imu.txt", "gnss.pos", "gnss_posvel.txt", "gnss_q.txt"):
        if not os.path.exists(os.path.join(args.data, f)):
            sys.exit(f"{args.data}/{f} is missing (set --data or NAVSYNC_WALK0827_DIR)")
    work = args.work or tempfile.mkdtemp(prefix="walk0827-")
    os.makedirs(work, exist_ok=True)
    imu = os.path.join(args.data, "imu.txt")
    results = {}
    navsync, kf = {}, {}
    for ph in PHASES:
        pa = phase_args(ph, args.data)
        wins = score_outages.windows(pa)
        posvel = os.path.join(work, f"gnss_posvel_{ph}.txt")
        withhold(os.path.join(args.data, "gnss_posvel.txt"), posvel, wins)
        rec = os.path.join(work, f"walk_{ph}.mcap")
        if os.path.exists(rec):
            os.remove(rec)
        run([args.navsync, "import", "kf-gins", "--imu", imu, "--gnss", posvel, "--gnss-layout", "matlab",
             "--week", "2381", "--out", rec], os.path.join(work, f"import_{ph}.log"))
        out = os.path.join(work, f"navsync_{ph}")
        os.makedirs(out, exist_ok=True)
        summary = os.path.join(out, "summary.json")
        run([args.navsync, "replay", rec, "--estimate", "--lever-arm", ",".join(map(str, LEVER)),
             "--format", "kf-gins", "--out", out + "/", "--summary-json", summary, *args.replay_flags],
            os.path.join(work, f"replay_{ph}.log"))
        navsync[ph] = score_outages.score(argparse.Namespace(**vars(pa), result=nav_file(out)))
        with open(summary) as f:
            navsync[ph]["summary"] = json.load(f)
        if args.kf_gins:
            pos = os.path.join(work, f"gnss_{ph}.pos")
            withhold(os.path.join(args.data, "gnss.pos"), pos, wins)
            kdir = os.path.join(work, f"kf-gins_{ph}")
            os.makedirs(kdir, exist_ok=True)
            kcfg = os.path.join(work, f"kf-gins_{ph}.yaml")
            kf_gins_config(kcfg, imu, pos, kdir, args.data)
            run([args.kf_gins, kcfg], os.path.join(work, f"kf-gins_{ph}.log"))
            kf[ph] = score_outages.score(argparse.Namespace(
                **vars(pa), result=os.path.join(kdir, "KF_GINS_Navresult.nav")))
    results["navsync"] = combine(navsync)
    if kf:
        results["kf_gins"] = combine(kf)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)

    def fmt(x, p=2):
        return "n/a" if x is None else f"{x:.{p}f}"
    print(f"walk0827 outage benchmark (A1, A2, B1), work dir {work}")
    print(f"{'filter':10} {'A1':>7} {'A2':>7} {'B1':>7} {'mean m':>8} {'max m':>8} "
          f"{'with GNSS RMS m (A, B)':>24}")
    for name, r in results.items():
        a, b = r["with_gnss_rms_m"]["A"], r["with_gnss_rms_m"]["B"]
        print(f"{name:10} " + " ".join(f"{fmt(e):>7}" for e in r["window_ends_m"])
              + f" {fmt(r['outage_end_mean_m']):>8} {fmt(r['outage_end_max_m']):>8} "
              f"{fmt(a, 3):>11}, {fmt(b, 3):<11}")
    for name, r in results.items():
        cov = r["with_gnss_within_2sigma"]
        if all(cov.values()):
            print(f"{name:10} with GNSS, north / east within 2 sigma: "
                  + ", ".join(f"{ph} {c[0]:.3f} / {c[1]:.3f}" for ph, c in cov.items()))
    if results["navsync"]["outage_end_mean_m"] is None:
        sys.exit("navsync: a scored window has no output")


if __name__ == "__main__":
    main()
