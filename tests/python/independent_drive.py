#!/usr/bin/env python3
"""Independent GNSS/INS car-drive generator writing KF-GINS file formats (numpy only).

Written from first principles, sharing no code or design with navsync's own simulator, so that
navsync's filter can be scored on data it did not generate.

Trajectory (all in time relative to the start t0, seconds):
  * four smooth scalar profiles, each a constant plus a sum of "events" (a change by DELTA over
    [t_s, t_s + T] shaped by the C3 septic smooth step S(u) = 35u^4 - 84u^5 + 70u^6 - 20u^7,
    whose 1st..3rd derivatives vanish at u = 0 and u = 1):
      speed s(t) [m/s], heading psi(t), road grade theta(t), road bank b(t);
  * NED velocity v^n = s [cos(theta) cos(psi), cos(theta) sin(psi), -sin(theta)]
    (the velocity lies along body x: no side slip, no vertical body velocity);
  * attitude (ZYX Euler, C_b^n = Rz(psi) Ry(theta) Rx(phi)): yaw = psi (heading along track),
    pitch = theta (follows the climb), roll phi = b(t) - k_roll * s * dpsi/dt (the body rolls
    a little out of the turn, k_roll deg per m/s^2 of lateral acceleration);
  * geodetic position on WGS-84 from dlat/dt = vN/(R_M + h), dlon/dt = vE/((R_N + h) cos lat),
    dh/dt = -vD, solved on the IMU grid by Picard iteration with per-interval Gauss-Legendre
    quadrature (converges to ~1e-16 rad), cubic Hermite (value + exact derivative) between
    grid points.
  * Sensor truth: omega_ib^b = omega_nb^b(Euler rates) + C_n^b (omega_ie^n + omega_en^n),
    f^b = C_n^b (dv^n/dt + (2 omega_ie^n + omega_en^n) x v^n - g^n), with omega_en^n using
    R_M + h and R_N + h, and normal gravity = the GRS80 series expansion of Somigliana's
    formula with the free-air height terms (Torge & Mueller, Geodesy 2012, eq. 4.78a/4.79),
    the model KF-GINS's Earth::gravity() uses:
      g0 = 9.7803267715 (1 + 0.0052790414 s2 + 0.0000232718 s2^2 + 0.0000001262 s2^3
                          + 0.0000000007 s2^4),  s2 = sin^2(lat)
      g  = g0 - (3.0877e-6 - 4.3e-9 s2) h + 0.72e-12 h^2.
  * IMU increments over (t_{k-1}, t_k]: Gauss-Legendre quadrature (default 4 nodes x 2
    sub-intervals) of omega_ib^b and f^b: the integrands are analytic inside each interval
    (event boundaries are on whole seconds, which are on the IMU grid for integer rates), so the
    increments are exact to rounding (--self-check measures it against 6 nodes x 4).

Sensor errors (seeded, numpy default_rng(seed)), per axis, KF-GINS's model:
    dtheta_meas = (1 + s_g) dtheta + (b_g_on + b_g_gm(t)) dt + ARW noise
    dv_meas     = (1 + s_a) dv     + (b_a_on + b_a_gm(t)) dt + VRW noise
  turn-on biases and scale factors are random constants N(0, sigma), the bias instability is a
  first-order Gauss-Markov process (sigma, correlation time tau), exact discretisation, started
  in its stationary distribution. KF-GINS compensates exactly this form ((meas - b dt)/(1 + s)).

Vibration (--vibration V, default none): per body axis, three tones of 8-40 Hz as exact rate and
acceleration terms of a small rotation and displacement (the excursions themselves, <= 0.03 V deg
and 0.09 V mm, are left out of the truth): what makes an IMU array's time offsets observable.

IMU array (--array-offsets TD1 TD2 ...): IMU i (1, 2, ...) sits with IMU 0 (no lever arm, same
axes), has its own draw of the same error model (default_rng([seed, i])) and its samples are
stamped TD_i late: its row tagged t_k holds the increments over (t_{k-1} - TD_i, t_k - TD_i]
(navsync's convention for an IMU offset Td, estimator/src/array/imu_offset.rs).

Outputs in OUTDIR: imu.txt (imu1.txt ... for an array), gnss.pos, truth.nav, kf-gins.yaml (+
empty kf-gins-out/ for its results), meta.json. See tests/python/README.md.
"""

import argparse
import json
import math
import os
import sys
import time

import numpy as np

# ---------------------------------------------------------------- WGS-84 / Earth model
WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)  # 0.00669437999014
OMEGA_IE = 7.2921151467e-5  # rad/s
D2R = math.pi / 180.0


def radii(lat):
    """Meridian (R_M) and prime-vertical (R_N) radii of curvature."""
    s2 = np.sin(lat) ** 2
    w = 1.0 - WGS84_E2 * s2
    rn = WGS84_A / np.sqrt(w)
    rm = WGS84_A * (1.0 - WGS84_E2) / (w * np.sqrt(w))
    return rm, rn


def normal_gravity(lat, h):
    """GRS80 Somigliana series + height terms (Torge & Mueller 2012, 4.78a/4.79), m/s^2."""
    s2 = np.sin(lat) ** 2
    s4 = s2 * s2
    g0 = 9.7803267715 * (1.0 + 0.0052790414 * s2 + 0.0000232718 * s4
                         + 0.0000001262 * s2 * s4 + 0.0000000007 * s4 * s4)
    return g0 - (3.0877e-6 - 4.3e-9 * s2) * h + 0.72e-12 * h * h


