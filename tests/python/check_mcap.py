"""Reads an MCAP file with the `mcap` package from PyPI (no navsync code): used by
tests/tests/recording/record_replay_python.rs.

Checks, with the library's CRC validation on (zstd and lz4 chunks decompressed by the
package):
  * the indexed reader (summary, chunk indexes) yields every message;
  * a linear StreamReader pass (data-section and chunk CRCs) yields the same messages and
    ends in a footer whose statistics match the counts;
  * a `cdr` channel has a `ros2msg` schema and the ROS 2 channel metadata
    (`offered_qos_profiles`), and every message starts with the CDR encapsulation header
    (its content is decoded by check_rosbag.py with rosbags);
  * a `json` channel (older recordings, `--encoding json`): every message is JSON and conforms
    to its channel's schema (encoding `jsonschema`): types, required properties, no
    undeclared properties, array lengths, string lengths.
Prints a JSON report on stdout: per-topic counts, schema names and encodings, the profile, the
chunk compressions, and the first and last decoded message of each JSON topic. Exits non-zero
with the reason on any failure.
"""

import json
import sys

from mcap.reader import make_reader
from mcap.records import Channel, Footer, Message, Schema, Statistics
from mcap.stream_reader import StreamReader


def fail(msg):
    print(f"check_mcap: {msg}", file=sys.stderr)
    sys.exit(1)


def validate(value, schema, path):
    """A small JSON Schema (draft 2020-12) validator for the keywords navsync's schemas use."""
    types = schema.get("type")
    if types is not None:
        allowed = types if isinstance(types, list) else [types]
        ok = False
        for t in allowed:
            if t == "object" and isinstance(value, dict):
                ok = True
            elif t == "array" and isinstance(value, list):
                ok = True
            elif t == "integer" and isinstance(value, int) and not isinstance(value, bool):
                ok = True
            elif t == "number" and isinstance(value, (int, float)) and not isinstance(value, bool):
                ok = True
            elif t == "null" and value is None:
                ok = True
            elif t == "string" and isinstance(value, str):
                ok = True
        if not ok:
            fail(f"{path}: {value!r} is not of type {types}")
    if isinstance(value, dict):
        props = schema.get("properties", {})
        for key in schema.get("required", []):
            if key not in value:
                fail(f"{path}: required property {key!r} missing")
        for key, v in value.items():
            if key not in props:
                fail(f"{path}: property {key!r} is not in the schema")
            validate(v, props[key], f"{path}.{key}")
    if isinstance(value, list):
        if "minItems" in schema and len(value) < schema["minItems"]:
            fail(f"{path}: {len(value)} items < minItems {schema['minItems']}")
        if "maxItems" in schema and len(value) > schema["maxItems"]:
            fail(f"{path}: {len(value)} items > maxItems {schema['maxItems']}")
        items = schema.get("items")
        if items is not None:
            for i, v in enumerate(value):
                validate(v, items, f"{path}[{i}]")
    if isinstance(value, str) and "maxLength" in schema and len(value.encode()) > schema["maxLength"]:
        fail(f"{path}: string longer than {schema['maxLength']}")


def main(path):
    report = {"topics": {}, "schemas": {}, "encodings": {}, "first": {}, "last": {}}
    schemas = {}
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        if summary is None:
            fail("no summary section")
        if summary.statistics is None:
            fail("no statistics in the summary")
        if not summary.chunk_indexes:
            fail("no chunk indexes in the summary")
        report["profile"] = reader.get_header().profile
        report["compression"] = sorted({ci.compression for ci in summary.chunk_indexes})
        for sid, s in summary.schemas.items():
            if s.encoding == "jsonschema":
                schemas[sid] = json.loads(s.data)
                report["schemas"][s.name] = schemas[sid].get("title")
            elif s.encoding == "ros2msg":
                text = s.data.decode()
                if not text.strip():
                    fail(f"schema {s.name}: empty definition")
                report["schemas"][s.name] = s.name
            else:
                fail(f"schema {s.name}: encoding {s.encoding!r}")
        for c in summary.channels.values():
            report["encodings"][c.topic] = c.message_encoding
            if c.message_encoding == "cdr" and "offered_qos_profiles" not in c.metadata:
                fail(f"{c.topic}: a cdr channel without offered_qos_profiles")
        indexed = 0
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema is None:
                fail(f"{channel.topic}: no schema")
            t = channel.topic
            if channel.message_encoding == "json":
                if schema.encoding != "jsonschema":
                    fail(f"{t}: json messages with a {schema.encoding} schema")
                try:
                    value = json.loads(message.data)
                except ValueError as e:
                    fail(f"{t}: message {message.sequence} is not JSON: {e}")
                validate(value, schemas[schema.id], t)
                report["first"].setdefault(t, value)
                report["last"][t] = value
            elif channel.message_encoding == "cdr":
                if schema.encoding != "ros2msg":
                    fail(f"{t}: cdr messages with a {schema.encoding} schema")
                if message.data[:4] != bytes([0, 1, 0, 0]):
                    fail(f"{t}: message {message.sequence} does not start with the CDR_LE header")
            else:
                fail(f"{t}: message encoding {channel.message_encoding!r}")
            report["topics"][t] = report["topics"].get(t, 0) + 1
            indexed += 1
        stats = summary.statistics
        if stats.message_count != indexed:
            fail(f"statistics say {stats.message_count} messages, the indexed reader read {indexed}")
        counts = {summary.channels[c].topic: n for c, n in stats.channel_message_counts.items() if n}
        if counts != report["topics"]:
            fail(f"per-channel statistics {counts} != messages read {report['topics']}")
        if len(summary.chunk_indexes) != stats.chunk_count:
            fail(f"{len(summary.chunk_indexes)} chunk indexes, statistics say {stats.chunk_count}")

    # A linear pass with every CRC checked (chunks and the data section).
    linear = 0
    footer = None
    with open(path, "rb") as f:
        for record in StreamReader(f, validate_crcs=True).records:
            if isinstance(record, Message):
                linear += 1
            elif isinstance(record, Footer):
                footer = record
    if footer is None or footer.summary_start == 0:
        fail("the linear pass found no footer with a summary")
    if linear != indexed:
        fail(f"linear pass read {linear} messages, the indexed reader {indexed}")
    report["messages"] = indexed
    report["chunks"] = stats.chunk_count
    json.dump(report, sys.stdout)


if __name__ == "__main__":
    main(sys.argv[1])
