"""Atomic file writes: write next to the destination, then rename, so no reader sees half a file.

An interrupted job leaves either the old file or none, plus at most a hidden ``.<name>.*.tmp*``,
which the next job writing that file removes (:func:`remove_stale_temporaries`).
"""

from __future__ import annotations

import errno
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from becos.errors import DiskFullError


@contextmanager
def atomic_path(path: str | Path, suffix: str = ".tmp") -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` (mode 0644), else it is removed.

    ``suffix`` must end like what the writer appends (``np.savez`` adds ``.npz`` unless present).
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
    except OSError as exc:
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            raise DiskFullError(path, exc) from exc
        raise
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; results are meant to be shared
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            raise DiskFullError(path, exc) from exc
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def atomic_folder(path: str | Path) -> Iterator[Path]:
    """Yield a new temporary folder beside ``path`` (``.<name>.tmp-<random>``); on success it replaces
    ``path`` (mode 0755; an existing folder is moved aside to ``.<name>.old-<random>``, then removed), else
    it is removed. The two folders a killed write of ``path`` left are removed first: only the one job
    that writes ``path`` may call it. A reader sees the old folder, none, or the whole new one."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        # exactly ".<name>.tmp-*" and ".<name>.old-*": other jobs write their folders beside this one (the
        # remesh folders of a dataset), and the file rule of remove_stale_temporaries would take a running
        # write of "<name>.<suffix>" (a shape named "a.1" beside "a") for a killed one of "<name>"
        for entry in os.scandir(path.parent):
            if not entry.name.startswith((f".{path.name}.tmp-", f".{path.name}.old-")):
                continue
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path, ignore_errors=True)
            else:
                Path(entry.path).unlink(missing_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.tmp-"))
    except OSError as exc:
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            raise DiskFullError(path, exc) from exc
        raise
    try:
        yield tmp
        os.chmod(tmp, 0o755)  # mkdtemp creates 0700; results are meant to be shared
        if path.exists():
            old = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.old-"))
            os.replace(path, old / path.name)
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT):
            raise DiskFullError(path, exc) from exc
        raise


def remove_stale_temporaries(folder: str | Path, names: Iterable[str]) -> int:
    """Delete the hidden temporary files (or folders, e.g. a Zarr store's) that killed writes of
    ``names`` (in ``folder``) left behind; the number deleted. Only the one job that writes ``names``
    may call it (another job's write in progress would lose its temporary file). One directory
    listing, whatever ``names`` holds.
    """
    names = set(names)
    removed = 0
    try:
        entries = list(os.scandir(folder))
    except FileNotFoundError:
        return 0
    for entry in entries:
        if not entry.name.startswith(".") or ".tmp" not in entry.name and ".old-" not in entry.name:
            continue
        targets = {
            # ".<name>.<mkstemp's random part, no dots><suffix starting .tmp>"
            entry.name[1 : entry.name.rindex(".tmp")].rpartition(".")[0] if ".tmp" in entry.name else "",
            # a folder built aside, ".<name>.tmp-<random>", or the old one it replaces, ".<name>.old-<random>"
            entry.name[1:].split(".tmp-")[0],
            entry.name[1:].split(".old-")[0],
        }
        if targets & names:
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path, ignore_errors=True)
            else:
                Path(entry.path).unlink(missing_ok=True)
            removed += 1
    return removed


NPZ_LEVEL = 1
"""Deflate level of the compressed members of a .npz (:func:`save_npz`): level 1 is ~2x faster to
write than numpy's default (6) and as small (measured on TOSCA pair records)."""


def save_npz(path: str | Path, compressed: bool = False, **arrays: np.ndarray) -> None:
    """``np.savez`` to ``path``, atomically. ``compressed``: integer and boolean members deflated at
    :data:`NPZ_LEVEL` (indices shrink ~4x), floating-point members stored as they are (deflate saves
    ~9 % on float64 coordinates and weights for ~20 ms of CPU per TOSCA pair record); ``np.load``
    reads both, and the file's bytes depend only on the arrays (fixed zip timestamps)."""
    import zipfile

    with atomic_path(path, suffix=".tmp.npz") as tmp:
        if not compressed:
            np.savez(tmp, **arrays)
            return
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=NPZ_LEVEL) as z:
            for key, value in arrays.items():
                value = np.asanyarray(value)
                member: str | zipfile.ZipInfo = f"{key}.npy"
                if value.dtype.kind in "fc":
                    member = zipfile.ZipInfo(member)  # default timestamp 1980-01-01, as numpy's
                    member.compress_type = zipfile.ZIP_STORED
                with z.open(member, "w", force_zip64=True) as fh:
                    np.lib.format.write_array(fh, value, allow_pickle=False)


def save_npy(path: str | Path, array: np.ndarray) -> int:
    """``np.save`` to ``path``, atomically, as one large buffered write (numpy's ``tofile`` on the open
    file for a contiguous array); returns the bytes written."""
    array = np.ascontiguousarray(array)
    with atomic_path(path, suffix=".tmp.npy") as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, array, allow_pickle=False)
    return Path(path).stat().st_size


def link_or_copy(source: str | Path, path: str | Path) -> bool:
    """Make ``path`` a hard link of the file ``source`` (same bytes, no new disk space), atomically;
    where the file system refuses (another device, no hard links, link limit) a copy instead. Returns
    whether it linked. The two names then share one file: never write into either in place."""
    with atomic_path(path, suffix=".tmp.link") as tmp:
        tmp.unlink()
        try:
            os.link(source, tmp)
            linked = True
        except OSError as exc:
            if exc.errno not in (errno.EXDEV, errno.EPERM, errno.EMLINK, errno.ENOTSUP, errno.EOPNOTSUPP):
                raise
            shutil.copyfile(source, tmp)
            linked = False
    return linked


def write_bytes(path: str | Path, data: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text(path: str | Path, text: str) -> None:
    """UTF-8 text, newlines written as given."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
