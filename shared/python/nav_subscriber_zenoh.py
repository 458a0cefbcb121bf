"""Subscribes to navsync's fused navigation state through Zenoh, from a host without navsync:
the official `eclipse-zenoh` package (PyPI, the version of the zenoh crate navsync uses:
`pip install eclipse-zenoh==1.2.1`) and the generated ctypes layouts with their CDR decoder.

    PYTHONPATH=shared/python python3 shared/python/nav_subscriber_zenoh.py \\
        --connect tcp/192.168.1.10:7447 [--instance car1] [--count 10] [--json]

A sample whose layout version differs from navsync_types.py's is refused with both named.
Times: `utc_ns` is UTC; `host_ns` is the source host's CLOCK_MONOTONIC (meaningless here).
"""

import argparse
import ctypes
import json
import math
import sys

import zenoh

from navsync_cdr import decode, layout_of
from navsync_types import NavState


def plain(v):
    """A decoded value as JSON values (NaN as null, strings as text)."""
    if isinstance(v, ctypes.Structure):
        return {n: plain(getattr(v, n)) for n, _ in type(v)._fields_ if n != "reserved"}
    if isinstance(v, ctypes.Array):
        return [plain(x) for x in v]
    if isinstance(v, bytes):
        return v.decode(errors="replace")
    if isinstance(v, float) and math.isnan(v):
        return None
    return v


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--connect", required=True, help="Zenoh endpoint, e.g. tcp/192.168.1.10:7447")
    p.add_argument("--instance", default="*", help="the navsync instance (default: any)")
    p.add_argument("--count", type=int, default=0, help="stop after N states (default: never)")
    p.add_argument("--json", action="store_true", help="one JSON object per state")
    a = p.parse_args()

    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([a.connect]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    ours = NavState.type_name()
    n = 0
    with zenoh.open(conf) as session:
        sub = session.declare_subscriber(f"navsync/{a.instance}/nav/state")
        for sample in sub:
            key = str(sample.key_expr)
            if sample.attachment is None:
                print(f"{key}: no navsync attachment", file=sys.stderr)
                continue
            layout, seq = layout_of(sample.attachment.to_bytes())
            if layout != ours:
                print(f"{key}: the sender's layout is {layout}, this subscriber reads {ours}", file=sys.stderr)
                continue
            s = decode(NavState, sample.payload.to_bytes())
            instance = key.split("/")[1]
            if a.json:
                print(json.dumps({"instance": instance, "seq": seq, "sample": plain(s)}), flush=True)
            else:
                lat = "n/a" if math.isnan(s.lat_deg) else f"{s.lat_deg:.7f}"
                lon = "n/a" if math.isnan(s.lon_deg) else f"{s.lon_deg:.7f}"
                print(f"{instance} #{s.seq} utc_ns={s.utc_ns} lat={lat} lon={lon} h={s.height_m:.2f} m", flush=True)
            n += 1
            if a.count and n >= a.count:
                break
    return 0


if __name__ == "__main__":
    sys.exit(main())
