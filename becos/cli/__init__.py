"""The ``becos`` command line: thin wrappers around library functions (one sub-command each).

Every sub-command prints progress to stderr and a short result to stdout; errors from bad input
print the message (file, problem, fix) and exit with status 2 instead of a traceback.

The command line lives in this package only: one module per sub-command group (``becos.cli.check``,
``becos.cli.workflow`` for the workflow's stages, ...). Each module's ``COMMANDS`` maps each of its
sub-commands to one pair: a function that adds the sub-command's arguments to its parser, and the
handler ``run(args) -> int`` (exit status); the science modules they call know nothing of argparse.
"""

from __future__ import annotations

import argparse
import atexit
import importlib
import os
import sys
import threading

from becos.errors import BecosError

SUBCOMMANDS: tuple[tuple[str, str, str], ...] = (
    # (name, module whose COMMANDS[name] is (add arguments to a parser, run(args) -> int), help)
    ("info", "becos.cli.info", "summarise a BeCoS annotation folder"),
    ("synthetic", "becos.cli.synthetic", "generate the built-in synthetic shape collection"),
    ("check", "becos.cli.check", "check that the enabled datasets and the annotation folder are present"),
    ("fetch-annotations", "becos.cli.check", "download the annotation folder from a pinned archive"),
    ("prepare-dt4d", "becos.cli.dt4d", "write DeformingThings4D frames (.anime) as the OBJ files BeCoS indexes"),
    ("download-dataset", "becos.cli.download", "download and unpack a dataset's public archive (kids, shrec20)"),
    ("write-config", "becos.cli.workflow", "validate a configuration and write it with defaults filled in"),
    ("catalog", "becos.cli.workflow", "write the shape catalog of a workflow config"),
    ("manifest", "becos.cli.workflow", "write the pair manifest of one setting"),
    ("remesh", "becos.cli.workflow", "remesh the variants of one shape"),
    ("ground-truth", "becos.cli.workflow", "compute the ground truth of one chunk of pairs"),
    ("pairs", "becos.cli.workflow", "build the pair records of one chunk of pairs"),
    ("metadata", "becos.cli.workflow", "metadata of a setting's store (config digest, dataset licences)"),
    ("export-pairings", "becos.cli.workflow", "write a manifest in the published pickle schema"),
    ("export-zarr", "becos.cli.export_zarr", "collect a setting's pair records into one Zarr store"),
    ("validate", "becos.cli.validate", "check a benchmark store; non-zero exit with a list of problems"),
    ("export-released", "becos.cli.export", "write a store in the released BeCoS folder layout"),
    ("export-psmal", "becos.cli.export", "write a store as PSMAL-style shapes/*.off + maps/*.vts"),
    ("export-geodesics", "becos.cli.export", "write geodesic matrices of a store's shapes in the loaders' layout"),
    ("geodesic-plan", "becos.cli.geodesic_jobs", "spread the distinct full meshes of some stores over geodesic jobs"),
    ("geodesic-rows", "becos.cli.geodesic_jobs", "compute the geodesic rows of one part of a geodesic plan"),
    ("export-ulrssm", "becos.cli.export", "write a store ULRSSM style: one off/ corres/ [dist/] root per pair"),
    ("export-dpfm", "becos.cli.export", "write a store DPFM style: shapes/*.off + maps/<x>_<y>.map"),
    ("report", "becos.cli.report", "counts, overlap histogram and renders of a store"),
    ("evaluate", "becos.cli.evaluate", "score predictions against a benchmark store"),
    ("baseline", "becos.cli.baselines", "run a baseline matcher on a benchmark store"),
)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser. Only the module of sub-command ``only`` is imported (none for ``becos --help``):
    the others are listed by name and help, so a job imports what its sub-command uses."""
    parser = argparse.ArgumentParser(prog="becos", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    for name, module_name, help_text in SUBCOMMANDS:
        command = sub.add_parser(name, help=help_text, description=help_text[:1].upper() + help_text[1:] + ".")
        if name == only:
            arguments, run = importlib.import_module(module_name).COMMANDS[name]
            arguments(command)
            command.set_defaults(func=run)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    known = {name for name, _, _ in SUBCOMMANDS}
    only = argv[0] if argv and argv[0] in known else None
    if only is not None:
        from becos.cli.audit import install_open_audit

        install_open_audit(only)  # tests only (BECOS_AUDIT_OPENS): what the job opens
    args = build_parser(only).parse_args(argv)
    try:
        return args.func(args)
    except BecosError as exc:
        # one problem per line, each prefixed (a config error lists several); indented lines continue one
        for line in str(exc).splitlines() or [""]:
            print(line if line[:1].isspace() else f"becos {args.command}: {line}", file=sys.stderr)
        return 2


def program() -> None:
    """The ``becos`` program (console script and ``python -m becos``): :func:`main`, then the exit.

    A sub-command that returns ends the process without the interpreter's teardown of its modules
    (unless a non-daemon thread still runs): the ``atexit`` handlers run (logging's flush,
    multiprocessing's joins, ...), stdout and stderr are flushed, then :func:`os._exit`. Every file
    becos writes is closed (and moved into place) before its function returns, so the teardown only
    frees memory that the exit frees anyway: it took 0.05-0.08 CPU-s of each ~1.2 CPU-s remesh job
    (numpy's, scipy's and pymeshlab's modules). An exception still ends the usual way, with its
    traceback. :func:`main` returns its status, for callers in the same process."""
    status = main()
    if any(t.is_alive() and not t.daemon for t in threading.enumerate() if t is not threading.main_thread()):
        sys.exit(status)  # the interpreter's exit waits for them
    atexit._run_exitfuncs()  # what the interpreter's own exit runs next
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):  # a reader that left (``becos info | head -1``), a closed stream
        status = status or 120  # the status Python's own exit gives a failed flush
    os._exit(status)


if __name__ == "__main__":
    program()
