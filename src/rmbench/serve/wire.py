"""The policy server's wire format: msgpack with numpy arrays, the shape openpi uses.

An array travels as a map ``{"__ndarray__": True, "data": bytes, "dtype": str, "shape": [...]}``
and a numpy scalar as ``{"__npgeneric__": True, "data": bytes, "dtype": str}``. Nothing else is
decoded: no pickle, no object dtypes.
"""

from __future__ import annotations

from typing import Any

import msgpack
import numpy as np

PROTOCOL = 1
MAX_MESSAGE_BYTES = 64 * 2**20  # a few uncompressed 640x480 frames with room to spare


class WireError(ValueError):
    pass


def _encode(obj):
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind not in "biufc":
            raise WireError(f"arrays of dtype {obj.dtype} cannot be sent")
        return {b"__ndarray__": True, b"data": np.ascontiguousarray(obj).tobytes(),
                b"dtype": obj.dtype.str, b"shape": list(obj.shape)}
    if isinstance(obj, np.generic):
        return {b"__npgeneric__": True, b"data": obj.tobytes(), b"dtype": obj.dtype.str}
    return obj


def _decode(obj):
    if b"__ndarray__" in obj or b"__npgeneric__" in obj:
        try:
            dtype = np.dtype(obj[b"dtype"].decode() if isinstance(obj[b"dtype"], bytes)
                             else obj[b"dtype"])
            if dtype.kind not in "biufc":
                raise WireError(f"dtype {dtype} is not accepted")
            if b"__ndarray__" in obj:
                return np.frombuffer(obj[b"data"], dtype=dtype).reshape(obj[b"shape"])
            return np.frombuffer(obj[b"data"], dtype=dtype)[0]
        except (KeyError, TypeError, ValueError) as err:
            raise WireError(f"malformed array: {err}") from None
    return obj


def pack(obj: Any) -> bytes:
    return msgpack.packb(obj, default=_encode, use_bin_type=True)


def unpack(data: bytes) -> Any:
    if not isinstance(data, bytes):
        raise WireError("expected a binary msgpack message, got text")
    if len(data) > MAX_MESSAGE_BYTES:
        raise WireError(f"message of {len(data)} bytes exceeds {MAX_MESSAGE_BYTES}")
    try:
        return msgpack.unpackb(data, object_hook=_decode, raw=False, strict_map_key=False)
    except WireError:
        raise
    except Exception as err:  # msgpack raises several types for bad input
        raise WireError(f"not a msgpack message: {err}") from None
