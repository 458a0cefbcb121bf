#!/usr/bin/env python3
"""navsync (and optionally KF-GINS) on an independently generated drive, scored against its truth.

  generated_bench.py [--navsync BIN] [--work DIR] [--preset industrial|consumer] [--seed 1]
                     [--duration 660] [--gnss-rate 1] [--gnss-epoch-offset 0]
                     [--latency 1.1] [--kf-gins BIN] [--json OUT] [-- REPLAY FLAGS…]

1. independent_drive.py writes the drive in KF-GINS's formats (it shares no code with
   navsync's simulator): imu.txt, gnss.pos, truth.nav and kf-gins.yaml (the exact initial
   state and the true noise figures: what KF-GINS is given).
2. Runs navsync on it three times, each imported with the same kf-gins.yaml:
   * "hardware": `import kf-gins` with PPS edges (fixes stamped at their epoch, delivered
     0.05 s later), `replay --estimate`;
   * "software_0" and "software": `import kf-gins --no-pps --gnss-latency 0 | L`: no PPS, each
     fix stamped on receipt 0 or L s after its epoch; `replay --estimate --software-sync` (the
     estimator must find the latency itself and still give every output a GNSS time).
   * "receipt_tags": the GNSS file rewritten with each tag L s after its epoch (a logging
     computer's receipt times on the IMU's clock), `import kf-gins --gnss-tags receipt`,
     `replay --estimate` with no flag: scored against the file's own truth, on its time axis.
3. Scores each result (and KF-GINS's, with --kf-gins) with score_truth.score; also counts the
   output rows (one per NavState with a time) against the IMU samples and measures how far
   the output's time labels are from the input's IMU time tags (off_axis_ms).
Exits non-zero when a step fails or a result is missing. Needs numpy.
"""

import argparse
import json
import os
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import score_truth  # noqa: E402
from bench_common import run  # noqa: E402

REPO = os.path.dirname(os.path.dirname(HERE))


def rows(path):
    with open(path) as f:
        return sum(1 for line in f if line.strip())


def off_axis_ms(nav, imu_txt):
    """The largest distance of an output's time label from the nearest IMU time tag, ms."""
    with open(imu_txt) as f:
        tags = sorted(float(line.split()[0]) for line in f if line.strip())
    with open(nav) as f:
        labels = [float(line.split()[1]) for line in f if line.strip()]
    worst, j = 0.0, 0
    for t in labels:
        while j + 1 < len(tags) and tags[j + 1] <= t:
            j += 1
        d = min(abs(t - tags[j]), abs(tags[min(j + 1, len(tags) - 1)] - t))
        worst = max(worst, d)
    return worst * 1e3


def late_gnss_file(src, dst, late_s):
    """The GNSS file with every tag `late_s` after its epoch (a logging computer's receipt)."""
    with open(src) as f, open(dst, "w") as g:
        for line in f:
            c = line.split()
            if c:
                g.write(" ".join([f"{float(c[0]) + late_s:.6f}"] + c[1:]) + "\n")


def navsync_run(a, drive, name, import_flags, replay_flags, gnss=None):
    out = os.path.join(a.work, name)
    os.makedirs(out, exist_ok=True)
    rec = os.path.join(a.work, f"{name}.mcap")
    run([a.navsync, "import", "kf-gins", "--imu", os.path.join(drive, "imu.txt"),
         "--gnss", gnss or os.path.join(drive, "gnss.pos"), "--truth", os.path.join(drive, "truth.nav"),
         "--kf-gins-config", os.path.join(drive, "kf-gins.yaml"), "--out", rec, *import_flags],
        os.path.join(a.work, f"{name}-import.log"))
    summary = os.path.join(out, "summary.json")
    run([a.navsync, "replay", rec, "--estimate", "--format", "kf-gins", "--out", out + "/",
         "--summary-json", summary, *replay_flags, *a.replay_flags],
        os.path.join(a.work, f"{name}-replay.log"))
    nav = os.path.join(out, "KF_GINS_Navresult.nav")
    if not os.path.exists(nav) or rows(nav) == 0:
        sys.exit(f"navsync ({name}) wrote no result rows into {nav}")
    r = score_truth.score(score_truth.load_nav(nav), score_truth.load_nav(
        os.path.join(drive, "truth.nav")))
    with open(summary) as f:
        s = json.load(f)
    r["rows"] = rows(nav)
    r["off_axis_ms"] = off_axis_ms(nav, os.path.join(drive, "imu.txt"))
    r["imu_samples"] = s.get("imu_samples")
    r["gnss_fixes"] = s.get("gnss_fixes")
    r["rejected_fixes"] = s.get("rejected_fixes")
    r["gnss_delay_est_s"] = s.get("gnss_delay_est_s")
    r["gnss_delay_std_s"] = s.get("gnss_delay_std_s")
    return r


