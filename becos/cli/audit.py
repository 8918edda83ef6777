"""The opened-paths audit of a ``becos`` job (tests): with ``BECOS_AUDIT_OPENS=<folder>`` set, the
command line records every path it opens or lists into ``<folder>/<command>-<pid>.json``.

The record holds the command line (``argv``), the working directory and ``opened``: ``[event, absolute
path, mode]`` per distinct path, ``event`` one of :data:`AUDIT_EVENTS` (Python's audit events,
https://docs.python.org/3/library/audit_events.html: ``open`` is raised by ``builtins.open``,
``io.open`` and ``os.open``, hence by ``np.load`` and pandas; listings raise their own events). Files
opened by C code (e.g. a mesh library's own reader) raise no event, and an ``os.open`` of a relative
name may be relative to a folder descriptor (``dir_fd``, which the event does not carry): it is left out.
"""

from __future__ import annotations

import atexit
import json
import os
import sys

AUDIT_ENV = "BECOS_AUDIT_OPENS"
AUDIT_EVENTS = ("open", "os.listdir", "os.scandir", "glob.glob")
CODE_SUFFIXES = (".py", ".pyc", ".so")


def install_open_audit(command: str) -> None:
    """When ``BECOS_AUDIT_OPENS`` names a folder, record what this process opens (see the module)."""
    folder = os.environ.get(AUDIT_ENV)
    if not folder:
        return
    cwd = os.getcwd()
    seen: dict[tuple[str, str], str] = {}
    state = {"on": True}

    def hook(event: str, args: tuple) -> None:
        if not state["on"] or event not in AUDIT_EVENTS:
            return
        path = args[0] if args else None
        if isinstance(path, bytes):
            path = os.fsdecode(path)
        if path is None and event != "open":
            path = "."  # os.listdir() / os.scandir() of the working directory
        if not isinstance(path, str | os.PathLike):
            return  # a file descriptor
        mode = ""
        if event == "open" and len(args) > 2:
            if args[1] is None and not os.path.isabs(path):
                return  # os.open of a name in a folder given by descriptor (dir_fd; shutil.rmtree), unknown here
            mode = args[1] if isinstance(args[1], str) else _flags_mode(args[2])
        absolute = os.path.normpath(os.path.join(cwd, os.fspath(path)))
        if absolute.endswith(CODE_SUFFIXES) or "__path_hook__" in absolute:
            return  # an import
        key = (event, absolute)
        if "w" in mode or "a" in mode or "x" in mode or key not in seen:
            seen[key] = "w" if ("w" in mode or "a" in mode or "x" in mode) else seen.get(key, "r")

    def save() -> None:
        state["on"] = False
        os.makedirs(folder, exist_ok=True)
        record = {
            "argv": sys.argv[1:],
            "cwd": cwd,
            "opened": [[event, path, mode] for (event, path), mode in sorted(seen.items())],
        }
        with open(os.path.join(folder, f"{command}-{os.getpid()}.json"), "w") as f:
            json.dump(record, f, indent=0)

    atexit.register(save)
    sys.addaudithook(hook)


def _flags_mode(flags) -> str:
    """``"w"`` for ``os.open`` flags that write, else ``"r"``."""
    if not isinstance(flags, int):
        return "r"
    return "w" if flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT) else "r"
