"""The policy server's wire format: msgpack with numpy arrays, the shape openpi uses.

An array travels as a map ``{"__ndarray__": True, "data": bytes, "dtype": str, "shape": [...]}``
and a numpy scalar as ``{"__npgeneric__": True, "data": bytes, "dtype": str}``. Nothing else is
decoded: no pickle, no object dtypes, no msgpack extension types.

A message from an untrusted peer is measured before it is decoded (``scan``): its size, how
many values it holds and how deeply they nest. Decoding builds a Python object per value and
calls a hook per map, so a few megabytes of empty maps would cost hundreds of megabytes and
a second of the interpreter; an observation holds a few dozen values, so ``Limits.items``
refuses such a message after reading a few thousand headers, whatever its size.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np

PROTOCOL = 2
MAX_MESSAGE_BYTES = 64 * 2**20  # what a client accepts from a server: a few frames of chunks
# the numeric dtypes an array may have on the wire (native and both byte orders)
DTYPES = frozenset(np.dtype(f"{order}{kind}{size}").str for order in "<>" for kind, size in
                   [("f", 4), ("f", 8), ("f", 2), ("i", 1), ("i", 2), ("i", 4), ("i", 8),
                    ("u", 1), ("u", 2), ("u", 4), ("u", 8)]) | {"|b1", "|u1", "|i1"}
MAX_NDIM = 4


class WireError(ValueError):
    pass


@dataclass(frozen=True)
class Limits:
    """What one message may hold: ``bytes`` in all, ``items`` values (maps, arrays, strings,
    numbers...; an array of numbers counts each), nested ``depth`` containers deep, strings of
    ``text`` bytes."""

    bytes: int = MAX_MESSAGE_BYTES
    items: int = 4096
    depth: int = 8
    text: int = 4096


TRUSTED = Limits(items=2**31, depth=512, text=MAX_MESSAGE_BYTES)  # a message this process made
# What a client reads from a server, which may be any program at the address it was given: a
# greeting and replies of action chunks, statuses and an error text hold far fewer values,
# and a reply of millions of empty maps must not cost gigabytes to refuse.
REPLY = Limits(items=2**16, depth=32, text=2**20)


def _encode(obj):
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind not in "biufc":
            raise WireError(f"arrays of dtype {obj.dtype} cannot be sent")
        return {b"__ndarray__": True, b"data": np.ascontiguousarray(obj).tobytes(),
                b"dtype": obj.dtype.str, b"shape": list(obj.shape)}
    if isinstance(obj, np.generic):
        return {b"__npgeneric__": True, b"data": obj.tobytes(), b"dtype": obj.dtype.str}
    return obj


def _array(obj: dict) -> np.ndarray | np.generic:
    dtype, data = obj.get(b"dtype"), obj.get(b"data")
    if isinstance(dtype, bytes):
        dtype = dtype.decode("ascii", "replace")
    if dtype not in DTYPES:
        raise WireError(f"array dtype {dtype!r} is not accepted (numeric dtypes only)")
    if not isinstance(data, bytes):
        raise WireError("array data must be bytes")
    if b"__npgeneric__" in obj:
        if len(data) != np.dtype(dtype).itemsize:
            raise WireError(f"scalar of dtype {dtype} needs {np.dtype(dtype).itemsize} bytes, "
                            f"got {len(data)}")
        return np.frombuffer(data, dtype=dtype)[0]
    shape = obj.get(b"shape")
    if (not isinstance(shape, list) or len(shape) > MAX_NDIM
            or not all(type(n) is int and 0 <= n < 2**31 for n in shape)):
        raise WireError(f"array shape must be up to {MAX_NDIM} sizes >= 0, got {shape!r:.80}")
    if int(np.prod(shape, dtype=object)) * np.dtype(dtype).itemsize != len(data):
        raise WireError(f"array of shape {tuple(shape)} and dtype {dtype} needs "
                        f"{int(np.prod(shape, dtype=object)) * np.dtype(dtype).itemsize} bytes, "
                        f"got {len(data)}")
    return np.frombuffer(data, dtype=dtype).reshape(shape).copy()  # writable, like an env's


def _decode(obj):
    if b"__ndarray__" in obj or b"__npgeneric__" in obj:
        return _array(obj)
    return obj


def pack(obj: Any) -> bytes:
    return msgpack.packb(obj, default=_encode, use_bin_type=True)


def unpack(data: bytes, limits: Limits = TRUSTED) -> Any:
    """The message, or a one-line WireError: text, too large, too many values, too deep, not
    msgpack, or an array that is not a numeric array of the size its shape claims."""
    if not isinstance(data, bytes):
        raise WireError("expected a binary msgpack message, got text")
    if len(data) > limits.bytes:
        raise WireError(f"message of {len(data)} bytes exceeds {limits.bytes}")
    if limits is not TRUSTED:
        scan(data, limits)
    try:
        return msgpack.unpackb(data, object_hook=_decode, raw=False, strict_map_key=False,
                               max_str_len=limits.text, max_bin_len=limits.bytes,
                               max_array_len=limits.items, max_map_len=limits.items,
                               max_ext_len=0)
    except WireError:
        raise
    except Exception as err:  # msgpack raises several types for bad input
        raise WireError(f"not a msgpack message: {type(err).__name__}: {err}"[:200]) from None


# msgpack's headers by first byte: (bytes of a length field or fixed payload, kind)
_FIXED = {0xc0: 0, 0xc2: 0, 0xc3: 0, 0xca: 4, 0xcb: 8, 0xcc: 1, 0xcd: 2, 0xce: 4, 0xcf: 8,
          0xd0: 1, 0xd1: 2, 0xd2: 4, 0xd3: 8}
_SIZED = {0xc4: (1, "bin"), 0xc5: (2, "bin"), 0xc6: (4, "bin"), 0xd9: (1, "str"),
          0xda: (2, "str"), 0xdb: (4, "str"), 0xdc: (2, "array"), 0xdd: (4, "array"),
          0xde: (2, "map"), 0xdf: (4, "map")}
_LENGTH = {1: struct.Struct(">B"), 2: struct.Struct(">H"), 4: struct.Struct(">I")}


def scan(data: bytes, limits: Limits) -> None:
    """Walks the message's msgpack headers without building anything (bin and str payloads
    are skipped by their length): a WireError if it holds more than ``limits.items`` values,
    nests deeper than ``limits.depth``, has a string longer than ``limits.text``, uses an
    extension type, or is truncated or followed by more bytes. The walk stops at the first
    excess, so its cost is bounded by the limits, not by the message."""
    pos, end, items = 0, len(data), 0
    pending = [1]  # values still to read at each open nesting level
    try:
        while pending:
            if pending[-1] == 0:
                pending.pop()
                continue
            pending[-1] -= 1
            items += 1
            if items > limits.items:
                raise WireError(f"message holds more than {limits.items} values")
            b = data[pos]
            pos += 1
            if b <= 0x7f or b >= 0xe0:
                continue
            if 0x80 <= b <= 0x9f:  # fixmap, fixarray
                count = (b & 0x0f) * (2 if b <= 0x8f else 1)
                kind = "map"
            elif 0xa0 <= b <= 0xbf:  # fixstr
                length, kind = b & 0x1f, "str"
            elif b in _FIXED:
                pos += _FIXED[b]
                continue
            elif b in _SIZED:
                width, kind = _SIZED[b]
                if pos + width > end:
                    raise IndexError
                (length,) = _LENGTH[width].unpack_from(data, pos)
                pos += width
                if kind in ("array", "map"):
                    count = length * (2 if kind == "map" else 1)
            else:
                raise WireError(f"msgpack type 0x{b:02x} is not accepted (extension types "
                                f"or the reserved byte)")
            if kind in ("str", "bin"):
                if kind == "str" and length > limits.text:
                    raise WireError(f"a string of {length} bytes exceeds {limits.text}")
                pos += length
                if pos > end:
                    raise IndexError
                continue
            if len(pending) > limits.depth:
                raise WireError(f"message nests deeper than {limits.depth} levels")
            if count > limits.items - items:
                raise WireError(f"message holds more than {limits.items} values")
            pending.append(count)
    except IndexError:
        raise WireError("truncated msgpack message") from None
    if pos > end:
        raise WireError("truncated msgpack message")
    if pos != end:
        raise WireError(f"{end - pos} bytes follow the msgpack message")
