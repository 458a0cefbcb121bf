#!/usr/bin/env python3
"""The randomized sweep (issue 34): many independent drives, navsync with its defaults on each.

  sweep.py [--navsync BIN] [--runs N] [--seed S] [--duration S] [--work DIR [--keep]]
           [--json OUT] [--kf-gins BIN] [--no-array] [--imu-model default|matched]

Each run draws (from --seed and its index) a drive of `independent_drive.py` (exact
kinematics, shares no code with navsync): a profile (car, pedestrian, slow robot: the speed
changes scaled 1, 0.08, 0.04; the stops and turns kept), a start heading (any), a place (both
hemispheres, both sides of Greenwich, up to 75 deg latitude), an IMU grade (industrial,
consumer), a GNSS sigma (1 cm to 3 m, log-uniform) and rate (1, 2, 4, 5, 10 Hz), a lever arm
(up to 1 m per axis), and the time synchronisation: PPS (fixes at their epoch) or software sync
with a receipt latency of 0 to 1.5 s. Under PPS the fixes carry what is left between the IMU's
and the receiver's time after the PPS mapping (an IMU's filter group delay and data-ready
latency): the IMU's tags are moved early by a delay drawn from N(0, 0.02 s), the prior navsync
states for it (`delay_prior_std_s`); the fixes and the truth keep the GNSS axis. The delay's
coverage is then a calibration check (a consistent estimator covers ~95 % of draws from its
own prior: Talts et al. 2018, "Validating Bayesian inference algorithms with simulation-based
calibration"). navsync gets what a user would give:
the files, the lever arm and, in software sync, `--software-sync`; no IMU model, no initial
state (with `--imu-model matched` also the drive's IMU grade, as `--imu-model`).

Per run: the exit status and the summary's problem (a run that exits 0 must have usable
output; one that fails must say why), NaN in any output row, and per output epoch whether the
error is within 2 sigma of the output's own sigma, for north and east position and yaw (against
truth.nav at the output's time), and for the final GNSS delay. Pooled over the runs: the share
of epochs within 2 sigma (a consistent filter: ~95 %).

With --kf-gins: KF-GINS on the same files with its exact noise set and initial state, and
navsync given the same (`import --kf-gins-config`); the ratio of horizontal RMS per drive.
KF-GINS reads each fix at its epoch; navsync is run a second time with that same information
(the fixes at their epochs, under PPS, without the drawn delay) and the ratio is taken on that
run (the first run's RMS, which pays for estimating the delay, is kept beside it).

IMU arrays (unless --no-array): each run's drive is made a second time with a vehicle's
vibration (scale 0.3 to 3) and two more IMUs stamped late by -20 to +20 ms each (drawn from
the run's own seed, so the runs above do not change), imported as an array and replayed with
`--imus 0,1,2`: the final offset of each IMU within 2 sigma of its own sigma, and whether it
converged (sigma < 1 ms).
Exits non-zero when a step of the sweep itself fails. Needs numpy.
"""

import argparse
import json
import math
import os
import random
import shutil
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import score_truth  # noqa: E402

REPO = os.path.dirname(os.path.dirname(HERE))
PROFILES = {"car": 1.0, "pedestrian": 0.08, "robot": 0.04}
# The IMU-to-GNSS delay left under PPS, s (1 sigma): navsync's own prior (`delay_prior_std_s`).
PPS_DELAY_STD_S = 0.02


def draw(rng, i, duration):
    profile = rng.choice(sorted(PROFILES))
    software = rng.random() < 0.5
    d = {
        "index": i,
        "profile": profile,
        "preset": rng.choice(["industrial", "consumer"]),
        "heading0": round(rng.uniform(0.0, 360.0), 3),
        "lat0": round(rng.uniform(-75.0, 75.0), 6),
        "lon0": round(rng.uniform(-180.0, 180.0), 6),
        "gnss_sigma": round(10 ** rng.uniform(-2.0, math.log10(3.0)), 4),
        "gnss_rate": rng.choice([1, 2, 4, 5, 10]),
        "lever_arm": [round(rng.uniform(-1.0, 1.0), 3) for _ in range(3)],
        "latency_s": round(rng.uniform(0.0, 1.5), 3) if software else None,
        "seed": rng.randrange(1, 1 << 30),
        "duration": duration,
    }
    # Drawn from the run's own seed, so that the runs above do not change.
    d["pps_delay_s"] = None if software else round(random.Random(d["seed"] ^ 0x5EED).gauss(0.0, PPS_DELAY_STD_S), 4)
    return d


