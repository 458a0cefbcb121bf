"""Writes a ROS 2 bag (MCAP storage) with `rosbags` (PyPI): every navsync message of IN.mcap,
deserialised and serialised again by rosbags' own CDR code with the `navsync_msgs`
definitions found in IN's schemas; the standard ROS 2 messages are left out. Used by
tests/tests/recording/record_replay_python.rs to show that navsync reads bags other tools wrote.

usage: write_rosbag.py IN.mcap OUT_DIR   (OUT_DIR must not exist; rosbags creates it with
metadata.yaml and OUT_DIR/OUT_DIR.mcap). Prints the number of messages written.
"""

import sys
from pathlib import Path

from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer


def main(src, dst):
    n = 0
    with AnyReader([Path(src)]) as reader:
        store = reader.typestore
        conns = [c for c in reader.connections if c.msgtype.startswith("navsync_msgs/")]
        if not conns:
            print("write_rosbag: no navsync_msgs channels", file=sys.stderr)
            sys.exit(1)
        with Writer(Path(dst), version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            out = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=store) for c in conns}
            for c, t, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, c.msgtype)
                writer.write(out[c.id], t, store.serialize_cdr(msg, c.msgtype))
                n += 1
    print(n)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
