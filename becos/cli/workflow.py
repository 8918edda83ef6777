"""The workflow's stage sub-commands (:mod:`becos.workflow`): ``write-config``, ``catalog``, ``manifest``,
``remesh``, ``ground-truth``, ``pairs``, ``metadata`` and ``export-pairings``."""

from __future__ import annotations

import argparse
import functools
import json
import re
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


def _stage(run):
    """The handler of a stage sub-command from ``run(args, config)``: ``--options`` parsed
    (:func:`parse_json_option`), exit status 0; an options dict that lacks a key or holds a value of
    the wrong type is a :class:`ConfigError`, a missing input an :class:`InputFileError` naming it."""

    @functools.wraps(run)
    def handler(args: argparse.Namespace) -> int:
        options = parse_json_option(args.options, "--options", args.command)
        given = sorted(options)
        for key in ("data_dir", "annotations"):  # the folders the rule passes stand for the options' own
            if getattr(args, key, None) is not None:
                options[key] = str(getattr(args, key))
        try:
            run(args, options)
        except KeyError as exc:
            raise ConfigError(
                f"--options: lacks the key {exc} (given keys: {given}). Fix: "
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
                f"to it (its input options; `results` in --options: {options.get('results')!r})",
            ) from None
        return 0

    return handler


# --- arguments several stages share, in the order they appear on a command line ----------------------


def _options(parser: argparse.ArgumentParser, whole_config: bool = False) -> None:
    what = "the whole config" if whole_config else "the job's options (becos.workflow.job_options)"
    parser.add_argument("--options", required=True, help=f"JSON: {what}")


def _annotations(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--annotations",
        required=True,
        type=Path,
        help="the annotation folder the job reads (config `annotations`; replaces the options' own)",
    )


