"""Names and defaults every stage of the benchmark shares: the settings, the splits, the P2P overlap range.

Standard library only, so the Snakefile, the config check and light jobs import it for free. The config
defaults of ``min_overlap`` / ``max_overlap`` in ``becos/data/schema.yaml`` equal :data:`MIN_OVERLAP` /
:data:`MAX_OVERLAP` (a test checks).
"""

from __future__ import annotations

SETTINGS = ("full_full", "partial_full", "partial_partial")
"""The three pair settings, in the order manifests, stores and reports list them."""
SETTING_LABELS = {"full_full": "F2F", "partial_full": "P2F", "partial_partial": "P2P"}
"""The short name of each setting (reports, tables)."""

SPLITS = ("train", "val", "test")
"""The benchmark's splits, in the order tables list them (the published pickles store train, test, val:
``becos.build.published.PUBLISHED_SPLITS``)."""

MIN_OVERLAP = 0.1
MAX_OVERLAP = 0.9
"""A partial-to-partial pair is accepted when both overlaps (shares of a partial shape's vertices whose
ground-truth point lies on the other shape, 0-1) lie in ``[MIN_OVERLAP, MAX_OVERLAP]`` (the published
benchmark's range)."""


def overlap_range_problem(min_overlap: float, max_overlap: float) -> str | None:
    """What is wrong with the overlap range ``[min_overlap, max_overlap]`` (``key: problem. Fix: fix``), or
    None when ``0 <= min_overlap <= max_overlap <= 1``."""
    for key, value in (("min_overlap", min_overlap), ("max_overlap", max_overlap)):
        if not 0.0 <= value <= 1.0:
            return f"{key}: {value} is outside [0, 1] (a share of a shape's vertices). Fix: use a value in [0, 1]"
    if min_overlap > max_overlap:
        return (
            f"min_overlap: {min_overlap} is above max_overlap {max_overlap} (the overlap range is reversed). "
            "Fix: set min_overlap <= max_overlap"
        )
    return None
