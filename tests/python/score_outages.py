#!/usr/bin/env python3
"""Outage benchmark on rtklibexplorer drive0708 (its README, "Outage benchmark"), numpy only.

Windows: GNSS epochs are withheld in 15 s windows [start_k, start_k + 15) with
start_k = 243296.5 + 45 k, k = 0..10 (11 windows: 15 s without GNSS, 30 s with, to the end of
the data). The defaults can be changed with --first/--outage/--period/--windows.

  score_outages.py --write-gnss OUT [--data DIR]
      writes DIR/gnss.pos without the windowed epochs (lines copied verbatim), the file a
      filter is given.
  score_outages.py RESULT.nav [--data DIR] [--json]
      scores a KF-GINS-format result (`week sow lat lon h vn ve vd roll pitch yaw`, the IMU
      point; KF_GINS_Navresult.nav or navsync's .nav):
        * the antenna position of each result row = IMU position + C_b^n(roll, pitch, yaw) l^b,
          l^b = [0, -0.05, 0] m FRD (--lever), then linear interpolation to each GNSS epoch time;
        * horizontal error (N/E, metres) against the RTK-fixed (gnss_q.txt Q = 1) epochs;
        * per window: the error at its last withheld Q = 1 epoch ("end of window"); mean and
          max over the windows; RMS over all withheld Q = 1 epochs;
        * with GNSS: RMS (and max) over all Q = 1 epochs that are not withheld; also a
          "settled" RMS without the fixes in the first --settle (1) s after each window.
      The solution is interpolated at the epoch time: a filter that writes its state before
      the update at that epoch is scored on its prediction there, so the first fix after a
      window carries the outage drift.
      Epochs outside the result's time span are not scored (counted in the report); a window
      with no scored epoch is reported as missing.
Heights in drive0708's gnss.pos are above MSL (geoid not applied), not ellipsoidal: only
horizontal errors are scored. (A filter that takes them as ellipsoidal heights is off by
~17 m in gravity/radius terms only: ~5e-5 m/s^2 of gravity, 3e-6 relative in the radii.)
"""

import argparse
import json
import os
import sys

import numpy as np

# The dataset under $NAVSYNC_SHARED_DIR/datasets/ when it is set, else beside the checkout
# (../shared/datasets/).
DEFAULT_DATA = os.path.normpath(os.path.join(
    os.environ.get("NAVSYNC_SHARED_DIR",
                   os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "..", "shared")),
    "datasets", "rtklibexplorer-drive0708"))
A = 6378137.0
E2 = (1.0 / 298.257223563) * (2.0 - 1.0 / 298.257223563)


def radii(lat):
    s2 = np.sin(lat) ** 2
    return A * (1.0 - E2) / (1.0 - E2 * s2) ** 1.5, A / np.sqrt(1.0 - E2 * s2)


def windows(args):
    return [(args.first + k * args.period, args.first + k * args.period + args.outage)
            for k in range(args.windows)]


def window_index(t, wins):
    """Index of the window holding each time (start <= t < end), -1 if none."""
    idx = np.full(len(t), -1)
    for k, (s, e) in enumerate(wins):
        idx[(t >= s - 1e-6) & (t < e - 1e-6)] = k
    return idx


def write_gnss(args):
    wins = windows(args)
    kept = dropped = 0
    with open(os.path.join(args.data, "gnss.pos")) as fi, open(args.write_gnss, "w") as fo:
        for line in fi:
            f = line.split()
            if not f or line.lstrip().startswith(("#", "%")):
                continue
            if window_index(np.array([float(f[0])]), wins)[0] >= 0:
                dropped += 1
                continue
            fo.write(line)
            kept += 1
    print(f"wrote {args.write_gnss}: {kept} epochs kept, {dropped} withheld in {len(wins)} "
          f"windows {wins[0][0]}..{wins[-1][1]}")


