"""SHA-256 digests (16 hex digits) of arrays and of files that becos records beside what it writes, so
that a file edited or replaced afterwards is noticed."""

from __future__ import annotations

import hashlib
import json

import numpy as np


def content_digest(arrays: dict[str, np.ndarray], meta: dict) -> str:
    """SHA-256 (hex, 16 digits) of a record's arrays (name, dtype, shape, bytes; sorted by name) and of
    its meta without ``content_digest``."""
    h = hashlib.sha256(json.dumps({k: v for k, v in meta.items() if k != "content_digest"}, sort_keys=True).encode())
    for key in sorted(arrays):
        a = np.ascontiguousarray(arrays[key])
        h.update(f"|{key}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def bytes_digest(data: bytes) -> str:
    """SHA-256 (16 hex digits) of a file's bytes, as becos records the files a result was made from."""
    return hashlib.sha256(data).hexdigest()[:16]
