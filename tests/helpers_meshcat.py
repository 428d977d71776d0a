"""Reading Drake's Meshcat scene in tests: a minimal msgpack reader of its packed messages,
independent of the code under test, and the pose and properties of a path."""

import struct

import numpy as np


# --- a minimal msgpack reader: Drake's packed messages, independent of the code under test ----


def unpack(data: bytes):
    value, end = _unpack(data, 0)
    assert end == len(data)
    return value


def _unpack(b: bytes, i: int):
    c = b[i]
    if c <= 0x7F:
        return c, i + 1
    if c >= 0xE0:
        return c - 0x100, i + 1
    if 0x80 <= c <= 0x8F:
        return _map(b, i + 1, c & 0x0F)
    if 0x90 <= c <= 0x9F:
        return _array(b, i + 1, c & 0x0F)
    if 0xA0 <= c <= 0xBF:
        n = c & 0x1F
        return b[i + 1:i + 1 + n].decode(), i + 1 + n
    fixed = {0xC0: None, 0xC2: False, 0xC3: True}
    if c in fixed:
        return fixed[c], i + 1
    numbers = {0xCA: ">f", 0xCB: ">d", 0xCC: ">B", 0xCD: ">H", 0xCE: ">I", 0xCF: ">Q",
               0xD0: ">b", 0xD1: ">h", 0xD2: ">i", 0xD3: ">q"}
    if c in numbers:
        size = struct.calcsize(numbers[c])
        return struct.unpack(numbers[c], b[i + 1:i + 1 + size])[0], i + 1 + size
    lengths = {0xD9: (">B", "str"), 0xDA: (">H", "str"), 0xDB: (">I", "str"),
               0xC4: (">B", "bin"), 0xC5: (">H", "bin"), 0xC6: (">I", "bin"),
               0xDC: (">H", "array"), 0xDD: (">I", "array"), 0xDE: (">H", "map"),
               0xDF: (">I", "map")}
    if c in lengths:
        fmt, kind = lengths[c]
        size = struct.calcsize(fmt)
        n = struct.unpack(fmt, b[i + 1:i + 1 + size])[0]
        j = i + 1 + size
        if kind == "str":
            return b[j:j + n].decode(), j + n
        if kind == "bin":
            return b[j:j + n], j + n
        return (_array if kind == "array" else _map)(b, j, n)
    # Extensions: meshcat's typed arrays, little-endian (type 23 = Float32Array, ...).
    ext = {0xD4: 1, 0xD5: 2, 0xD6: 4, 0xD7: 8, 0xD8: 16, 0xC7: ">B", 0xC8: ">H", 0xC9: ">I"}
    if c in ext:
        j = i + 1
        if isinstance(ext[c], str):
            size = struct.calcsize(ext[c])
            n = struct.unpack(ext[c], b[j:j + size])[0]
            j += size
        else:
            n = ext[c]
        code, raw = b[j], b[j + 1:j + 1 + n]
        dtypes = {18: "<u1", 21: "<i4", 22: "<u4", 23: "<f4"}
        if code not in dtypes:
            raise ValueError(f"msgpack extension type {code} not supported by this reader")
        return np.frombuffer(raw, dtype=dtypes[code]).tolist(), j + 1 + n
    raise ValueError(f"msgpack type byte {c:#x} at {i} not supported by this reader")


def _array(b, i, n):
    out = []
    for _ in range(n):
        v, i = _unpack(b, i)
        out.append(v)
    return out, i


def _map(b, i, n):
    out = {}
    for _ in range(n):
        k, i = _unpack(b, i)
        v, i = _unpack(b, i)
        out[k] = v
    return out, i


# --- helpers reading the scene ------------------------------------------------------------------


def transform(meshcat, path) -> np.ndarray:
    """4x4 pose of path in its parent; three.js packs it column-major."""
    return np.array(unpack(meshcat._GetPackedTransform(path))["matrix"]).reshape(4, 4).T


def prop(meshcat, path, name):
    return unpack(meshcat._GetPackedProperty(path, name))["value"]