def antenna_positions(nav, lever):
    """Geodetic antenna position (rad, rad, m) of every result row."""
    lat, lon, h = np.deg2rad(nav[:, 2]), np.deg2rad(nav[:, 3]), nav[:, 4]
    r, p, y = (np.deg2rad(nav[:, i]) for i in (8, 9, 10))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    lx, ly, lz = lever
    # C_b^n = Rz(yaw) Ry(pitch) Rx(roll) applied to the lever arm
    n = cp * cy * lx + (-cr * sy + sr * sp * cy) * ly + (sr * sy + cr * sp * cy) * lz
    e = cp * sy * lx + (cr * cy + sr * sp * sy) * ly + (-sr * cy + cr * sp * sy) * lz
    d = -sp * lx + sr * cp * ly + cr * cp * lz
    rm, rn = radii(lat)
    return lat + n / (rm + h), lon + e / ((rn + h) * np.cos(lat)), h - d


def score(args):
    nav = np.loadtxt(args.result, ndmin=2)
    nav = nav[np.argsort(nav[:, 1], kind="stable")]
    g = np.loadtxt(os.path.join(args.data, "gnss.pos"), ndmin=2)
    q = np.loadtxt(os.path.join(args.data, "gnss_q.txt"), ndmin=2)
    qmap = {round(t * 1000): int(v) for t, v in q[:, :2]}
    qual = np.array([qmap.get(round(t * 1000), 0) for t in g[:, 0]])
    alat, alon, _ = antenna_positions(nav, args.lever)
    t = g[:, 0]
    covered = (t >= nav[0, 1]) & (t <= nav[-1, 1])
    lat_s = np.interp(t, nav[:, 1], alat)
    lon_s = np.interp(t, nav[:, 1], np.unwrap(alon))
    lat_r, lon_r = np.deg2rad(g[:, 1]), np.deg2rad(g[:, 2])
    rm, rn = radii(lat_r)
    dn = (lat_s - lat_r) * (rm + g[:, 3])
    de = (np.angle(np.exp(1j * (lon_s - lon_r)))) * (rn + g[:, 3]) * np.cos(lat_r)
    err = np.hypot(dn, de)
    wins = windows(args)
    widx = window_index(t, wins)
    fixed = qual == 1
    per = []
    for k, (s, e) in enumerate(wins):
        m = (widx == k) & fixed & covered
        if not m.any():
            per.append({"window": k, "start": s, "end": e, "scored_epochs": 0})
            continue
        last = np.flatnonzero(m)[-1]
        per.append({"window": k, "start": s, "end": e, "scored_epochs": int(m.sum()),
                    "end_epoch_sow": float(t[last]), "end_error_m": float(err[last]),
                    "rms_m": float(np.sqrt(np.mean(err[m] ** 2))),
                    "max_m": float(err[m].max())})
    ends = np.array([w["end_error_m"] for w in per if "end_error_m" in w])
    wm = (widx >= 0) & fixed & covered
    gm = (widx < 0) & fixed & covered
    # "settled": without the fixes in the first --settle seconds after each window (those
    # still show the outage drift until the filter has taken the first fixes back)
    after = np.zeros(len(t), dtype=bool)
    for s, e in wins:
        after |= (t >= e - 1e-6) & (t < e + args.settle - 1e-6)
    gs = gm & ~after
    rep = {
        "result": args.result,
        "lever_arm_frd_m": list(args.lever),
        "windows": len(wins),
        "windows_scored": int(len(ends)),
        "outage_end_mean_m": float(ends.mean()) if len(ends) else None,
        "outage_end_max_m": float(ends.max()) if len(ends) else None,
        "outage_rms_m": float(np.sqrt(np.mean(err[wm] ** 2))) if wm.any() else None,
        "outage_epochs_scored": int(wm.sum()),
        "with_gnss_rms_m": float(np.sqrt(np.mean(err[gm] ** 2))) if gm.any() else None,
        "with_gnss_max_m": float(err[gm].max()) if gm.any() else None,
        "with_gnss_epochs_scored": int(gm.sum()),
        "with_gnss_settled_rms_m": float(np.sqrt(np.mean(err[gs] ** 2))) if gs.any() else None,
        "with_gnss_settled_max_m": float(err[gs].max()) if gs.any() else None,
        "settle_s": args.settle,
        "fixed_epochs_not_covered": int((fixed & ~covered).sum()),
        "per_window": per,
    }
    # The result's own sigma (KF_GINS_STD.txt beside it: time, north, east sigma in m), at the
    # same epochs: the share of north and east errors within 2 sigma (the fix's own ~1 cm is
    # part of the error).
    std_path = os.path.join(os.path.dirname(args.result), "KF_GINS_STD.txt")
    if gm.any() and os.path.exists(std_path):
        sd = np.loadtxt(std_path, ndmin=2)
        sd = sd[np.argsort(sd[:, 0], kind="stable")]
        sn, se = (np.interp(t[gm], sd[:, 0], sd[:, k]) for k in (1, 2))
        rep["with_gnss_within_2sigma"] = [float(np.mean(np.abs(dn[gm]) <= 2 * sn)),
                                          float(np.mean(np.abs(de[gm]) <= 2 * se))]
    return rep


