"""A failed workflow job's own error message, read from its log file for the console.

Every rule sends its ``becos <sub-command>`` output to a log file (``logs/...``), so Snakemake's
console only says that a job failed. The workflow's ``onerror`` handler (workflow/rules/common.smk)
prints :func:`failure_report`: per failed job, the rule, the log and the lines of the log that say
what went wrong.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path

MAX_LINES = 12
"""Lines of one job's error shown on the console (the log keeps all)."""
_BECOS_LINE = re.compile(r"^becos [a-z0-9-]+( [^:\s]+)?: ")


def error_lines(text: str, limit: int = MAX_LINES) -> list[str]:
    """The lines of a job log that say why the job failed.

    - The trailing ``becos <command>: ...`` lines (the CLI's error lines, ``<file>: <problem>. Fix:
      <fix>``) with their indented continuation lines;
    - when a Python traceback follows the last such line (a bug, not bad input): the exception's
      last line;
    - else the log's last lines (e.g. ``Killed`` from the out-of-memory killer).

    At most ``limit`` lines; an empty log gives ``[]``.
    """
    lines = [line.rstrip() for line in text.splitlines()]
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        return []
    last_becos = max((i for i, line in enumerate(lines) if _BECOS_LINE.match(line)), default=-1)
    tracebacks = [i for i, line in enumerate(lines) if line.startswith("Traceback (most recent call last)")]
    if tracebacks and tracebacks[-1] > last_becos:
        exception = next((line for line in reversed(lines) if line and not line[:1].isspace()), lines[-1])
        return [
            exception,
            f"(a Python traceback: the full one is in the log{'' if last_becos < 0 else ' below the becos lines'})",
        ]
    if last_becos >= 0 and all(
        not line.strip() or line[:1].isspace() or _BECOS_LINE.match(line) for line in lines[last_becos:]
    ):
        prefix = lines[last_becos].split(": ", 1)[0] + ": "  # "becos check: "
        start = last_becos
        while start > 0 and (lines[start - 1].startswith(prefix) or lines[start - 1][:1].isspace()):
            start -= 1
        shown = lines[start:]
    else:
        shown = lines[-3:]
    if len(shown) > limit:
        shown = shown[: limit - 1] + [f"... ({len(shown) - limit + 1} more lines in the log)"]
    return shown


def failure_report(jobs: Iterable[tuple[str, str, list[str]]]) -> str:
    """Console text for failed jobs, each given as ``(rule, wildcards text, log paths)``: one heading per
    job (rule, wildcards, log) and its :func:`error_lines`; ``""`` when there are none."""
    blocks = []
    for rule, wildcards, logs in jobs:
        label = f"{rule} ({wildcards})" if wildcards else rule
        shown = []
        for log in logs:
            path = Path(log)
            try:
                shown += error_lines(path.read_text(errors="replace"))
            except OSError:
                shown.append(f"(no log: {log} was not written)")
        where = ", ".join(map(str, logs)) or "no log file"
        blocks.append("\n".join([f"becos: job {label} failed (log: {where}):", *(shown or ["(the log is empty)"])]))
    if not blocks:
        return ""
    return "\n".join(blocks)


def snakemake_failed_jobs(workflow) -> list[tuple[str, str, list[str]]]:
    """``(rule, wildcards text, log paths)`` of the jobs a finished Snakemake run marked failed (its
    scheduler's ``failed`` set; a group job gives its member jobs), in a stable order."""
    scheduler = getattr(workflow, "scheduler", None)
    found = []
    for job in getattr(scheduler, "failed", ()) or ():
        for member in getattr(job, "jobs", None) or [job]:
            rule = getattr(getattr(member, "rule", None), "name", "?")
            wildcards = ", ".join(f"{k}={v}" for k, v in dict(getattr(member, "wildcards_dict", {}) or {}).items())
            logs = [str(p) for p in (getattr(member, "log", None) or [])]
            found.append((rule, wildcards, logs))
    return sorted(found)
