"""Mesh file formats, one module each (the model is trimesh's ``exchange/``): the cheap structure check
of a file, and for OFF the one reader of becos.

Modules: ``off`` (header, :func:`~becos.core.formats.off.check_off`, :func:`~becos.core.formats.off.read_off`),
``ply`` (ASCII and binary check from header and file size), ``obj``, ``text`` (data lines and the
line-numbered checks OFF and ASCII PLY share), ``problems``, ``write`` (OFF and VTS text). PLY, OBJ and irregular OFF files are read by
trimesh (:func:`becos.core.mesh.read_mesh`). :func:`check_file` dispatches on the suffix;
:func:`not_a_regular_file` names an entry that is no file, from ``stat`` alone. In detail:
docs/design/data.md.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from becos.core.formats.obj import check_obj
from becos.core.formats.off import check_off
from becos.core.formats.ply import check_ply
from becos.core.formats.problems import LINK_FIX, NOT_A_FILE_FIX, TRUNCATED_FIX
from becos.errors import InputFileError

_KINDS = (  # (test of st_mode, what the entry is), for everything but a regular file and a link
    (stat.S_ISDIR, "a folder"),
    (stat.S_ISFIFO, "a named pipe (FIFO)"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISCHR, "a device file (character device)"),
    (stat.S_ISBLK, "a device file (block device)"),
)


def _kind(mode: int) -> str:
    """What a ``st_mode`` that is no regular file and no link names (``a folder``, ``a socket``, ...)."""
    return next((what for test, what in _KINDS if test(mode)), f"a special file (mode {stat.S_IFMT(mode):o})")


def not_a_regular_file(path: str | Path) -> str | None:
    """What is at ``path`` when it is no regular file (symbolic links followed): ``'a folder'``,
    ``'a named pipe (FIFO)'``, ``'a socket'``, ``'a device file (character device)'``,
    ``'a symbolic link to /dev/zero, a device file (character device)'``,
    ``'a symbolic link to <target>, which does not exist (a dangling link)'``, a loop of links;
    ``None`` for a regular file (or a link to one) and where nothing is at all (the caller's "not found").

    Decided by ``lstat``/``stat`` alone: nothing is opened, so a named pipe (which would block) or a link
    to ``/dev/zero`` (which never ends) is safe to ask about. The same test as the input digests
    (:meth:`becos.workflow.digests.DigestCache.file`, whose stand-in is ``not a regular file``)."""
    path = Path(path)
    try:
        own = os.lstat(path)
    except OSError:
        return None
    if not stat.S_ISLNK(own.st_mode):
        return None if stat.S_ISREG(own.st_mode) else _kind(own.st_mode)
    try:
        target = os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return f"a symbolic link to {os.readlink(path)} that never reaches a file (a loop of links)"
        if exc.errno in (errno.ENOENT, errno.ENOTDIR):
            return f"a symbolic link to {os.readlink(path)}, which does not exist (a dangling link)"
        return f"a symbolic link to {os.readlink(path)}, which cannot be examined ({exc.strerror})"
    if stat.S_ISREG(target.st_mode):
        return None
    return f"a symbolic link to {os.path.realpath(path)}, {_kind(target.st_mode)}"


def not_a_mesh_file(path: str | Path) -> tuple[str, str] | None:
    """``(problem, fix)`` for an entry at ``path`` that is no regular file (:func:`not_a_regular_file`),
    e.g. ``('is a named pipe (FIFO), not a mesh file', 'replace it with the mesh file itself ...')``;
    ``None`` for a regular file, a link to one, or nothing."""
    what = not_a_regular_file(path)
    if what is None:
        return None
    if what.endswith("(a dangling link)"):
        return f"is {what}", LINK_FIX
    return f"is {what}, not a mesh file", LINK_FIX if os.path.islink(path) else NOT_A_FILE_FIX


def check_file(path: str | Path) -> tuple[int, int]:
    """Cheap check that a mesh file is complete (see :mod:`becos.sources.check.meshes`); returns (V, F) counts.

    For OBJ the counts are the numbers of ``v`` and ``f`` lines.

    Raises:
        InputFileError: missing, empty, truncated or unparsable file.
    """
    path = Path(path)
    fix = TRUNCATED_FIX
    odd = not_a_mesh_file(path)
    if odd is not None:
        raise InputFileError(path, *odd)
    if not path.is_file():
        raise InputFileError(path, "mesh file not found", fix)
    size = path.stat().st_size
    if size == 0:
        raise InputFileError(path, "the mesh file is empty (0 bytes)", fix)
    suffix = path.suffix.lower()
    try:
        if suffix == ".off":
            counts = check_off(path.read_bytes())
        elif suffix == ".ply":
            counts = check_ply(path, size)
        elif suffix == ".obj":
            counts = check_obj(path.read_bytes())
        else:
            raise ValueError(f"unknown mesh type '{suffix}' (use .off, .ply or .obj)")
    except (ValueError, IndexError, OverflowError) as exc:
        raise InputFileError(path, str(exc) or type(exc).__name__, getattr(exc, "fix", fix)) from None
    return counts
