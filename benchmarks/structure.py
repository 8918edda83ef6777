"""The structure drawing of the ``becos`` package (issue #32): floors, rooms and arrows, as JSON.

A room is a top-level module or subpackage of ``becos`` (inside a layer package, each of its modules
and subpackages); a floor is the layer a room lives on (``tests/test_imports.py``: ``FLOORS``, lowest
first; a checkout without layer packages has every room on ``base``). Arrows are imports between rooms
(``tests/test_imports.py``'s import graph: module level and inside functions, ``TYPE_CHECKING`` left
out), counted once per pair of rooms, and summed per pair of floors; ``upward`` lists the room arrows
that go to a higher floor.

Usage::

    python benchmarks/structure.py [--repo CHECKOUT]    # e.g. a `git worktree add --detach` of an old commit
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from test_imports import FLOORS, LAYERS, floor, import_graph  # noqa: E402


def room(module: str) -> str:
    """The room of a module: ``becos.<top>``, or ``becos.<layer>.<child>`` inside a layer package."""
    parts = module.split(".")
    depth = 3 if len(parts) > 2 and parts[1] in LAYERS else 2
    return ".".join(parts[:depth])


def drawing(package: Path) -> dict:
    graph = import_graph(package)
    inits = {"becos", *(f"becos.{layer}" for layer in LAYERS)}  # the package and its layers: no rooms
    rooms = sorted({room(m) for m in graph if m not in inits}, key=lambda r: (FLOORS.index(floor(r)), r))
    arrows = sorted(
        {(room(a), room(b)) for a, targets in graph.items() for b in targets if room(a) != room(b) and b not in inits}
    )
    by_floor = collections.Counter((floor(a), floor(b)) for a, b in arrows if floor(a) != floor(b))
    return {
        "package": str(package),
        "floors": {f: [r for r in rooms if floor(r) == f] for f in FLOORS if any(floor(r) == f for r in rooms)},
        "rooms": len(rooms),
        "arrows_between_rooms": len(arrows),
        "arrows_between_floors": {f"{a} -> {b}": n for (a, b), n in sorted(by_floor.items())},
        "upward": [f"{a} -> {b}" for a, b in arrows if FLOORS.index(floor(b)) > FLOORS.index(floor(a))],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", type=Path, default=REPO, help="the checkout whose becos/ is drawn")
    args = parser.parse_args()
    print(json.dumps(drawing(args.repo.resolve() / "becos"), indent=1))


if __name__ == "__main__":
    main()