def run(cmd, log):
    with open(log, "w") as f:
        return subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT).returncode


def coverage(nav_path, std_path, truth_path):
    """Per output epoch: (|e_N| <= 2 sN, |e_E| <= 2 sE, |e_yaw| <= 2 s_yaw), and any NaN."""
    try:
        nav = np.loadtxt(nav_path, ndmin=2)
        std = np.loadtxt(std_path, ndmin=2)
    except (OSError, ValueError):
        return None, False
    if nav.size == 0:
        return np.zeros((0, 3), dtype=bool), False
    nan = bool(np.isnan(nav).any() or np.isnan(std).any())
    truth = score_truth.load_nav(truth_path)
    t = nav[:, 1]
    keep = (t >= truth[0, 1]) & (t <= truth[-1, 1])
    nav = nav[keep]
    t = nav[:, 1]
    by_t = {round(r[0], 4): r for r in std}
    s = np.array([by_t.get(round(x, 4), [np.nan] * 10) for x in t])
    lat = np.interp(t, truth[:, 1], truth[:, 2])
    lon = np.interp(t, truth[:, 1], truth[:, 3])
    yaw_t = np.interp(t, truth[:, 1], np.unwrap(np.radians(truth[:, 10])))
    s2 = np.sin(np.radians(lat)) ** 2
    rn = score_truth.A / np.sqrt(1.0 - score_truth.E2 * s2)
    rm = score_truth.A * (1.0 - score_truth.E2) / (1.0 - score_truth.E2 * s2) ** 1.5
    h = np.interp(t, truth[:, 1], truth[:, 4])
    e_n = np.radians(nav[:, 2] - lat) * (rm + h)
    e_e = np.radians(score_truth.wrap180(nav[:, 3] - lon)) * (rn + h) * np.cos(np.radians(lat))
    e_yaw = score_truth.wrap180(nav[:, 10] - np.degrees(yaw_t))
    ok = np.stack([np.abs(e_n) <= 2 * s[:, 1], np.abs(e_e) <= 2 * s[:, 2], np.abs(e_yaw) <= 2 * s[:, 9]], -1)
    return ok, nan


def import_cmd(a, d, drive, rec):
    """`navsync import kf-gins` of a drive (fixes at their epochs, PPS)."""
    return [a.navsync, "import", "kf-gins", "--imu", os.path.join(drive, "imu.txt"),
            "--gnss", os.path.join(drive, "gnss.pos"), "--truth", os.path.join(drive, "truth.nav"),
            "--out", rec, "--force"]


def delayed_imu(drive, delay_s):
    """imu.txt with its tags `delay_s` early (on the GNSS axis, where gnss.pos and truth.nav
    stay, the fixes come that much late): its file name."""
    with open(os.path.join(drive, "imu.txt")) as f, open(os.path.join(drive, "imu_delayed.txt"), "w") as g:
        for line in f:
            t, _, rest = line.strip().partition(" ")
            if t:
                g.write(f"{float(t) - delay_s:.9f} {rest}\n")
    return "imu_delayed.txt"


def replay(a, d, rec, work, extra=()):
    """`navsync replay --estimate` as a user runs it: (exit status, summary, output folder)."""
    out = os.path.join(work, "out")
    summary = os.path.join(work, "summary.json")
    rep = [a.navsync, "replay", rec, "--estimate", *extra, "--lever-arm", ",".join(map(str, d["lever_arm"])),
           "--format", "kf-gins", "--out", out + "/", "--summary-json", summary, "--force"]
    if d["latency_s"] is not None:
        rep.append("--software-sync")
    if getattr(a, "imu_model", "default") == "matched":
        rep += ["--imu-model", d["preset"]]
    rc = run(rep, os.path.join(work, "replay.log"))
    s = {}
    if os.path.exists(summary):
        with open(summary) as f:
            s = json.load(f)
    return rc, s, out