def main():
    ap = argparse.ArgumentParser(description="navsync vs KF-GINS on an independently generated drive")
    ap.add_argument("--navsync", default=os.path.join(REPO, "target", "release", "navsync"))
    ap.add_argument("--work", help="working directory (default: a temporary one)")
    ap.add_argument("--preset", default="industrial", choices=["industrial", "consumer"])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=660.0)
    ap.add_argument("--gnss-rate", type=float, default=1.0)
    ap.add_argument("--gnss-epoch-offset", type=float, default=0.0)
    ap.add_argument("--latency", type=float, default=1.1,
                    help="receipt latency of the software-sync run, s")
    ap.add_argument("--kf-gins", help="KF-GINS binary: run it on the same files")
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("replay_flags", nargs="*", help="extra `navsync replay` flags (after --)")
    a = ap.parse_args()
    a.work = a.work or tempfile.mkdtemp(prefix="generated-drive-")
    os.makedirs(a.work, exist_ok=True)
    drive = os.path.join(a.work, "drive")
    run([sys.executable, os.path.join(HERE, "independent_drive.py"), drive, "--preset", a.preset,
         "--seed", str(a.seed), "--duration", str(a.duration), "--gnss-rate", str(a.gnss_rate),
         "--gnss-epoch-offset", str(a.gnss_epoch_offset)], os.path.join(a.work, "generate.log"))
    res = {"preset": a.preset, "seed": a.seed, "duration_s": a.duration,
           "gnss_rate_hz": a.gnss_rate, "gnss_epoch_offset_s": a.gnss_epoch_offset}
    res["hardware"] = navsync_run(a, drive, "hardware", [], [])
    res["software_0"] = navsync_run(a, drive, "software_0", ["--no-pps", "--gnss-latency", "0"],
                                    ["--software-sync"])
    res["software"] = navsync_run(a, drive, "software",
                                  ["--no-pps", "--gnss-latency", str(a.latency)],
                                  ["--software-sync"])
    res["software"]["latency_s"] = a.latency
    # The GNSS file tagged on receipt (each tag `latency` after its epoch, the IMU and the
    # truth on the true axis): imported as such, scored against the file's own truth.
    late = os.path.join(a.work, "gnss-receipt-tags.pos")
    late_gnss_file(os.path.join(drive, "gnss.pos"), late, a.latency)
    res["receipt_tags"] = navsync_run(a, drive, "receipt_tags", ["--gnss-tags", "receipt"], [],
                                      gnss=late)
    if a.kf_gins:
        run([a.kf_gins, os.path.join(drive, "kf-gins.yaml")], os.path.join(a.work, "kf-gins.log"))
        res["kf_gins"] = score_truth.score(
            score_truth.load_nav(os.path.join(drive, "kf-gins-out", "KF_GINS_Navresult.nav")),
            score_truth.load_nav(os.path.join(drive, "truth.nav")))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1)
    print(f"generated drive ({a.preset}, seed {a.seed}, {a.duration:g} s, GNSS {a.gnss_rate:g} Hz), "
          f"work dir {a.work}")
    print(f"{'run':28} {'hor RMS m':>9} {'height RMS m':>12} {'vel RMS m/s':>11} "
          f"{'yaw RMS deg':>11} {'rows':>7}")
    names = {"kf_gins": "KF-GINS",
             "hardware": "navsync (PPS)",
             "software_0": "navsync (software, 0 s)",
             "software": f"navsync (software, {a.latency:g} s)",
             "receipt_tags": f"navsync (tags {a.latency:g} s late)"}
    for key in ("kf_gins", "hardware", "software_0", "software", "receipt_tags"):
        if key not in res:
            continue
        x = res[key]
        print(f"{names[key]:28} {x['horizontal_rms_m']:9.3f} {x['height_rms_m']:12.3f} "
              f"{x['velocity_rms_m_s']:11.3f} {x['yaw_rms_deg']:11.3f} {x.get('rows', ''):>7}")
    for key, lat in (("software_0", 0.0), ("software", a.latency), ("receipt_tags", a.latency)):
        d = res[key]
        print(f"software sync, receipt latency {lat:g} s: Δ estimated "
              f"{d['gnss_delay_est_s']:.4f} ± {d['gnss_delay_std_s']:.4f} s")
    ratio = res["software"]["horizontal_rms_m"] / res["software_0"]["horizontal_rms_m"]
    res["software_latency_rms_ratio"] = ratio
    print(f"horizontal RMS with {a.latency:g} s latency / without: {ratio:.3f}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1)


if __name__ == "__main__":
    main()
