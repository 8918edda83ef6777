"""``becos info``: summarise a BeCoS annotation folder (:mod:`becos.sources.annotations`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def configure_parser(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--annotations", required=True, type=Path, help="folder laid out like the BeCoS checkout")
    parser.add_argument("--edges", action="store_true", help="also parse every edge file (cached after the first run)")


def run_cli(args: argparse.Namespace) -> int:
    """Summarise an annotation folder: network, edges, template rows, available TOSCA shapes."""
    from becos.sources.annotations import AnnotationSource

    source = AnnotationSource(args.annotations)
    edges = source.edge_sources()
    kinds = {k: sum(e.kind == k for e in edges) for k in ("file", "identity")}
    zero_rows = 0
    if args.edges:
        for e in edges:
            if e.kind == "file":
                zero_rows += source.edge_report(e.source, e.target).get("zero_weight_rows", 0)
    info = {
        "annotations": str(Path(args.annotations).resolve()),
        "nodes": source.graph.number_of_nodes(),
        "undirected_edges": source.graph.number_of_edges(),
        "directed_edges": kinds,
        "template_rows": len(source.template_rows()),
    }
    if args.edges:
        info["zero_weight_rows"] = zero_rows
    print(json.dumps(info, indent=2))
    return 0


COMMANDS = {"info": (configure_parser, run_cli)}
"""The sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