def geodetic_to_ecef(lat, lon, h):
    _, rn = radii(lat)
    cl = np.cos(lat)
    return np.stack([(rn + h) * cl * np.cos(lon), (rn + h) * cl * np.sin(lon),
                     (rn * (1.0 - WGS84_E2) + h) * np.sin(lat)], axis=-1)


def ecef_to_geodetic(r):
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    p = np.hypot(x, y)
    lon = np.arctan2(y, x)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    for _ in range(8):
        _, rn = radii(lat)
        h = p / np.cos(lat) - rn
        lat = np.arctan2(z, p * (1.0 - WGS84_E2 * rn / (rn + h)))
    _, rn = radii(lat)
    h = p / np.cos(lat) - rn
    return lat, lon, h


def c_n_to_e(lat, lon):
    """C_n^e (NED -> ECEF), shape (..., 3, 3)."""
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    z = np.zeros_like(lat)
    return np.stack([np.stack([-sl * co, -so, -cl * co], -1),
                     np.stack([-sl * so, co, -cl * so], -1),
                     np.stack([cl, z, -sl], -1)], -2)


# ---------------------------------------------------------------- smooth step (C3)
_S = np.array([-20.0, 70.0, -84.0, 35.0, 0.0, 0.0, 0.0, 0.0])  # highest power first
_S1 = np.polyder(_S)
_S2 = np.polyder(_S1)


def smooth_step(u):
    """S(u), S'(u), S''(u) with u clipped to [0, 1] (S = 0 before, 1 after)."""
    uc = np.clip(u, 0.0, 1.0)
    inside = (u > 0.0) & (u < 1.0)
    return np.polyval(_S, uc), np.where(inside, np.polyval(_S1, uc), 0.0), \
        np.where(inside, np.polyval(_S2, uc), 0.0)


# ---------------------------------------------------------------- the drive
# Motion pattern after the standing start: (quantity, start [s after motion start],
# duration [s], change). Units: speed m/s, heading/grade/bank deg. All boundaries on whole
# seconds. 600 s long, ends stationary; repeated for longer --duration.
MOTION_PATTERN = [
    ("speed", 0, 12, 12.0),        # pull away, 0 -> 12 m/s
    ("grade", 1, 5, -0.8),         # leave the parking slope
    ("bank", 1, 5, 0.5),
    ("heading", 15, 12, 90.0),     # right turn 90 deg at 12 m/s
    ("speed", 30, 10, 8.0),        # 12 -> 20 m/s
    ("grade", 40, 5, 3.0),         # climb 3 deg
    ("grade", 70, 5, -3.0),
    ("heading", 80, 20, -45.0),    # gentle left 45 deg at 20 m/s
    ("speed", 110, 10, -12.0),     # 20 -> 8
    ("heading", 122, 8, -120.0),   # sharp left 120 deg at 8 m/s
    ("speed", 135, 10, -8.0),      # stop
    ("speed", 165, 10, 15.0),      # (20 s stop) 0 -> 15
    ("grade", 180, 5, -4.0),       # descent 4 deg
    ("grade", 200, 5, 4.0),
    ("speed", 212, 5, -5.0),       # 15 -> 10
    ("heading", 220, 16, 180.0),   # U-turn right 180 deg at 10 m/s
    ("speed", 240, 15, 8.0),       # 10 -> 18
    ("heading", 260, 10, -30.0),   # S-curve
    ("heading", 270, 10, 30.0),
    ("grade", 285, 5, 2.5),        # climb 2.5 deg
    ("grade", 315, 5, -2.5),
    ("speed", 330, 10, -12.0),     # 18 -> 6
    ("heading", 342, 8, 60.0),     # right 60, left 75 at 6 m/s
    ("heading", 350, 8, -75.0),
    ("speed", 360, 10, 10.0),      # 6 -> 16
    ("heading", 375, 20, 100.0),   # long right 100 deg at 16 m/s
    ("speed", 400, 15, -16.0),     # stop
    ("speed", 440, 12, 14.0),      # (25 s stop) 0 -> 14
    ("grade", 455, 5, -2.0),       # descent 2 deg
    ("heading", 470, 15, -70.0),   # left 70 deg at 14 m/s
    ("grade", 480, 5, 2.0),
    ("speed", 490, 15, 6.0),       # 14 -> 20
    ("heading", 510, 15, 45.0),    # right 45 deg at 20 m/s
    ("speed", 530, 10, -10.0),     # 20 -> 10
    ("heading", 545, 10, -90.0),   # left 90 deg at 10 m/s
    ("speed", 560, 15, -10.0),     # stop; stationary to 600
]
PATTERN_LENGTH = 600.0