def main(argv=None):
    ap = argparse.ArgumentParser(description="drive0708 outage benchmark")
    ap.add_argument("result", nargs="?")
    ap.add_argument("--data", default=DEFAULT_DATA)
    ap.add_argument("--write-gnss", metavar="OUT")
    ap.add_argument("--lever", type=float, nargs=3, default=[0.0, -0.05, 0.0],
                    metavar=("F", "R", "D"), help="IMU -> antenna, body FRD, m")
    ap.add_argument("--first", type=float, default=243296.5, help="first window start, sow")
    ap.add_argument("--outage", type=float, default=15.0, help="window length, s")
    ap.add_argument("--period", type=float, default=45.0, help="window start spacing, s")
    ap.add_argument("--windows", type=int, default=11)
    ap.add_argument("--settle", type=float, default=1.0,
                    help="s after each window left out of the 'settled' with-GNSS RMS")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if args.write_gnss:
        write_gnss(args)
        if not args.result:
            return
    if not args.result:
        ap.error("give RESULT.nav or --write-gnss OUT")
    rep = score(args)
    if args.json:
        print(json.dumps(rep, indent=1))
        return
    print(f"{args.result}: {rep['windows_scored']}/{rep['windows']} windows scored, "
          f"lever arm {args.lever} m FRD (horizontal only: gnss.pos heights are MSL)")
    for w in rep["per_window"]:
        if "end_error_m" in w:
            print(f"  window {w['window']:2d} {w['start']:.1f}-{w['end']:.1f}: end "
                  f"{w['end_error_m']:7.3f} m (at {w['end_epoch_sow']:.2f})  rms "
                  f"{w['rms_m']:7.3f}  max {w['max_m']:7.3f}  ({w['scored_epochs']} epochs)")
        else:
            print(f"  window {w['window']:2d} {w['start']:.1f}-{w['end']:.1f}: not scored")

    def f(x):
        return "n/a" if x is None else f"{x:.3f}"
    print(f"  outage end error mean {f(rep['outage_end_mean_m'])} m, max "
          f"{f(rep['outage_end_max_m'])} m; RMS over {rep['outage_epochs_scored']} withheld "
          f"fixed epochs {f(rep['outage_rms_m'])} m")
    print(f"  with GNSS: RMS {f(rep['with_gnss_rms_m'])} m, max {f(rep['with_gnss_max_m'])} m "
          f"over {rep['with_gnss_epochs_scored']} fixed epochs; "
          f"{rep['fixed_epochs_not_covered']} fixed epochs outside the result's span")
    print(f"  with GNSS, settled (without the first {args.settle:g} s after each window): RMS "
          f"{f(rep['with_gnss_settled_rms_m'])} m, max {f(rep['with_gnss_settled_max_m'])} m")


if __name__ == "__main__":
    main()
