"""The opened-paths audit of a workflow run (``BECOS_AUDIT_OPENS``, :mod:`becos.cli.audit`): which paths
each ``becos`` job opened or listed that its rule did not declare.

A job's declared paths are what Snakemake recorded for its outputs (``.snakemake/metadata``: ``input``,
``log``, ``params``, and the outputs themselves); a job is matched to its audit record by its command
line (the recorded ``shellcmd`` up to its redirection is ``becos`` + the record's ``argv``). Only paths
under the working directory and the given data folders are judged (the package, the environment and
the system are not the workflow's inputs). A path is declared when it is a declared path, lies under a
declared folder, is a hidden temporary beside a declared path (``becos.atomic``), is a file a declared
chunk index lists, or (a listing) is the folder of a declared output (stale temporaries are looked for
there).
"""

from __future__ import annotations

import base64
import json
import os
import shlex
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Job:
    rule: str
    argv: tuple[str, ...]
    outputs: tuple[str, ...]
    declared: tuple[str, ...]  # absolute inputs, outputs, logs and path-valued params


def recorded_jobs(workdir: Path) -> dict[tuple[str, ...], Job]:
    """Each finished job of the run in ``workdir`` by its command line (``becos`` sub-command + arguments)."""
    workdir = Path(workdir).resolve()
    grouped: dict[tuple[str, ...], dict] = {}
    for path in (workdir / ".snakemake" / "metadata").iterdir():
        output = base64.b64decode(path.name.replace("@", "/")).decode()
        meta = json.loads(path.read_text())
        shellcmd = meta.get("shellcmd") or ""
        words = shlex.split(shellcmd)
        if not words or words[0] != "becos":
            continue
        argv = tuple(words[1 : words.index(">")] if ">" in words else words[1:])
        job = grouped.setdefault(argv, {"rule": meta["rule"], "outputs": set(), "declared": set()})
        job["outputs"].add(output)
        params = [_unquote(p) for p in meta.get("params", []) if isinstance(p, str)]
        for p in [output, *meta.get("input", []), *meta.get("log", []), *params]:
            if p and not p.startswith(("{", "[")) and "\n" not in p and (p.startswith("/") or (workdir / p).exists()):
                job["declared"].add(os.path.normpath(workdir / p))
    return {
        argv: Job(j["rule"], argv, tuple(sorted(j["outputs"])), tuple(sorted(j["declared"])))
        for argv, j in grouped.items()
    }


def _unquote(param: str) -> str:
    """A recorded param value without the shell quotes Snakemake's ``:q`` record keeps."""
    try:
        words = shlex.split(param)
    except ValueError:
        return param
    return words[0] if len(words) == 1 else param


def _under(path: str, folder: str) -> bool:
    return path == folder or path.startswith(folder.rstrip("/") + "/")


def _indexed_files(index: str, workdir: Path) -> set[str]:
    """The files a chunk index (``becos.workflow.stages._write_index``) lists; none for another file."""
    if not index.endswith(".json") or not os.path.isfile(index):
        return set()
    try:
        entries = json.loads(Path(index).read_text())["pairs"]
        return {os.path.normpath(workdir / e["path"]) for e in entries}
    except (ValueError, KeyError, TypeError):
        return set()


def undeclared_opens(workdir: Path, audit: Path, roots: list[Path]) -> list[str]:
    """``rule (outputs): event path`` for each path a job of the run in ``workdir`` opened or listed (audit
    records in ``audit``) under ``workdir`` or ``roots`` without its rule declaring it, and a line for
    each audit record no recorded job matches."""
    workdir = Path(workdir).resolve()
    jobs = recorded_jobs(workdir)
    judged = [str(workdir), *(os.path.normpath(r) for r in roots)]
    problems = []
    for record_path in sorted(Path(audit).glob("*.json")):
        record = json.loads(record_path.read_text())
        job = jobs.get(tuple(record["argv"]))
        if job is None:
            problems.append(f"{record_path.name}: no recorded job ran `becos {shlex.join(record['argv'])[:200]}`")
            continue
        declared = set(job.declared)
        for d in job.declared:
            declared |= _indexed_files(d, workdir)
        outputs_folders = {os.path.dirname(os.path.normpath(workdir / o)) for o in job.outputs}
        for event, path, mode in record["opened"]:
            if not any(_under(path, root) for root in judged) or _under(path, str(workdir / ".snakemake")):
                continue
            ok = (
                any(_under(path, d) for d in declared)
                or any(path.startswith(os.path.join(os.path.dirname(d), f".{os.path.basename(d)}.")) for d in declared)
                or (event in ("os.listdir", "os.scandir") and path in outputs_folders)
            )
            if not ok:
                problems.append(f"{job.rule} ({', '.join(job.outputs)}): {event} {mode} {path}")
    return problems