class Drive:
    """Analytic kinematics of the drive (everything except position, which is integrated)."""

    def __init__(self, args):
        self.static = float(args.static)
        self.duration = float(args.duration)
        self.k_roll = args.roll_gain * D2R  # rad per m/s^2
        # Every speed change scaled: 1 a car (up to 20 m/s), 0.08 a pedestrian, 0.04 a slow
        # robot; the stops and turns stay where they are.
        self.speed_scale = float(getattr(args, "speed_scale", 1.0))
        self.init = {"speed": 0.0, "heading": args.heading0 * D2R,
                     "grade": args.grade0 * D2R, "bank": args.bank0 * D2R}
        self.events = {q: [] for q in self.init}
        # Vibration (--vibration V): per body axis three tones of 8-40 Hz, a rotation of
        # V * 0.01 deg and a displacement of V * 0.03 mm each, random phases (own seed).
        vr = np.random.default_rng([int(getattr(args, "seed", 1)), 1000])
        v = float(getattr(args, "vibration", 0.0))
        self.vibration = [] if v <= 0.0 else [
            (kind, axis, amp, 2.0 * math.pi * vr.uniform(8.0, 40.0), vr.uniform(0.0, 2.0 * math.pi))
            for kind, amp in (("rotation", v * 0.01 * D2R), ("displacement", v * 0.03e-3))
            for axis in range(3) for _ in range(3)]
        rep = 0
        while self.static + rep * PATTERN_LENGTH < self.duration:
            off = self.static + rep * PATTERN_LENGTH
            for q, ts, T, d in MOTION_PATTERN:
                if off + ts >= self.duration:
                    continue
                if rep > 0 and q in ("grade", "bank") and ts < 10:
                    continue  # the parking-slope changes only once
                scale = self.speed_scale if q == "speed" else D2R
                self.events[q].append((off + ts, float(T), d * scale))
            rep += 1

    def profile(self, q, t):
        v = np.full_like(t, self.init[q])
        d1 = np.zeros_like(t)
        d2 = np.zeros_like(t)
        for ts, T, d in self.events[q]:
            s0, s1, s2 = smooth_step((t - ts) / T)
            v += d * s0
            d1 += d / T * s1
            d2 += d / (T * T) * s2
        return v, d1, d2

    def motion(self, t):
        """Speed, NED velocity, its derivative, Euler angles and omega_nb^b at times t."""
        s, sd, _ = self.profile("speed", t)
        psi, psid, psidd = self.profile("heading", t)
        th, thd, _ = self.profile("grade", t)
        b, bd, _ = self.profile("bank", t)
        phi = b - self.k_roll * s * psid
        phid = bd - self.k_roll * (sd * psid + s * psidd)
        cth, sth, cps, sps = np.cos(th), np.sin(th), np.cos(psi), np.sin(psi)
        u = np.stack([cth * cps, cth * sps, -sth], -1)
        du = np.stack([-sth * thd * cps - cth * sps * psid,
                       -sth * thd * sps + cth * cps * psid,
                       -cth * thd], -1)
        vn = s[:, None] * u
        an = sd[:, None] * u + s[:, None] * du
        cph, sph = np.cos(phi), np.sin(phi)
        w_nb = np.stack([phid - psid * sth,
                         thd * cph + psid * sph * cth,
                         -thd * sph + psid * cph * cth], -1)
        return dict(speed=s, vn=vn, an=an, euler=np.stack([phi, th, psi], -1), w_nb=w_nb)


def euler_to_cbn(e):
    """C_b^n = Rz(yaw) Ry(pitch) Rx(roll), e = (..., [roll, pitch, yaw])."""
    cr, sr = np.cos(e[..., 0]), np.sin(e[..., 0])
    cp, sp = np.cos(e[..., 1]), np.sin(e[..., 1])
    cy, sy = np.cos(e[..., 2]), np.sin(e[..., 2])
    return np.stack([
        np.stack([cp * cy, -cr * sy + sr * sp * cy, sr * sy + cr * sp * cy], -1),
        np.stack([cp * sy, cr * cy + sr * sp * sy, -sr * cy + cr * sp * sy], -1),
        np.stack([-sp, sr * cp, cr * cp], -1)], -2)


