#!/usr/bin/env python3
"""The pose at any recent instant from Python: the estimator's history of states in shared
memory (Rust: ``navsync_shared::history``, docs/guide/history.md), read with the standard
library only (``mmap``, ``struct``).

    PYTHONPATH=shared/python python3 -c 'import navsync_history as h; print(h.History().state_at_host(T))'
    python3 shared/python/navsync_history.py HOST_NS [HOST_NS ...]   # one JSON line each

The file is ``/dev/shm/<prefix>nav_history`` (``$NAVSYNC_IPC_PREFIX``, default ``navsync_``):
a header of 16 little-endian 64-bit words, then two rings of records of 32 words (the
predicted states, then the fused ones: the delayed filter's state of each instant it has
passed), each under a sequence lock (word 0, odd while the estimator writes it). A query
answers from the fused states where they reach the instant, else from the predicted ones. A record is copied, then its sequence read
again: equal and even, the copy is consistent, else it is read again. The interpolation is the
Rust one: cubic Hermite on position in a local NED frame, linear velocity, slerp of the
attitude, linear σ. Errors: ``TooOld``/``TooNew`` (which side, with the oldest/newest time).
"""

import json
import math
import mmap
import os
import struct
import sys

MAGIC = int.from_bytes(b"NAVSHIST", "little")
LAYOUT_VERSION = 2
#: Header words holding the write index of the predicted and the fused ring.
WRITE_INDEX_WORDS = (9, 11)
PREDICTED, FUSED = 0, 1
TYPE_NAME = b"navsync.NavState.v2"
HEADER_WORDS = 16
RECORD_WORDS = 32
I64_MIN = -(2 ** 63)
WGS84_A = 6378137.0
WGS84_E2 = (1.0 / 298.257223563) * (2.0 - 1.0 / 298.257223563)
RECORD = struct.Struct("<QQqq" + "d" * 22 + "BBBB4x" + "d" * 5)


class HistoryError(Exception):
    pass


class TooOld(HistoryError):
    def __init__(self, requested, oldest):
        super().__init__(f"{requested} is older than the history: the oldest state is at {oldest}")
        self.oldest = oldest


class TooNew(HistoryError):
    def __init__(self, requested, newest):
        super().__init__(f"{requested} is newer than the history: the newest state is at {newest}")
        self.newest = newest


def path_for(prefix=None):
    prefix = prefix if prefix is not None else os.environ.get("NAVSYNC_IPC_PREFIX", "navsync_")
    return f"/dev/shm/{prefix}nav_history"


def _record(words):
    (seq, index, host, utc, lat, lon, h, vn, ve, vd, qw, qx, qy, qz, gx, gy, gz, sn, se, sd,
     svn, sve, svd, san, sae, sad, source, status, time_status, integrity, roll, pitch, yaw,
     _r1, _r2) = words
    return {
        "index": index, "host_ns": host, "utc_ns": utc, "lat_deg": lat, "lon_deg": lon,
        "height_m": h, "vel_ned_mps": [vn, ve, vd], "q_nb": [qw, qx, qy, qz],
        "rpy_rad": [roll, pitch, yaw], "pos_std_ned_m": [sn, se, sd],
        "vel_std_ned_mps": [svn, sve, svd], "att_std_rad": [san, sae, sad],
        "source": source, "status": status,
    }


