"""CDR decoding of navsync's samples into the ctypes structures of navsync_types.py: what
arrives through Zenoh (`navsync bridge zenoh`) and what the recordings hold.

The rules are those of navsync's Rust codec (shared/src/cdr.rs): a 4-byte encapsulation
header 00 01 00 00 (little-endian plain CDR), then the fields in declaration order, each
primitive aligned to its size counted from the byte after the header, a string as a uint32
length including the NUL, the bytes and the NUL, fixed-size arrays as their elements, nested
structures inline, `reserved` fields absent.
"""

import ctypes
import struct

_PRIMITIVE = {
    ctypes.c_int64: "q",
    ctypes.c_uint64: "Q",
    ctypes.c_int32: "i",
    ctypes.c_uint32: "I",
    ctypes.c_int16: "h",
    ctypes.c_uint16: "H",
    ctypes.c_uint8: "B",
    ctypes.c_double: "d",
    ctypes.c_float: "f",
}


class CdrError(ValueError):
    """A payload that is not a CDR message of the expected type."""


class _Reader:
    def __init__(self, data):
        if len(data) < 4 or data[0:2] != b"\x00\x01":
            raise CdrError("not little-endian plain CDR (encapsulation 0001)")
        self.body = memoryview(data)[4:]
        self.pos = 0

    def take(self, n, align):
        start = (self.pos + align - 1) // align * align
        end = start + n
        if end > len(self.body):
            raise CdrError(f"the message ends at byte {len(self.body) + 4}, {n} more needed")
        self.pos = end
        return self.body[start:end]


def _read_into(obj, cls, r):
    for name, t in cls._fields_:
        if name == "reserved":
            continue
        setattr(obj, name, _read_value(t, r, getattr(obj, name)))


def _read_value(t, r, current):
    if t in _PRIMITIVE:
        fmt = _PRIMITIVE[t]
        size = struct.calcsize(fmt)
        return struct.unpack("<" + fmt, r.take(size, size))[0]
    if isinstance(t, type) and issubclass(t, ctypes.Structure):
        _read_into(current, t, r)
        return current
    if isinstance(t, type) and issubclass(t, ctypes.Array):
        if t._type_ is ctypes.c_char:
            (n,) = struct.unpack("<I", r.take(4, 4))
            if n == 0 or n - 1 > t._length_:
                raise CdrError(f"a string of {n} bytes where at most {t._length_} fit")
            return bytes(r.take(n, 1))[:-1]
        for i in range(t._length_):
            v = _read_value(t._type_, r, current[i])
            if not isinstance(v, ctypes.Structure):
                current[i] = v
        return current
    raise CdrError(f"no CDR rule for {t}")


def decode(cls, data):
    """A `cls` (a structure of navsync_types.py) from a CDR message."""
    obj = cls()
    _read_into(obj, cls, _Reader(bytes(data)))
    return obj


def layout_of(attachment):
    """The layout version and sequence number of a bridge attachment (bytes)."""
    a = bytes(attachment)
    nul = a.index(0)
    (seq,) = struct.unpack("<Q", a[nul + 1 : nul + 9])
    return a[:nul].decode(), seq
