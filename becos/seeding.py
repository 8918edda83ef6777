"""Random streams derived from stable keys, so each draw depends only on what it is for.

``rng_for(seed, "pair", pair_id, "cameras")`` gives the same generator on any machine, in any job
order, whichever other pairs exist: the keys are hashed (SHA-256) into a numpy ``SeedSequence``.
"""

from __future__ import annotations

import hashlib

import numpy as np


def stable_hash(*keys: object, bits: int = 64) -> int:
    """A non-negative integer of ``bits`` bits from the keys' ``str`` forms (stable across runs and machines)."""
    text = "\x1f".join(str(k) for k in keys).encode()
    digest = hashlib.sha256(text).digest()
    return int.from_bytes(digest[: (bits + 7) // 8], "big") >> ((8 - bits % 8) % 8)


def rng_for(*keys: object) -> np.random.Generator:
    """A numpy Generator seeded from the keys (e.g. global seed, pair id, purpose)."""
    words = hashlib.sha256("\x1f".join(str(k) for k in keys).encode()).digest()
    return np.random.default_rng(np.random.SeedSequence(list(np.frombuffer(words, dtype=np.uint32))))