class History:
    def __init__(self, prefix=None, path=None):
        self.path = path or path_for(prefix)
        fd = os.open(self.path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
        try:
            st = os.fstat(fd)
            if st.st_mode & 0o022:
                raise HistoryError(f"{self.path}: others may write it")
            if st.st_uid not in (os.geteuid(), 0) and st.st_gid not in (os.getegid(), *os.getgroups()):
                raise HistoryError(f"{self.path}: belongs to uid {st.st_uid}, gid {st.st_gid}: not this user's")
            self._id = (st.st_dev, st.st_ino)
            self.map = mmap.mmap(fd, st.st_size, mmap.MAP_SHARED, mmap.PROT_READ)
        finally:
            os.close(fd)
        w = struct.unpack_from("<16Q", self.map, 0)
        name = struct.pack("<4Q", *w[2:6]).rstrip(b"\0")
        if w[0] != MAGIC or w[1] != LAYOUT_VERSION or name != TYPE_NAME or w[7] != RECORD_WORDS:
            raise HistoryError(f"{self.path}: not a history of layout {LAYOUT_VERSION} of {TYPE_NAME}")
        self.capacity = w[6]

    def is_current(self):
        """False once the file at the path is another (a restarted estimator's): open it again."""
        try:
            st = os.stat(self.path, follow_symlinks=False)
        except FileNotFoundError:
            return False
        return (st.st_dev, st.st_ino) == self._id

    def write_index(self, ring=PREDICTED):
        return struct.unpack_from("<Q", self.map, WRITE_INDEX_WORDS[ring] * 8)[0]

    def record(self, index, ring=PREDICTED):
        off = (HEADER_WORDS + (ring * self.capacity + index % self.capacity) * RECORD_WORDS) * 8
        for _ in range(100000):
            s1 = struct.unpack_from("<Q", self.map, off)[0]
            if s1 & 1 == 0:
                raw = self.map[off:off + RECORD_WORDS * 8]
                if struct.unpack_from("<Q", self.map, off)[0] == s1:
                    r = _record(RECORD.unpack(raw))
                    return r if s1 != 0 and r["index"] == index else None
        raise HistoryError("the writer kept overwriting the record")

    def state_at_host(self, t):
        return self._at(t, "host_ns")

    def state_at(self, utc_ns):
        a, b = self._either(utc_ns, "utc_ns")
        f = (utc_ns - a["utc_ns"]) / (b["utc_ns"] - a["utc_ns"]) if b["utc_ns"] != a["utc_ns"] else 0.0
        return interpolate(a, b, a["host_ns"] + round((b["host_ns"] - a["host_ns"]) * f))

    def _at(self, t, key):
        a, b = self._either(t, key)
        return interpolate(a, b, t)

    def _either(self, t, key):
        """The records around t among the fused states, else among the predicted ones."""
        try:
            a, b = self._bracket(t, key, FUSED)
            if key == "host_ns" or (a["utc_ns"] != I64_MIN and b["utc_ns"] != I64_MIN):
                return a, b
        except (TooOld, TooNew):
            pass
        except HistoryError as e:
            if "fewer than two" not in str(e):
                raise
        return self._bracket(t, key, PREDICTED)

    def _bracket(self, t, key, ring):
        for _ in range(8):
            n = self.write_index(ring)
            if n < 2:
                raise HistoryError("the history holds fewer than two states yet")
            lo, hi = max(0, n - (self.capacity - 1)), n - 1
            b, a = self.record(hi, ring), self.record(lo, ring)
            if a is None or b is None:
                continue
            if t > b[key]:
                raise TooNew(t, b[key])
            if t < a[key]:
                raise TooOld(t, a[key])
            lapped = False
            while hi - lo > 1:
                mid = (lo + hi) // 2
                m = self.record(mid, ring)
                if m is None:
                    lapped = True
                    break
                if m[key] <= t:
                    lo, a = mid, m
                else:
                    hi, b = mid, m
            if not lapped:
                return a, b
        raise HistoryError("the writer overwrote the records faster than they could be read")


def _hermite(p0, m0, p1, m1, t):
    t2, t3 = t * t, t * t * t
    return (2 * t3 - 3 * t2 + 1) * p0 + (t3 - 2 * t2 + t) * m0 + (-2 * t3 + 3 * t2) * p1 + (t3 - t2) * m1


def _slerp(a, b, t):
    dot = sum(x * y for x, y in zip(a, b))
    if dot < 0:
        b, dot = [-x for x in b], -dot
    if dot > 0.9995:
        wa, wb = 1 - t, t
    else:
        th = math.acos(min(1.0, dot))
        wa, wb = math.sin((1 - t) * th) / math.sin(th), math.sin(t * th) / math.sin(th)
    q = [wa * x + wb * y for x, y in zip(a, b)]
    n = math.sqrt(sum(x * x for x in q))
    return [x / n for x in q] if n > 0 else a


def interpolate(a, b, t):
    h = (b["host_ns"] - a["host_ns"]) * 1e-9
    tau = (t - a["host_ns"]) * 1e-9 / h if h > 0 else 0.0
    lat = math.radians(a["lat_deg"])
    w = 1 - WGS84_E2 * math.sin(lat) ** 2
    rn, rm = WGS84_A / math.sqrt(w), WGS84_A * (1 - WGS84_E2) / (w * math.sqrt(w))
    kn, ke = rm + a["height_m"], (rn + a["height_m"]) * math.cos(lat)
    d1 = [math.radians(b["lat_deg"] - a["lat_deg"]) * kn, math.radians(b["lon_deg"] - a["lon_deg"]) * ke,
          -(b["height_m"] - a["height_m"])]
    p = [_hermite(0.0, a["vel_ned_mps"][i] * h, d1[i], b["vel_ned_mps"][i] * h, tau) for i in range(3)]
    lerp = lambda x, y: [u + (v - u) * tau for u, v in zip(x, y)]  # noqa: E731
    qw, qx, qy, qz = _slerp(a["q_nb"], b["q_nb"], tau)
    return {
        "host_ns": t,
        "lat_deg": a["lat_deg"] + math.degrees(p[0] / kn),
        "lon_deg": a["lon_deg"] + math.degrees(p[1] / ke),
        "height_m": a["height_m"] - p[2],
        "vel_ned_mps": lerp(a["vel_ned_mps"], b["vel_ned_mps"]),
        "q_nb": [qw, qx, qy, qz],
        "rpy_rad": [math.atan2(2 * (qw * qx + qy * qz), 1 - 2 * (qx * qx + qy * qy)),
                    math.asin(max(-1.0, min(1.0, 2 * (qw * qy - qz * qx)))),
                    math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))],
        "pos_std_ned_m": lerp(a["pos_std_ned_m"], b["pos_std_ned_m"]),
        "vel_std_ned_mps": lerp(a["vel_std_ned_mps"], b["vel_std_ned_mps"]),
        "att_std_rad": lerp(a["att_std_rad"], b["att_std_rad"]),
        "sources": [a["source"], b["source"]],
        "fraction": tau,
    }


def main(argv):
    h = History()
    for t in argv:
        print(json.dumps(h.state_at_host(int(t))))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
