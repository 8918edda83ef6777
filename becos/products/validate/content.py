"""``checksum``: a store's array content read back against the sha256 recorded when it was written
(``becos_store.sha256``), and which chunk files are absent when it differs."""

from __future__ import annotations

import numpy as np

from becos.products.validate.report import MAX_EXAMPLES


def digests_to_check(bench):
    """A :class:`becos.products.store.ContentDigests` for the store's nodes, or None if it recorded none."""
    from becos.products.store import ContentDigests

    if not bench.content_digests:
        return None
    dtypes = {f"arrays/{key}": bench.array(key).dtype for key in bench.layout}
    dtypes.update({f"offsets/{group}": np.int64 for group in bench.offsets})
    return ContentDigests(dtypes)


def absent_chunk_files(bench, node: str) -> list[str]:
    """Chunk (shard) file names of ``node`` that its shape calls for but are not on disk."""
    if not node.startswith("arrays/"):
        return []  # offsets are read whole when the store opens
    array = bench.array(node.removeprefix("arrays/"))
    files_per_axis = [-(-size // step) for size, step in zip(array.shape, array.shards or array.chunks)]
    names = [array.metadata.encode_chunk_key(idx) for idx in np.ndindex(*files_per_axis)]
    return [name for name in names if not (bench.path / node / name).exists()]


def check_digests(bench, digests, problems: list[str]) -> None:
    """``checksum``: content read back (every block, then the offsets) against the recorded sha256."""
    for group, offsets in bench.offsets.items():
        digests.update(f"offsets/{group}", offsets)
    actual = digests.hexdigests()
    for node, recorded in sorted(bench.content_digests.items()):
        if node in actual and actual[node] != recorded:
            absent = absent_chunk_files(bench, node)
            why = (
                f"; chunk files absent (Zarr reads them as zeros): {', '.join(absent[:MAX_EXAMPLES])}"
                f"{' ...' if len(absent) > MAX_EXAMPLES else ''}"
                if absent
                else "; a chunk file changed after the store was written"
            )
            problems.append(
                f"checksum: {node} content differs from the sha256 recorded when the store was "
                f"written{why}. Fix: rebuild the store (delete it and rerun the workflow, or "
                "`becos export-zarr`) or restore it from a copy"
            )