def cbn_to_euler(c):
    roll = np.arctan2(c[..., 2, 1], c[..., 2, 2])
    pitch = np.arcsin(np.clip(-c[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(c[..., 1, 0], c[..., 0, 0])
    return np.stack([roll, pitch, yaw], -1)


def earth_rates(lat, h, vn):
    rm, rn = radii(lat)
    w_ie = np.stack([OMEGA_IE * np.cos(lat), np.zeros_like(lat), -OMEGA_IE * np.sin(lat)], -1)
    w_en = np.stack([vn[:, 1] / (rn + h), -vn[:, 0] / (rm + h),
                     -vn[:, 1] * np.tan(lat) / (rn + h)], -1)
    return w_ie, w_en


def sensor_truth(drive, t, lat, h):
    """True omega_ib^b and f^b at times t (position lat, h given at the same times)."""
    m = drive.motion(t)
    vn = m["vn"]
    w_ie, w_en = earth_rates(lat, h, vn)
    cnb = np.swapaxes(euler_to_cbn(m["euler"]), -1, -2)
    g = np.zeros_like(vn)
    g[:, 2] = normal_gravity(lat, h)
    fn = m["an"] + np.cross(2.0 * w_ie + w_en, vn) - g
    f_b = np.einsum("nij,nj->ni", cnb, fn)
    w_ib = m["w_nb"] + np.einsum("nij,nj->ni", cnb, w_ie + w_en)
    # Vibration: a rotation A sin(wt + p) about a body axis adds its rate A w cos(wt + p); a
    # displacement D sin(wt + p) along it adds its acceleration -D w^2 sin(wt + p).
    for kind, axis, amp, w, ph in drive.vibration:
        if kind == "rotation":
            w_ib[:, axis] += amp * w * np.cos(w * t + ph)
        else:
            f_b[:, axis] -= amp * w * w * np.sin(w * t + ph)
    return w_ib, f_b


def gauss_legendre_unit(nodes, substeps):
    """Nodes c in (0,1) and weights w (sum 1) of composite Gauss-Legendre on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    c = np.concatenate([(j + 0.5 * (x + 1.0)) / substeps for j in range(substeps)])
    ww = np.concatenate([0.5 * w / substeps for _ in range(substeps)])
    return c, ww


def hermite(y0, y1, d0, d1, dt, c):
    """Cubic Hermite between grid values y0, y1 (derivatives d0, d1) at fractions c (M,)."""
    c = c[None, :]
    h00 = 2 * c ** 3 - 3 * c ** 2 + 1
    h10 = c ** 3 - 2 * c ** 2 + c
    h01 = -2 * c ** 3 + 3 * c ** 2
    h11 = c ** 3 - c ** 2
    return (h00 * y0[:, None] + h10 * dt * d0[:, None] + h01 * y1[:, None]
            + h11 * dt * d1[:, None])


class Track:
    """Geodetic position of the IMU on a uniform grid tau_k = tau0 + k dt, with derivatives."""

    def __init__(self, drive, lat0, lon0, h0, tau0, dt, n, gl=(4, 2)):
        self.drive, self.tau0, self.dt, self.n = drive, tau0, dt, n
        self.tg = tau0 + dt * np.arange(n + 1)
        c, w = gauss_legendre_unit(*gl)
        tn = (self.tg[:-1, None] + dt * c[None, :]).ravel()
        vg = drive.motion(self.tg)["vn"]
        vnode = drive.motion(tn)["vn"].reshape(n, len(c), 3)
        # height: exact quadrature of -vD
        self.h = h0 + np.concatenate([[0.0], np.cumsum(-dt * (vnode[:, :, 2] @ w))])
        self.dh = -vg[:, 2]
        hn = hermite(self.h[:-1], self.h[1:], self.dh[:-1], self.dh[1:], dt, c)
        # latitude: Picard iteration
        lat = np.full(n + 1, lat0)
        self.iterations = []
        for it in range(12):
            rm, _ = radii(lat)
            dlat = vg[:, 0] / (rm + self.h)
            latn = hermite(lat[:-1], lat[1:], dlat[:-1], dlat[1:], dt, c)
            rmn, _ = radii(latn)
            inc = dt * ((vnode[:, :, 0] / (rmn + hn)) @ w)
            new = lat0 + np.concatenate([[0.0], np.cumsum(inc)])
            change = float(np.max(np.abs(new - lat)))
            lat = new
            self.iterations.append(change)
            if change < 1e-15:
                break
        self.lat = lat
        rm, rn = radii(lat)
        self.dlat = vg[:, 0] / (rm + self.h)
        latn = hermite(lat[:-1], lat[1:], self.dlat[:-1], self.dlat[1:], dt, c)
        _, rnn = radii(latn)
        inc = dt * ((vnode[:, :, 1] / ((rnn + hn) * np.cos(latn))) @ w)
        self.lon = lon0 + np.concatenate([[0.0], np.cumsum(inc)])
        self.dlon = vg[:, 1] / ((rn + self.h) * np.cos(lat))

    def at(self, tau):
        """lat, lon, h at arbitrary times inside the grid (cubic Hermite, exact derivatives)."""
        tau = np.asarray(tau, dtype=float)
        k = np.clip(np.floor((tau - self.tau0) / self.dt).astype(int), 0, self.n - 1)
        c = (tau - self.tg[k]) / self.dt
        out = []
        for y, d in ((self.lat, self.dlat), (self.lon, self.dlon), (self.h, self.dh)):
            h00 = 2 * c ** 3 - 3 * c ** 2 + 1
            h10 = c ** 3 - 2 * c ** 2 + c
            h01 = -2 * c ** 3 + 3 * c ** 2
            h11 = c ** 3 - c ** 2
            out.append(h00 * y[k] + h10 * self.dt * d[k] + h01 * y[k + 1]
                       + h11 * self.dt * d[k + 1])
        return out


def increments(drive, track, gl, chunk=20000):
    """Exact increments over each grid interval (tau_{k-1}, tau_k], k = 1..n."""
    c, w = gauss_legendre_unit(*gl)
    n, dt = track.n, track.dt
    dth = np.empty((n, 3))
    dvl = np.empty((n, 3))
    for a in range(0, n, chunk):
        b = min(n, a + chunk)
        tn = (track.tg[a:b, None] + dt * c[None, :]).ravel()
        latn = hermite(track.lat[a:b], track.lat[a + 1:b + 1], track.dlat[a:b],
                       track.dlat[a + 1:b + 1], dt, c).ravel()
        hn = hermite(track.h[a:b], track.h[a + 1:b + 1], track.dh[a:b],
                     track.dh[a + 1:b + 1], dt, c).ravel()
        w_ib, f_b = sensor_truth(drive, tn, latn, hn)
        dth[a:b] = dt * np.einsum("nmj,m->nj", w_ib.reshape(b - a, len(c), 3), w)
        dvl[a:b] = dt * np.einsum("nmj,m->nj", f_b.reshape(b - a, len(c), 3), w)
    return dth, dvl


# ---------------------------------------------------------------- sensor errors
PRESETS = {
    # ARW deg/sqrt(h), VRW m/s/sqrt(h), bias turn-on / GM instability (deg/h, mGal),
    # scale factors ppm, GM correlation time h
    "industrial": dict(arw=0.1, vrw=0.1, gyro_bias=2.0, gyro_bias_instab=0.5,
                       accel_bias=50.0, accel_bias_instab=20.0, gyro_scale=300.0,
                       accel_scale=300.0, bias_corr_time=1.0),
    "consumer": dict(arw=0.3, vrw=0.2, gyro_bias=300.0, gyro_bias_instab=20.0,
                     accel_bias=3000.0, accel_bias_instab=300.0, gyro_scale=1000.0,
                     accel_scale=1000.0, bias_corr_time=1.0),
}


def gauss_markov(rng, n, dt, sigma, tau_s):
    """n samples (n, 3) of a stationary first-order GM process, exact discretisation."""
    x = np.zeros((n, 3))
    if sigma <= 0.0:
        return x
    a = math.exp(-dt / tau_s)
    q = sigma * math.sqrt(1.0 - a * a) * rng.standard_normal((n, 3))
    x_prev = sigma * rng.standard_normal(3)
    block = max(1, int(min(n, 5.0 * tau_s / dt)))  # keeps a^-k <= e^5
    for s in range(0, n, block):
        e = min(n, s + block)
        k = np.arange(1, e - s + 1)[:, None]
        ak = a ** k
        x[s:e] = ak * (x_prev + np.cumsum(q[s:e] / ak, axis=0))
        x_prev = x[e - 1]
    return x


def add_sensor_errors(rng, dth, dvl, dt, p, enabled):
    """Returns measured increments and the realised error parameters."""
    n = len(dth)
    draws = {
        "gyro_bias_turn_on_deg_h": rng.standard_normal(3) * p["gyro_bias"],
        "accel_bias_turn_on_mgal": rng.standard_normal(3) * p["accel_bias"],
        "gyro_scale_ppm": rng.standard_normal(3) * p["gyro_scale"],
        "accel_scale_ppm": rng.standard_normal(3) * p["accel_scale"],
    }
    tau = p["bias_corr_time"] * 3600.0
    bg_gm = gauss_markov(rng, n, dt, p["gyro_bias_instab"] * D2R / 3600.0, tau)
    ba_gm = gauss_markov(rng, n, dt, p["accel_bias_instab"] * 1e-5, tau)
    wg = rng.standard_normal((n, 3)) * (p["arw"] * D2R / 60.0) * math.sqrt(dt)
    wa = rng.standard_normal((n, 3)) * (p["vrw"] / 60.0) * math.sqrt(dt)
    if not enabled:
        return dth.copy(), dvl.copy(), None
    bg = draws["gyro_bias_turn_on_deg_h"] * D2R / 3600.0 + bg_gm
    ba = draws["accel_bias_turn_on_mgal"] * 1e-5 + ba_gm
    mth = (1.0 + draws["gyro_scale_ppm"] * 1e-6) * dth + bg * dt + wg
    mvl = (1.0 + draws["accel_scale_ppm"] * 1e-6) * dvl + ba * dt + wa
    real = {k: v.tolist() for k, v in draws.items()}
    real["gyro_bias_total_start_deg_h"] = (bg[0] * 3600.0 / D2R).tolist()
    real["gyro_bias_total_end_deg_h"] = (bg[-1] * 3600.0 / D2R).tolist()
    real["accel_bias_total_start_mgal"] = (ba[0] * 1e5).tolist()
    real["accel_bias_total_end_mgal"] = (ba[-1] * 1e5).tolist()
    return mth, mvl, real


# ---------------------------------------------------------------- self-check strapdown
def skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rotvec_to_dcm(v):
    a = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    k = skew(v)
    if a < 1e-8:
        s, c = 1.0 - a * a / 6.0, 0.5 - a * a / 24.0
    else:
        s, c = math.sin(a) / a, (1.0 - math.cos(a)) / (a * a)
    return np.eye(3) + s * k + c * (k @ k)


def strapdown(dth, dvl, dt, lat, lon, h, vn, cbn):
    """Free-inertial integration of increments (rows 1.. propagate; row 0 is the interval
    ending at the initial time and only feeds the coning/sculling terms). Two-sample coning
    and sculling, rotation compensation, predictor-corrector for the Earth/transport terms,
    trapezoidal position. Returns arrays of lat, lon, h, vn, cbn at every row time."""
    n = len(dth)
    out_p = np.empty((n, 3))
    out_v = np.empty((n, 3))
    out_c = np.empty((n, 3, 3))
    out_p[0] = (lat, lon, h)
    out_v[0] = vn
    out_c[0] = cbn
    vn = np.array(vn, dtype=float)
    for k in range(1, n):
        a1, v1, a0, v0 = dth[k], dvl[k], dth[k - 1], dvl[k - 1]
        dv_b = v1 + 0.5 * np.cross(a1, v1) + (np.cross(a0, v1) + np.cross(v0, a1)) / 12.0
        phi_b = a1 + np.cross(a0, a1) / 12.0
        latm, hm, vm = lat, h, vn.copy()
        for _ in range(2):  # predictor, corrector with mid-interval values
            rm, rn = radii(latm)
            w_ie = np.array([OMEGA_IE * math.cos(latm), 0.0, -OMEGA_IE * math.sin(latm)])
            w_en = np.array([vm[1] / (rn + hm), -vm[0] / (rm + hm),
                             -vm[1] * math.tan(latm) / (rn + hm)])
            zeta = (w_ie + w_en) * dt
            dv_n = (np.eye(3) - 0.5 * skew(zeta)) @ (cbn @ dv_b)
            g = np.array([0.0, 0.0, normal_gravity(latm, hm)])
            vnew = vn + dv_n + (g - np.cross(2.0 * w_ie + w_en, vm)) * dt
            vm = 0.5 * (vn + vnew)
            hnew = h - vm[2] * dt
            hm = 0.5 * (h + hnew)
            latnew = lat + vm[0] * dt / (rm + hm)
            latm = 0.5 * (lat + latnew)
        rm, rn = radii(latm)
        lon += vm[1] * dt / ((rn + hm) * math.cos(latm))
        lat, h = latm * 2.0 - lat, hm * 2.0 - h
        w_ie = np.array([OMEGA_IE * math.cos(latm), 0.0, -OMEGA_IE * math.sin(latm)])
        w_en = np.array([vm[1] / (rn + hm), -vm[0] / (rm + hm),
                         -vm[1] * math.tan(latm) / (rn + hm)])
        cbn = rotvec_to_dcm(-(w_ie + w_en) * dt) @ cbn @ rotvec_to_dcm(phi_b)
        vn = vnew
        out_p[k] = (lat, lon, h)
        out_v[k] = vn
        out_c[k] = cbn
    return out_p, out_v, out_c


def ned_error(lat_ref, h_ref, dlat, dlon, dh):
    rm, rn = radii(lat_ref)
    return np.stack([dlat * (rm + h_ref), dlon * (rn + h_ref) * np.cos(lat_ref), -dh], -1)


def self_check(drive, track, dth, dvl, dt, args, gl):
    rep = {}
    t0 = time.time()
    hi = (max(6, gl[0] + 2), max(4, gl[1] * 2))
    dth2, dvl2 = increments(drive, track, hi)
    rep["quadrature"] = {
        "reference_rule": f"{hi[0]} nodes x {hi[1]}",
        "max_abs_diff_dtheta_rad": float(np.max(np.abs(dth2 - dth))),
        "max_abs_diff_dvel_m_s": float(np.max(np.abs(dvl2 - dvl))),
        "max_rel_diff_dvel": float(np.max(np.abs(dvl2 - dvl)) / np.max(np.abs(dvl))),
        "max_rel_diff_dtheta": float(np.max(np.abs(dth2 - dth)) / np.max(np.abs(dth))),
    }
    m0 = drive.motion(np.array([0.0]))
    p, v, c = strapdown(dth, dvl, dt, track.lat[1], track.lon[1], track.h[1], m0["vn"][0],
                        euler_to_cbn(m0["euler"][0]))
    # rows of dth correspond to grid points 1..n (grid point 1 = tau 0)
    lat, lon, h = track.lat[1:], track.lon[1:], track.h[1:]
    tau = track.tg[1:]
    m = drive.motion(tau)
    e = ned_error(lat, h, p[:, 0] - lat, p[:, 1] - lon, p[:, 2] - h)
    hor = np.hypot(e[:, 0], e[:, 1])
    ct = euler_to_cbn(m["euler"])
    dc = np.einsum("nji,njk->nik", ct, c)  # C_true^T C_est ~ I + [psi x] (body frame)
    att = np.stack([dc[:, 2, 1], dc[:, 0, 2], dc[:, 1, 0]], -1)
    rep["strapdown"] = {
        "duration_s": float(tau[-1]),
        "max_horizontal_error_m": float(hor.max()),
        "final_horizontal_error_m": float(hor[-1]),
        "max_vertical_error_m": float(np.max(np.abs(e[:, 2]))),
        "max_velocity_error_m_s": float(np.max(np.linalg.norm(v - m["vn"], axis=1))),
        "max_attitude_error_deg": float(np.max(np.abs(att)) / D2R),
        "horizontal_error_at_s": {str(int(s)): float(hor[min(len(hor) - 1, int(round(s / dt)))])
                                  for s in (60, 200, 400, 600, tau[-1])},
    }
    rep["seconds"] = time.time() - t0
    return rep


# ---------------------------------------------------------------- main
def parse_args(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    ap.add_argument("outdir")
    ap.add_argument("--preset", choices=sorted(PRESETS), default="industrial")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--imu-rate", type=int, default=200, help="Hz")
    ap.add_argument("--gnss-rate", type=float, default=1.0, help="Hz (1, 4, 5, 10 ...)")
    ap.add_argument("--gnss-epoch-offset", type=float, default=0.0,
                    help="s added to the GNSS epoch grid (e.g. -0.001 gives x.999 stamps)")
    ap.add_argument("--gnss-sigma", type=float, nargs=3, default=[0.5, 0.5, 1.0],
                    metavar=("N", "E", "D"), help="GNSS white noise sigma, m (also the std "
                    "columns of gnss.pos)")
    ap.add_argument("--no-gnss-noise", action="store_true")
    ap.add_argument("--duration", type=float, default=660.0, help="s, total incl. static start")
    ap.add_argument("--static", type=float, default=60.0, help="s standing start (whole s)")
    ap.add_argument("--speed-scale", type=float, default=1.0,
                    help="scales every speed change: 1 a car (to 20 m/s), 0.08 a pedestrian, 0.04 a robot")
    ap.add_argument("--lever-arm", type=float, nargs=3, default=[0.3, -0.2, -1.0],
                    metavar=("F", "R", "D"), help="IMU -> antenna, body FRD, m")
    ap.add_argument("--week", type=int, default=2300)
    ap.add_argument("--start-sow", type=float, default=100000.0, help="t0, whole second")
    ap.add_argument("--lat0", type=float, default=45.0, help="deg")
    ap.add_argument("--lon0", type=float, default=7.5, help="deg")
    ap.add_argument("--h0", type=float, default=300.0, help="m ellipsoidal")
    ap.add_argument("--heading0", type=float, default=40.0, help="deg")
    ap.add_argument("--grade0", type=float, default=0.8, help="deg, parked on a slope")
    ap.add_argument("--bank0", type=float, default=-0.5, help="deg")
    ap.add_argument("--roll-gain", type=float, default=0.6,
                    help="deg of outward roll per m/s^2 of lateral acceleration")
    for k, v in PRESETS["industrial"].items():
        ap.add_argument("--" + k.replace("_", "-"), type=float, default=None,
                        help=f"override the preset (industrial {v}, consumer "
                             f"{PRESETS['consumer'][k]}); units: arw deg/sqrt(h), vrw "
                             "m/s/sqrt(h), gyro bias deg/h, accel bias mGal, scale ppm, "
                             "corr time h")
    ap.add_argument("--no-imu-errors", action="store_true", help="write the true increments")
    ap.add_argument("--vibration", type=float, default=0.0,
                    help="scale of a vehicle's vibration in the IMU data (1: ~0.8 m/s^2 and "
                         "~2 deg/s RMS per axis); the truth leaves out its <= 3 V * 0.01 deg, "
                         "3 V * 0.03 mm excursions")
    ap.add_argument("--array-offsets", type=float, nargs="+", default=[], metavar="TD",
                    help="s: one more IMU per value (imu1.txt ...) stamped TD late")
    ap.add_argument("--init-pos-std", type=float, nargs=3, default=[0.05, 0.05, 0.1])
    ap.add_argument("--init-vel-std", type=float, nargs=3, default=[0.02, 0.02, 0.02])
    ap.add_argument("--init-att-std", type=float, nargs=3, default=[0.05, 0.05, 0.2],
                    help="deg (KF-GINS yaml; the given initial state is exact)")
    ap.add_argument("--gl", type=int, nargs=2, default=[4, 2], metavar=("NODES", "SUBSTEPS"))
    ap.add_argument("--yaml-relative", action="store_true",
                    help="write ./imu.txt etc. in kf-gins.yaml (run KF-GINS from OUTDIR)")
    ap.add_argument("--self-check", action="store_true",
                    help="quadrature convergence + free-inertial strapdown of the noise-free "
                         "increments against the truth (adds ~10 s)")
    a = ap.parse_args(argv)
    if a.static < 1 or a.static != int(a.static) or a.start_sow != int(a.start_sow):
        ap.error("--static and --start-sow must be whole seconds (static >= 1)")
    return a


def main(argv=None):
    args = parse_args(argv)
    t_run = time.time()
    p = dict(PRESETS[args.preset])
    for k in p:
        v = getattr(args, k)
        if v is not None:
            p[k] = v
    os.makedirs(args.outdir, exist_ok=True)
    os.makedirs(os.path.join(args.outdir, "kf-gins-out"), exist_ok=True)
    rng = np.random.default_rng(args.seed)
    drive = Drive(args)
    rate = args.imu_rate
    dt = 1.0 / rate
    n_rows = int(round(args.duration * rate)) + 1  # rows at tau = 0, dt, ..., duration
    # grid tau_k = (k - 1) dt, k = 0..n_rows: the first interval (-dt, 0] feeds row 0
    track = Track(drive, args.lat0 * D2R, args.lon0 * D2R, args.h0, -dt, dt, n_rows,
                  gl=tuple(args.gl))
    dth, dvl = increments(drive, track, tuple(args.gl))
    tau = track.tg[1:]
    sow = args.start_sow + np.arange(n_rows) / rate
    mth, mvl, realised = add_sensor_errors(rng, dth, dvl, dt, p, not args.no_imu_errors)

    # truth at the IMU rows
    m = drive.motion(tau)
    eul = m["euler"] / D2R
    yaw = np.mod(eul[:, 2], 360.0)
    truth = np.column_stack([np.full(n_rows, args.week), sow, track.lat[1:] / D2R,
                             track.lon[1:] / D2R, track.h[1:], m["vn"], eul[:, 0], eul[:, 1],
                             yaw])

    # GNSS at the antenna
    k0 = math.floor(-args.gnss_epoch_offset * args.gnss_rate) + 1
    k1 = math.floor((args.duration - args.gnss_epoch_offset) * args.gnss_rate + 1e-9)
    ks = np.arange(k0, k1 + 1)
    tg = ks / args.gnss_rate + args.gnss_epoch_offset
    tg = tg[(tg > 0.0) & (tg <= args.duration)]
    glat, glon, gh = track.at(tg)
    mg = drive.motion(tg)
    lever_n = euler_to_cbn(mg["euler"]) @ np.array(args.lever_arm)
    r = geodetic_to_ecef(glat, glon, gh) + np.einsum("nij,nj->ni", c_n_to_e(glat, glon), lever_n)
    alat, alon, ah = ecef_to_geodetic(r)
    sig = np.array(args.gnss_sigma, dtype=float)
    noise = rng.standard_normal((len(tg), 3)) * sig
    if args.no_gnss_noise:
        noise[:] = 0.0
    rm, rn = radii(alat)
    alat_m = alat + noise[:, 0] / (rm + ah)
    alon_m = alon + noise[:, 1] / ((rn + ah) * np.cos(alat))
    ah_m = ah - noise[:, 2]
    gnss = np.column_stack([args.start_sow + tg, alat_m / D2R, alon_m / D2R, ah_m,
                            np.tile(sig, (len(tg), 1))])

    out = args.outdir
    np.savetxt(os.path.join(out, "imu.txt"), np.column_stack([sow, mth, mvl]),
               fmt=["%.9f"] + ["%.15e"] * 6)
    array = []
    for i, td in enumerate(args.array_offsets, start=1):
        # The same grid shifted TD earlier: row k integrates (tau_{k-1} - TD, tau_k - TD].
        tr = Track(drive, args.lat0 * D2R, args.lon0 * D2R, args.h0, -dt - td, dt, n_rows,
                   gl=tuple(args.gl))
        ath, avl = increments(drive, tr, tuple(args.gl))
        ath, avl, real_i = add_sensor_errors(np.random.default_rng([args.seed, i]), ath, avl, dt, p,
                                             not args.no_imu_errors)
        np.savetxt(os.path.join(out, f"imu{i}.txt"), np.column_stack([sow, ath, avl]),
                   fmt=["%.9f"] + ["%.15e"] * 6)
        array.append({"file": f"imu{i}.txt", "offset_s": td, "imu_error_realised": real_i})
    np.savetxt(os.path.join(out, "gnss.pos"), gnss,
               fmt=["%.6f", "%.12f", "%.12f", "%.6f", "%.4f", "%.4f", "%.4f"])
    np.savetxt(os.path.join(out, "truth.nav"), truth,
               fmt=["%d", "%.9f", "%.12f", "%.12f", "%.6f", "%.9f", "%.9f", "%.9f", "%.9f",
                    "%.9f", "%.9f"])

    # KF-GINS config
    def path(name):
        return "./" + name if args.yaml_relative else os.path.abspath(os.path.join(out, name))

    def vec(x, f="%.6f"):
        return "[ " + ", ".join(f % (v + 0.0) for v in x) + " ]"  # no "-0.0"

    bg0 = math.hypot(p["gyro_bias"], p["gyro_bias_instab"])
    ba0 = math.hypot(p["accel_bias"], p["accel_bias_instab"])
    yaml = f"""# KF-GINS configuration written by tests/python/independent_drive.py
# preset {args.preset}, seed {args.seed}; exact initial state (truth at t0) and the true
# IMU noise figures. Initial bias std = sqrt(turn-on^2 + instability^2).
imupath: "{path('imu.txt')}"
gnsspath: "{path('gnss.pos')}"
outputpath: "{path('kf-gins-out')}"
imudatalen: 7
imudatarate: {rate}
starttime: {args.start_sow:.3f}
endtime: -1
initpos: [ {truth[0, 2]:.12f}, {truth[0, 3]:.12f}, {truth[0, 4]:.6f} ]
initvel: {vec(truth[0, 5:8], "%.9f")}
initatt: {vec(truth[0, 8:11], "%.9f")}
initgyrbias: [ 0, 0, 0 ]    # [deg/h]
initaccbias: [ 0, 0, 0 ]    # [mGal]
initgyrscale: [ 0, 0, 0 ]   # [ppm]
initaccscale: [ 0, 0, 0 ]   # [ppm]
initposstd: {vec(args.init_pos_std)}
initvelstd: {vec(args.init_vel_std)}
initattstd: {vec(args.init_att_std)}
initbgstd: {vec([bg0] * 3)}    # [deg/h]
initbastd: {vec([ba0] * 3)}    # [mGal]
initsgstd: {vec([p['gyro_scale']] * 3)}    # [ppm]
initsastd: {vec([p['accel_scale']] * 3)}    # [ppm]
imunoise:
  arw: {vec([p['arw']] * 3)}          # [deg/sqrt(hr)]
  vrw: {vec([p['vrw']] * 3)}          # [m/s/sqrt(hr)]
  gbstd: {vec([p['gyro_bias_instab']] * 3)}        # [deg/hr]
  abstd: {vec([p['accel_bias_instab']] * 3)}     # [mGal]
  gsstd: {vec([p['gyro_scale']] * 3)}  # [ppm]
  asstd: {vec([p['accel_scale']] * 3)}  # [ppm]
  corrtime: {p['bias_corr_time']}                    # [hr]
antlever: {vec(args.lever_arm)}
"""
    with open(os.path.join(out, "kf-gins.yaml"), "w") as fh:
        fh.write(yaml)

    s = m["speed"]
    meta = {
        "generator": "tests/python/independent_drive.py",
        "argv": sys.argv[1:] if argv is None else list(argv),
        "args": vars(args),
        "imu_error_parameters": p,
        "imu_error_realised": realised,
        "array": array,
        "earth_model": {"ellipsoid": "WGS-84", "a": WGS84_A, "e2": WGS84_E2,
                        "omega_ie": OMEGA_IE,
                        "gravity": "GRS80 Somigliana series + height terms (Torge & Mueller "
                                   "2012 eq. 4.78a/4.79), as KF-GINS Earth::gravity"},
        "frames": "body FRD; navigation NED; Euler ZYX (roll, pitch, yaw), yaw in [0, 360)",
        "imu_increments": "sum over (t_{k-1}, t_k] of omega_ib^b and f^b; first row at t0 "
                          "is the interval ending at t0",
        "quadrature": {"gauss_legendre_nodes": args.gl[0], "substeps": args.gl[1]},
        "position_picard_changes_rad": track.iterations,
        "gnss": {"epochs": int(len(tg)), "first_sow": float(gnss[0, 0]),
                 "sigma_ned_m": sig.tolist(), "noise": not args.no_gnss_noise,
                 "point": "antenna (lever arm applied exactly via ECEF)"},
        "events": {q: [[ts, T, d if q == "speed" else d / D2R] for ts, T, d in ev]
                   for q, ev in drive.events.items()},
        "summary": {
            "rows": n_rows, "start_sow": args.start_sow, "end_sow": float(sow[-1]),
            "max_speed_m_s": float(s.max()),
            "distance_m": float(np.sum(s) * dt),
            "max_yaw_rate_deg_s": float(np.max(np.abs(m["w_nb"][:, 2])) / D2R),
            "max_roll_deg": float(np.max(np.abs(eul[:, 0]))),
            "height_range_m": [float(track.h.min()), float(track.h.max())],
            "max_horizontal_accel_m_s2": float(np.max(np.hypot(m["an"][:, 0], m["an"][:, 1]))),
        },
    }
    if args.self_check:
        meta["self_check"] = self_check(drive, track, dth, dvl, dt, args, tuple(args.gl))
    meta["runtime_s"] = time.time() - t_run
    with open(os.path.join(out, "meta.json"), "w") as fh:
        json.dump(meta, fh, indent=1)
    print(json.dumps({"outdir": out, "summary": meta["summary"],
                      "self_check": meta.get("self_check"),
                      "runtime_s": round(meta["runtime_s"], 2)}, indent=1))


if __name__ == "__main__":
    main()
