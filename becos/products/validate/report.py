"""What :func:`becos.products.validate.validate` returns: the problems found, gathered per check, and a summary.

:class:`Problems` accumulates the pair-wise problems across blocks (one message per check and what,
with the number of pairs and example pair ids); :class:`ValidationReport` is the result the command
line prints.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

MAX_EXAMPLES = 3
"""Example pair ids named per problem."""


@dataclass
class Problems:
    """Accumulates problems by (check, what) across blocks: pair count and example ids."""

    items: dict = field(default_factory=dict)

    def add(self, check: str, what: str, pair_ids, detail: str = "", values: int = 0) -> None:
        """Record ``pair_ids`` failing ``check``; ``values`` counts bad values (summed over calls)."""
        pair_ids = [str(p) for p in pair_ids]
        if not pair_ids:
            return
        entry = self.items.setdefault((check, what), {"n": 0, "examples": [], "detail": detail, "values": 0})
        entry["n"] += len(pair_ids)
        entry["values"] += int(values)
        entry["examples"].extend(pair_ids[: MAX_EXAMPLES - len(entry["examples"])])

    def merge(self, other: Problems) -> None:
        """Add ``other``'s problems, found after this one's: the same result as adding them here."""
        for key, e in other.items.items():
            entry = self.items.setdefault(key, {"n": 0, "examples": [], "detail": e["detail"], "values": 0})
            entry["n"] += e["n"]
            entry["values"] += e["values"]
            entry["examples"].extend(e["examples"][: MAX_EXAMPLES - len(entry["examples"])])

    def messages(self) -> list[str]:
        """One line per (check, what), in the order first found: ``check: what in N pair(s), e.g. ids (notes)``."""
        out = []
        for (check, what), e in self.items.items():
            notes = ([f"{e['values']} value(s)"] if e["values"] else []) + ([e["detail"]] if e["detail"] else [])
            notes_text = f" ({'; '.join(notes)})" if notes else ""
            out.append(f"{check}: {what} in {e['n']} pair(s), e.g. {', '.join(e['examples'])}{notes_text}")
        return out


@dataclass
class ValidationReport:
    """Result of :func:`validate`: ``problems`` (empty = valid) and a summary."""

    path: Path
    problems: list[str]
    n_pairs: int = 0
    setting: str = ""
    splits: dict = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def valid(self) -> bool:
        return not self.problems

    def summary(self) -> dict:
        return {
            "store": str(self.path),
            "valid": self.valid,
            "setting": self.setting,
            "n_pairs": self.n_pairs,
            "splits": self.splits,
            "n_problems": len(self.problems),
            "seconds": round(self.seconds, 2),
        }
