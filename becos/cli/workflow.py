"""The workflow's stage sub-commands (:mod:`becos.workflow`): ``write-config``, ``catalog``, ``manifest``,
``remesh``, ``ground-truth``, ``pairs``, ``metadata`` and ``export-pairings``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from becos.atomic import write_text
from becos.errors import ConfigError, InputFileError
from becos.settings import SETTINGS
from becos.workflow import (
    export_pairings_stage,
    ground_truth_stage,
    pairs_stage,
    remesh_stage,
    resolve_config,
    store_metadata,
    write_catalog_stage,
    write_manifest_stage,
)


def configure_parser(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument(
        "--options",
        required=True,
        help="JSON: the job's options (becos.workflow.job_options), or the whole config for write-config and metadata",
    )
    if name in ("manifest", "ground-truth", "pairs", "metadata", "export-pairings"):
        parser.add_argument("--setting", required=True, choices=SETTINGS)
    if name in ("ground-truth", "pairs"):
        parser.add_argument("--chunk", required=True, type=int)
        parser.add_argument(
            "--remeshed", required=True, type=Path, help="the folder of the remesh variants (results/remeshed)"
        )
    if name == "pairs":
        parser.add_argument("--ground-truth", required=True, type=Path, help="the chunk's ground-truth index")
        parser.add_argument(
            "--triangle-ids",
            type=Path,
            help="the folder of the published views' triangle ids (original_settings P2P; default: cast every view)",
        )
    if name in ("ground-truth", "pairs", "export-pairings"):
        parser.add_argument("--manifest", required=True, type=Path, help="the setting's pair manifest")
    if name in ("manifest", "ground-truth", "pairs", "export-pairings"):
        parser.add_argument("--catalog", required=True, type=Path)
    if name == "export-pairings":
        parser.add_argument("--store", required=True, type=Path, help="the setting's benchmark store")
    if name == "remesh":
        parser.add_argument("--shape", required=True, help="JSON: the shape's catalog row")
        parser.add_argument("--token", required=True, help="v<k> (variant k) or f<n> (target faces n)")
        parser.add_argument("--ply", type=Path, help="also write the remeshed mesh as PLY")
    parser.add_argument("--out", required=True, type=Path)


def parse_json_option(text: str, option: str, command: str) -> dict:
    """The JSON object passed as ``option`` to ``becos <command>``.

    Raises:
        ConfigError: not JSON, or not a JSON object (names the option, the position and the fix).
    """
    fix = (
        "Fix: pass the JSON the workflow's rule writes (--options: becos.workflow.job_options, or the whole "
        "resolved config for write-config and metadata; --shape: the shape's catalog row as a JSON object)"
    )
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(
            f"{option}: not valid JSON ({exc.msg} at line {exc.lineno} column "
            f"{exc.colno}: {text[max(0, exc.pos - 20) : exc.pos + 20]!r}). {fix}"
        ) from None
    if not isinstance(value, dict):
        raise ConfigError(
            f"{option}: a JSON object {{...}} is needed, not a JSON {type(value).__name__} ({text[:60]!r}). {fix}"
        )
    return value


def run_cli(args: argparse.Namespace) -> int:
    config = parse_json_option(args.options, "--options", args.command)
    try:
        return _run_stage(args, config)
    except KeyError as exc:
        raise ConfigError(
            f"--options: lacks the key {exc} (given keys: {sorted(config)}). Fix: "
            f"pass the JSON the workflow's rule writes (becos.workflow.job_options)"
        ) from None
    except TypeError as exc:
        raise ConfigError(
            f"--options: a value has the wrong type ({exc}). Fix: check the "
            f"values against becos/data/schema.yaml, or pass the JSON the workflow's rule writes"
        ) from None
    except FileNotFoundError as exc:
        raise InputFileError(
            exc.filename or "?",
            "not found (an input of this stage)",
            f"run the stages before `becos {args.command}` (the workflow does), or check the paths given "
            f"to it (its input options; `results` in --options: {config.get('results', 'results')!r})",
        ) from None


def _run_stage(args: argparse.Namespace, config: dict) -> int:
    if args.command == "write-config":
        write_text(args.out, json.dumps(resolve_config(config), indent=1, sort_keys=True) + "\n")
        return 0
    if args.command == "catalog":
        write_catalog_stage(config, args.out)
    elif args.command == "manifest":
        write_manifest_stage(config, args.setting, args.catalog, args.out)
    elif args.command == "remesh":
        remesh_stage(config, parse_json_option(args.shape, "--shape", args.command), args.token, args.out, args.ply)
    elif args.command in ("ground-truth", "pairs"):
        inputs = {"manifest": args.manifest, "catalog": args.catalog, "remeshed": args.remeshed}  # the rule's
        if args.command == "ground-truth":
            ground_truth_stage(config, args.setting, args.chunk, args.out, **inputs)
        else:
            pairs_stage(
                config, args.setting, args.chunk, args.ground_truth, args.out, triangle_ids=args.triangle_ids, **inputs
            )
    elif args.command == "metadata":
        write_text(
            args.out, json.dumps(store_metadata(config, args.setting), indent=1, sort_keys=True, default=str) + "\n"
        )
    elif args.command == "export-pairings":
        export_pairings_stage(config, args.setting, args.out, args.store, manifest=args.manifest, catalog=args.catalog)
    return 0
