"""Opens a navsync recording as a ROS 2 bag with `rosbags` (PyPI, pure Python) and decodes
every message of every channel, with no navsync code: navsync's own types (`navsync_msgs/...`)
with the `ros2msg` definitions stored in the file, the standard ROS 2 types (`sensor_msgs`,
`nav_msgs`, ...) with rosbags' built-in ROS 2 Humble type store. Used by
tests/tests/recording/record_replay_python.rs.

Prints a JSON report on stdout: per-topic message counts and types, and the first and last
decoded message of each topic (floats as JSON numbers, NaN as null, arrays as lists).
Exits non-zero with the reason on any failure.
"""

import json
import math
import sys
from pathlib import Path

from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore


def fail(msg):
    print(f"check_rosbag: {msg}", file=sys.stderr)
    sys.exit(1)


def plain(v):
    """A decoded message as JSON values."""
    if hasattr(v, "__dataclass_fields__"):
        return {k: plain(getattr(v, k)) for k in v.__dataclass_fields__ if k != "__msgtype__"}
    if hasattr(v, "tolist"):
        return plain(v.tolist())
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    if isinstance(v, float):
        return None if math.isnan(v) else v
    return v


def main(path):
    builtin = get_typestore(Stores.ROS2_HUMBLE)
    report = {"topics": {}, "types": {}, "first": {}, "last": {}}
    with AnyReader([Path(path)]) as reader:
        if not reader.connections:
            fail("no channels")
        for c in reader.connections:
            report["types"][c.topic] = c.msgtype
        for c, _t, raw in reader.messages():
            if c.msgtype.startswith("navsync_msgs/"):
                msg = reader.deserialize(raw, c.msgtype)
            else:
                if c.msgtype not in builtin.types:
                    fail(f"{c.topic}: {c.msgtype} is not a standard ROS 2 Humble type")
                msg = builtin.deserialize_cdr(raw, c.msgtype)
            value = plain(msg)
            report["topics"][c.topic] = report["topics"].get(c.topic, 0) + 1
            report["first"].setdefault(c.topic, value)
            report["last"][c.topic] = value
    if not report["topics"]:
        fail("no messages")
    json.dump(report, sys.stdout, allow_nan=False)


if __name__ == "__main__":
    main(sys.argv[1])
