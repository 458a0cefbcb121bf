#!/usr/bin/env python3
"""Scores a KF-GINS-format navigation result against a KF-GINS-format truth file (numpy only).

Both files: `week sow lat lon h vn ve vd roll pitch yaw` (deg, deg, m, m/s, deg), the IMU point
(KF-GINS's KF_GINS_Navresult.nav, navsync's own .nav output, independent_drive.py's truth.nav).
The week column is ignored (KF-GINS writes 0).

Only the time span both files cover is scored; --skip S drops the first S seconds of it.
The truth is linearly interpolated to the result's epochs (exact when both share the IMU grid);
yaw is unwrapped before interpolation and yaw/roll/pitch errors are wrapped to +-180 deg.

Reported: horizontal RMS and max (m, N/E with the WGS-84 radii at the truth position), height
RMS, velocity RMS (3-D norm of the NED error, and per axis), roll/pitch/yaw RMS, the final
horizontal error, the number of epochs.

usage: score_truth.py RESULT.nav TRUTH.nav [--skip S] [--json]
"""

import argparse
import json
import sys

import numpy as np

A = 6378137.0
E2 = (1.0 / 298.257223563) * (2.0 - 1.0 / 298.257223563)


def load_nav(path):
    d = np.loadtxt(path, ndmin=2)
    if d.shape[1] < 11:
        sys.exit(f"{path}: expected 11 columns, got {d.shape[1]}")
    d = d[:, :11]
    order = np.argsort(d[:, 1], kind="stable")
    return d[order]


def wrap180(x):
    return (x + 180.0) % 360.0 - 180.0


def score(res, tru, skip=0.0):
    t0 = max(res[0, 1], tru[0, 1])
    t1 = min(res[-1, 1], tru[-1, 1])
    if t1 <= t0:
        raise ValueError("the files do not overlap in time")
    sel = (res[:, 1] >= t0 + skip) & (res[:, 1] <= t1)
    r = res[sel]
    if len(r) == 0:
        raise ValueError("nothing left after --skip")
    tt = tru[:, 1]
    ref = np.empty((len(r), 9))
    for j, col in enumerate(range(2, 11)):
        y = tru[:, col]
        if col >= 8:
            y = np.rad2deg(np.unwrap(np.deg2rad(y)))
        ref[:, j] = np.interp(r[:, 1], tt, y)
    lat = np.deg2rad(ref[:, 0])
    s2 = np.sin(lat) ** 2
    rn = A / np.sqrt(1.0 - E2 * s2)
    rm = A * (1.0 - E2) / (1.0 - E2 * s2) ** 1.5
    dn = np.deg2rad(r[:, 2] - ref[:, 0]) * (rm + ref[:, 2])
    de = np.deg2rad(wrap180(r[:, 3] - ref[:, 1])) * (rn + ref[:, 2]) * np.cos(lat)
    dh = r[:, 4] - ref[:, 2]
    dv = r[:, 5:8] - ref[:, 3:6]
    datt = wrap180(r[:, 8:11] - ref[:, 6:9])
    hor = np.hypot(dn, de)

    def rms(x):
        return float(np.sqrt(np.mean(np.square(x))))

    return {
        "epochs": int(len(r)),
        "span_sow": [float(r[0, 1]), float(r[-1, 1])],
        "skip_s": skip,
        "horizontal_rms_m": rms(hor),
        "horizontal_max_m": float(hor.max()),
        "horizontal_final_m": float(hor[-1]),
        "height_rms_m": rms(dh),
        "velocity_rms_m_s": float(np.sqrt(np.mean(np.sum(dv * dv, axis=1)))),
        "velocity_rms_ned_m_s": [rms(dv[:, i]) for i in range(3)],
        "roll_rms_deg": rms(datt[:, 0]),
        "pitch_rms_deg": rms(datt[:, 1]),
        "yaw_rms_deg": rms(datt[:, 2]),
        "yaw_max_deg": float(np.max(np.abs(datt[:, 2]))),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description="Score a KF-GINS-format result against truth.nav")
    ap.add_argument("result")
    ap.add_argument("truth")
    ap.add_argument("--skip", type=float, default=0.0,
                    help="seconds dropped from the start of the common span")
    ap.add_argument("--json", action="store_true", help="print JSON only")
    a = ap.parse_args(argv)
    rep = score(load_nav(a.result), load_nav(a.truth), a.skip)
    if a.json:
        print(json.dumps(rep, indent=1))
        return
    print(f"{a.result} vs {a.truth}: {rep['epochs']} epochs, sow {rep['span_sow'][0]:.3f}.."
          f"{rep['span_sow'][1]:.3f} (skip {a.skip:g} s)")
    print(f"  horizontal RMS {rep['horizontal_rms_m']:.4f} m  max {rep['horizontal_max_m']:.4f} m"
          f"  final {rep['horizontal_final_m']:.4f} m")
    print(f"  height RMS     {rep['height_rms_m']:.4f} m")
    print(f"  velocity RMS   {rep['velocity_rms_m_s']:.5f} m/s (N/E/D "
          + " / ".join(f"{x:.5f}" for x in rep["velocity_rms_ned_m_s"]) + ")")
    print(f"  roll/pitch/yaw RMS {rep['roll_rms_deg']:.5f} / {rep['pitch_rms_deg']:.5f} / "
          f"{rep['yaw_rms_deg']:.5f} deg (yaw max {rep['yaw_max_deg']:.4f})")


if __name__ == "__main__":
    main()