def array_run(a, d, gen, work):
    """The drive again with vibration and an IMU array; the offsets against the truth."""
    rng = random.Random(d["seed"])
    offsets = [round(rng.uniform(-0.02, 0.02), 4) for _ in range(2)]
    vib = round(rng.uniform(0.3, 3.0), 2)
    os.makedirs(work, exist_ok=True)
    drive = os.path.join(work, "drive")
    gen = [drive if x == gen[2] else x for x in gen]
    if run(gen + ["--vibration", str(vib), "--array-offsets", *map(str, offsets)],
           os.path.join(work, "generate.log")) != 0:
        raise SystemExit(f"run {d['index']}: the array generator failed (see {work}/generate.log)")
    rec = os.path.join(work, "rec.mcap")
    imp = import_cmd(a, d, drive, rec)
    imp += [x for i in range(len(offsets)) for x in ("--array-imu", f"{i + 1}={drive}/imu{i + 1}.txt")]
    if d["latency_s"] is not None:
        imp += ["--no-pps", "--gnss-latency", str(d["latency_s"])]
    if run(imp, os.path.join(work, "import.log")) != 0:
        raise SystemExit(f"run {d['index']}: the array import failed (see {work}/import.log)")
    rc, s, out = replay(a, d, rec, work, ["--imus", "0,1,2"])
    _, nan = coverage(os.path.join(out, "KF_GINS_Navresult.nav"), os.path.join(out, "KF_GINS_STD.txt"),
                      os.path.join(drive, "truth.nav"))
    usable = s.get("usable_states") or 0
    r = {"vibration": vib, "offsets_true_s": offsets, "exit": rc, "problem": s.get("problem"), "nan": nan,
         "silent": (rc == 0 and (usable == 0 or s.get("problem") is not None)) or (rc != 0 and not s.get("problem"))}
    est, sd = s.get("imu_offset_est_s", {}), s.get("imu_offset_std_s", {})
    r["offsets"] = [[est.get(str(i + 1)), sd.get(str(i + 1)), t] for i, t in enumerate(offsets)]
    r["offsets_within_2sigma"] = [e is not None and s_ is not None and abs(e - t) <= 2 * s_
                                  for e, s_, t in r["offsets"]]
    r["offsets_converged"] = [s_ is not None and s_ < 1e-3 for _, s_, _ in r["offsets"]]
    return r