def _setting(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--setting", required=True, choices=SETTINGS)


def _chunk(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--chunk", required=True, type=int)
    parser.add_argument(
        "--remesh-files",
        required=True,
        type=Path,
        help="the list file of each chunk's remesh files (the manifest job's --remesh-files)",
    )


def _manifest_catalog(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--manifest", required=True, type=Path, help="the setting's pair manifest")
    parser.add_argument("--catalog", required=True, type=Path)


def _out(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, type=Path)


# --- one pair per sub-command: its arguments, its handler -----------------------------------------------


def write_config_arguments(parser: argparse.ArgumentParser) -> None:
    _options(parser, whole_config=True)
    _out(parser)


@_stage
def run_write_config(args: argparse.Namespace, config: dict) -> None:
    write_text(args.out, json.dumps(resolve_config(config), indent=1, sort_keys=True) + "\n")


def catalog_arguments(parser: argparse.ArgumentParser) -> None:
    _options(parser)
    parser.add_argument(
        "--data-dir",
        required=True,
        type=Path,
        help="the data folder the job lists (config `data_dir`; replaces the options' own)",
    )
    _annotations(parser)
    _out(parser)


@_stage
def run_catalog(args: argparse.Namespace, config: dict) -> None:
    write_catalog_stage(config, args.out)


def manifest_arguments(parser: argparse.ArgumentParser) -> None:
    _options(parser)
    _annotations(parser)
    _setting(parser)
    parser.add_argument("--catalog", required=True, type=Path)
    _out(parser)
    parser.add_argument("--remesh-files", type=Path, help="also write the remesh files of each chunk (JSON)")


@_stage
def run_manifest(args: argparse.Namespace, config: dict) -> None:
    write_manifest_stage(config, args.setting, args.catalog, args.out, args.remesh_files)


def remesh_arguments(parser: argparse.ArgumentParser) -> None:
    _options(parser)
    parser.add_argument("--shape", required=True, help="JSON: the shape's catalog row (but its file)")
    parser.add_argument(
        "--mesh", type=Path, help="the shape's mesh file (the workflow's rule passes it; default: the row's file)"
    )
    parser.add_argument(
        "--tokens",
        required=True,
        type=_tokens,
        help="the variants to write, comma-separated: v<k> (variant k) or f<n> (target faces n), e.g. v0,v1",
    )
    parser.add_argument(
        "--out-dir",
        required=True,
        type=Path,
        help="the shape's remesh folder, written whole: <token>.npz and <token>.ply per token",
    )


def _tokens(text: str) -> list[str]:
    """``--tokens``: comma-separated remesh tokens, each ``v<k>`` or ``f<n>``."""
    tokens = [t.strip() for t in text.split(",") if t.strip()]
    bad = [t for t in tokens if not re.fullmatch(r"[vf][0-9]+", t)]
    if not tokens or bad:
        raise argparse.ArgumentTypeError(
            f"{text!r}: give comma-separated tokens v<k> (remesh variant k) or f<n> (face target n), e.g. v0,v1"
        )
    return tokens


@_stage
def run_remesh(args: argparse.Namespace, config: dict) -> None:
    shape = parse_json_option(args.shape, "--shape", args.command)
    if args.mesh is not None:
        shape["file"] = str(args.mesh)
    remesh_stage(config, shape, args.tokens, args.out_dir)


def ground_truth_arguments(parser: argparse.ArgumentParser) -> None:
    _options(parser)
    _annotations(parser)
    _setting(parser)
    _chunk(parser)
    _manifest_catalog(parser)
    _out(parser)


@_stage
def run_ground_truth(args: argparse.Namespace, config: dict) -> None:
    ground_truth_stage(
        config,
        args.setting,
        args.chunk,
        args.out,
        manifest=args.manifest,
        catalog=args.catalog,
        remesh_files=args.remesh_files,
    )


def pairs_arguments(parser: argparse.ArgumentParser) -> None:
    _options(parser)
    _annotations(parser)
    _setting(parser)
    _chunk(parser)
    parser.add_argument("--ground-truth", required=True, type=Path, help="the chunk's ground-truth index")
    parser.add_argument(
        "--triangle-ids",
        type=Path,
        help="the folder of the published views' triangle ids (original_settings P2P; default: cast every view)",
    )
    _manifest_catalog(parser)
    _out(parser)


@_stage
def run_pairs(args: argparse.Namespace, config: dict) -> None:
    pairs_stage(
        config,
        args.setting,
        args.chunk,
        args.ground_truth,
        args.out,
        triangle_ids=args.triangle_ids,
        manifest=args.manifest,
        catalog=args.catalog,
        remesh_files=args.remesh_files,
    )


def metadata_arguments(parser: argparse.ArgumentParser) -> None:
    _options(parser, whole_config=True)
    _setting(parser)
    _out(parser)


@_stage
def run_metadata(args: argparse.Namespace, config: dict) -> None:
    metadata = store_metadata(config, args.setting)
    write_text(args.out, json.dumps(metadata, indent=1, sort_keys=True, default=str) + "\n")


def export_pairings_arguments(parser: argparse.ArgumentParser) -> None:
    _options(parser)
    _setting(parser)
    _manifest_catalog(parser)
    parser.add_argument("--store", required=True, type=Path, help="the setting's benchmark store")
    _out(parser)


@_stage
def run_export_pairings(args: argparse.Namespace, config: dict) -> None:
    export_pairings_stage(config, args.setting, args.out, args.store, manifest=args.manifest, catalog=args.catalog)


COMMANDS = {
    "write-config": (write_config_arguments, run_write_config),
    "catalog": (catalog_arguments, run_catalog),
    "manifest": (manifest_arguments, run_manifest),
    "remesh": (remesh_arguments, run_remesh),
    "ground-truth": (ground_truth_arguments, run_ground_truth),
    "pairs": (pairs_arguments, run_pairs),
    "metadata": (metadata_arguments, run_metadata),
    "export-pairings": (export_pairings_arguments, run_export_pairings),
}
"""Each sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
