"""The ``becos`` command line: thin wrappers around library functions (one sub-command each).

Every sub-command prints progress to stderr and a short result to stdout; errors from bad input
print the message (file, problem, fix) and exit with status 2 instead of a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from becos.errors import BecosError


def cmd_info(args: argparse.Namespace) -> int:
    """Summarise an annotation folder: network, edges, template rows, available TOSCA shapes."""
    from becos.annotations import AnnotationSource

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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="becos", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    info = sub.add_parser("info", help="summarise a BeCoS annotation folder")
    info.add_argument("--annotations", required=True, type=Path, help="folder laid out like the BeCoS checkout")
    info.add_argument("--edges", action="store_true", help="also parse every edge file (cached after the first run)")
    info.set_defaults(func=cmd_info)

    from becos.synthetic import configure_parser, run_cli

    synthetic = sub.add_parser("synthetic", help="generate the built-in synthetic shape collection")
    configure_parser(synthetic)
    synthetic.set_defaults(func=run_cli)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except BecosError as exc:
        print(f"becos {args.command}: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