def one(a, d, work):
    os.makedirs(work, exist_ok=True)
    drive = os.path.join(work, "drive")
    gen = [sys.executable, os.path.join(HERE, "independent_drive.py"), drive, "--preset", d["preset"],
           "--seed", str(d["seed"]), "--duration", str(d["duration"]), "--static", "30",
           "--speed-scale", str(PROFILES[d["profile"]]), "--heading0", str(d["heading0"]),
           "--lat0", str(d["lat0"]), "--lon0", str(d["lon0"]), "--gnss-rate", str(d["gnss_rate"]),
           "--gnss-sigma", str(d["gnss_sigma"]), str(d["gnss_sigma"]), str(2 * d["gnss_sigma"]),
           "--lever-arm", *map(str, d["lever_arm"])]
    if run(gen, os.path.join(work, "generate.log")) != 0:
        raise SystemExit(f"run {d['index']}: the generator failed (see {work}/generate.log)")
    rec = os.path.join(work, "rec.mcap")
    imp = import_cmd(a, d, drive, rec)
    if a.kf_gins:
        imp += ["--kf-gins-config", os.path.join(drive, "kf-gins.yaml")]
    imp_epochs = list(imp)  # fixes at their epochs (PPS)
    if d["latency_s"] is not None:
        imp += ["--no-pps", "--gnss-latency", str(d["latency_s"])]
    elif d.get("pps_delay_s"):
        imp[imp.index("--imu") + 1] = os.path.join(drive, delayed_imu(drive, d["pps_delay_s"]))
    if run(imp, os.path.join(work, "import.log")) != 0:
        raise SystemExit(f"run {d['index']}: the import failed (see {work}/import.log)")
    rc, s, out = replay(a, d, rec, work)
    usable = s.get("usable_states") or 0
    ok, nan = coverage(os.path.join(out, "KF_GINS_Navresult.nav"), os.path.join(out, "KF_GINS_STD.txt"),
                       os.path.join(drive, "truth.nav"))
    r = dict(d, exit=rc, problem=s.get("problem"), usable_states=usable, nan=nan,
             silent=(rc == 0 and (usable == 0 or s.get("problem") is not None)) or (rc != 0 and not s.get("problem")))
    if ok is not None and len(ok):
        r["epochs"] = int(len(ok))
        r["within_2sigma"] = [int(x) for x in ok.sum(0)]
    est, sd, true = s.get("gnss_delay_est_s"), s.get("gnss_delay_std_s"), s.get("gnss_delay_true_s")
    if d["latency_s"] is None and true is not None:
        true = d.get("pps_delay_s") or 0.0  # the summary knows the import's epochs, not the draw
    if None not in (est, sd, true):
        r["delay"] = [est, sd, true]
        r["delay_within_2sigma"] = abs(est - true) <= 2 * sd
    if rc == 0 and usable:
        sc = score_truth.score(score_truth.load_nav(os.path.join(out, "KF_GINS_Navresult.nav")),
                               score_truth.load_nav(os.path.join(drive, "truth.nav")))
        r["horizontal_rms_m"] = sc["horizontal_rms_m"]
    if a.kf_gins and (d["latency_s"] is not None or d.get("pps_delay_s")):
        # The information KF-GINS has: each fix at its epoch.
        same = os.path.join(work, "same-info")
        os.makedirs(same, exist_ok=True)
        rec2 = os.path.join(same, "rec.mcap")
        imp2 = list(imp_epochs)
        imp2[imp2.index("--out") + 1] = rec2
        if (run(imp2, os.path.join(same, "import.log")) == 0
                and replay(a, dict(d, latency_s=None), rec2, same)[0] == 0):
            r["horizontal_rms_same_info_m"] = score_truth.score(
                score_truth.load_nav(os.path.join(same, "out", "KF_GINS_Navresult.nav")),
                score_truth.load_nav(os.path.join(drive, "truth.nav")))["horizontal_rms_m"]
    if a.array:
        r["array"] = array_run(a, d, gen, os.path.join(work, "array"))
    if a.kf_gins:
        run([a.kf_gins, os.path.join(drive, "kf-gins.yaml")], os.path.join(work, "kf-gins.log"))
        kf = os.path.join(drive, "kf-gins-out", "KF_GINS_Navresult.nav")
        if os.path.exists(kf):
            r["kf_gins_horizontal_rms_m"] = score_truth.score(
                score_truth.load_nav(kf), score_truth.load_nav(os.path.join(drive, "truth.nav")))["horizontal_rms_m"]
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--navsync", default=os.path.join(REPO, "target", "release", "navsync"))
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=150.0)
    ap.add_argument("--work", help="working directory (default: a temporary one)")
    ap.add_argument("--keep", action="store_true",
                    help="keep each run's files (~60 MB a run) in the working directory")
    ap.add_argument("--kf-gins", help="KF-GINS binary: compare on the same files")
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("--imu-model", choices=["default", "matched"], default="default",
                    help="default: navsync's own (generic, an IMU of unknown class); matched: each drive's "
                         "IMU grade given as --imu-model (the filter's consistency when it knows its IMU)")
    ap.add_argument("--no-array", dest="array", action="store_false",
                    help="leave out the IMU-array runs (offset coverage)")
    a = ap.parse_args()
    temporary = a.work is None
    a.work = a.work or tempfile.mkdtemp(prefix="navsync-sweep-")
    rng = random.Random(a.seed)
    runs = []
    for i in range(a.runs):
        d = draw(rng, i, a.duration)
        r = one(a, d, os.path.join(a.work, f"run{i:03d}"))
        if not a.keep:
            shutil.rmtree(os.path.join(a.work, f"run{i:03d}"), ignore_errors=True)
        runs.append(r)
        cov = r.get("within_2sigma")
        print(f"{i:3d} {r['profile']:10s} {r['preset']:10s} sigma {r['gnss_sigma']:6.3f} m {r['gnss_rate']:2d} Hz "
              f"lat {r['lat0']:7.2f} {'latency %.2f s' % r['latency_s'] if r['latency_s'] is not None else 'PPS %+.3f s' % (r.get('pps_delay_s') or 0):14s} "
              f"exit {r['exit']} usable {r['usable_states']:6d} nan {r['nan']} silent {r['silent']} "
              f"2sigma {[round(c / max(r.get('epochs', 1), 1), 3) for c in cov] if cov else '-'} "
              f"delay {'ok' if r.get('delay_within_2sigma') else r.get('delay')}"
              + (f" rms {r.get('horizontal_rms_same_info_m', r.get('horizontal_rms_m', math.nan)):.3f} m"
                 f" KF-GINS {r['kf_gins_horizontal_rms_m']:.3f} m" if "kf_gins_horizontal_rms_m" in r else "")
              + (f" | array vib {r['array']['vibration']} exit {r['array']['exit']} offsets "
                 + " ".join(f"{1e3 * t:+.1f}:{'-' if e is None else f'{1e3 * e:+.2f}+-{1e3 * s_:.2f}'}"
                            for e, s_, t in r["array"]["offsets"]) + " ms" if "array" in r else ""),
              flush=True)
    epochs = sum(r.get("epochs", 0) for r in runs)
    within = [sum(r.get("within_2sigma", [0, 0, 0])[k] for r in runs) for k in range(3)]
    delays = [r["delay_within_2sigma"] for r in runs if "delay_within_2sigma" in r]
    arrays = [r["array"] for r in runs if "array" in r]
    offs = [w for x in arrays for w in x["offsets_within_2sigma"]]
    conv = [c for x in arrays for c in x["offsets_converged"]]
    res = {
        "runs": len(runs),
        "nan_runs": sum(r["nan"] for r in runs) + sum(x["nan"] for x in arrays),
        "silent_failures": sum(r["silent"] for r in runs) + sum(x["silent"] for x in arrays),
        "array_runs": len(arrays),
        "array_failed_runs": sum(x["exit"] != 0 for x in arrays),
        "failed_runs": sum(r["exit"] != 0 for r in runs),
        "epochs": epochs,
        "coverage_2sigma": {"north": within[0] / max(epochs, 1), "east": within[1] / max(epochs, 1),
                            "yaw": within[2] / max(epochs, 1),
                            "delay": sum(delays) / max(len(delays), 1),
                            "imu_offset": sum(offs) / max(len(offs), 1)},
        "imu_offsets": len(offs),
        "imu_offsets_converged": sum(conv),
        "work": a.work,
        "detail": runs,
    }
    pairs = [(r.get("horizontal_rms_same_info_m", r.get("horizontal_rms_m")), r["kf_gins_horizontal_rms_m"])
             for r in runs if "horizontal_rms_m" in r and "kf_gins_horizontal_rms_m" in r]
    pairs = [(n, k) for n, k in pairs if n is not None]
    if pairs:
        res["navsync_within_1p1_kf_gins"] = sum(n <= 1.1 * k for n, k in pairs) / len(pairs)
    c = res["coverage_2sigma"]
    print(f"{len(runs)} runs: {res['nan_runs']} with NaN, {res['silent_failures']} silent failures, "
          f"{res['failed_runs']} failed (saying why); within 2 sigma: north {c['north']:.3f}, east {c['east']:.3f}, "
          f"yaw {c['yaw']:.3f} over {epochs} epochs, delay {c['delay']:.3f} of {len(delays)} runs"
          + (f", IMU offsets {c['imu_offset']:.3f} of {len(offs)} ({sum(conv)} converged to < 1 ms)" if offs else "")
          + (f"; navsync <= 1.1 x KF-GINS on {res['navsync_within_1p1_kf_gins']:.2f} of {len(pairs)} drives"
             if pairs else ""))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1)
    if temporary and not a.keep:
        shutil.rmtree(a.work, ignore_errors=True)


if __name__ == "__main__":
    main()
