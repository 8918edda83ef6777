"""Content digests of the files a run reads from outside ``results`` (the datasets' mesh files, the
annotation folder): what the workflow's rerun decisions follow for them, instead of modification times.

The rules pass these digests as ``params``, so a file replaced by other content with an older time
(``cp -p``, an archive re-extracted with its stored times) still reruns the jobs that read it:
:func:`check_input_files` for the dataset check, catalog and manifest, a mesh file's digest for its
remesh job, :func:`annotation_input_files` (and, without remeshing, the pairs' meshes) for chunk jobs.
Files a rule of the same run writes are left out. Hashing is cached (:class:`DigestCache`,
``results/cache/input_digests.json``) on each file's size, times and inode. Why each: docs/design/workflow.md.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
from collections.abc import Iterable
from pathlib import Path

from becos.atomic import write_text
from becos.errors import DiskFullError
from becos.workflow.options import SourceOptions

DIGEST_CACHE_VERSION = 1
"""Bumped when the cache file's layout changes (an older cache is then ignored)."""

ANNOTATION_INPUTS = (
    "config/*",
    "precomputed_corr_templates/*",
    "precomputed_chirality_templates/*",
    "corres_comp/default_faces/*",
    "data/*.json",
)
"""Glob patterns, relative to the annotation folder, of the files the dataset check and the chunk jobs
read from it (:mod:`becos.sources.annotations`); the published views (``precomputed_triangle_ids``) are added
for ``original_settings``."""


def _stat_key(st: os.stat_result) -> list[int]:
    return [st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino]


class DigestCache:
    """SHA-256 digests of files, cached on (size, mtime, ctime, inode) in a JSON file.

    ``path``: the cache file (None: kept in memory only). Reading a damaged or older cache starts an
    empty one; :meth:`save` writes it atomically when something was hashed, and skips a results folder
    that cannot be written (the digests are then computed again next time).
    """

    def __init__(self, path: str | Path | None):
        self.path = None if path is None else Path(path)
        self._entries: dict[str, list] = {}
        self._dirty = False
        if self.path is not None:
            try:
                raw = json.loads(self.path.read_text(encoding="utf-8"))
                if raw.get("version") == DIGEST_CACHE_VERSION and isinstance(raw.get("files"), dict):
                    self._entries = raw["files"]
            except (OSError, ValueError, AttributeError):
                pass

    def file(self, path: str | Path) -> str:
        """64 hex digits of SHA-256 of the file's content (symbolic links followed), or a stand-in that
        names what is there instead (``missing``, ``not a regular file``), which the dataset check
        reports itself."""
        path = Path(path).absolute()
        try:
            st = os.stat(path)
        except OSError:
            return "missing"
        if not stat.S_ISREG(st.st_mode):
            return "not a regular file"
        key = _stat_key(st)
        cached = self._entries.get(str(path))
        if cached is not None and cached[:4] == key:
            return cached[4]
        try:
            with open(path, "rb") as fh:
                value = hashlib.file_digest(fh, "sha256").hexdigest()
        except OSError:
            return "unreadable"
        self._entries[str(path)] = [*key, value]
        self._dirty = True
        return value

    def files(self, paths: Iterable[str | Path]) -> str:
        """16 hex digits over the sorted (path as given, content digest) pairs of ``paths``: changes when
        a file is added, removed, renamed or its content changes, not when only its times do (nor when a
        working folder whose config names relative paths is copied or moved)."""
        listing = sorted((str(p), self.file(p)) for p in paths)
        text = json.dumps(listing, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def save(self) -> None:
        """Write the cache if a file was hashed since it was read (atomically; best effort)."""
        if self.path is None or not self._dirty:
            return
        # entries of files that are gone are dropped, so the cache does not grow with renamed trees
        live = {p: v for p, v in self._entries.items() if os.path.lexists(p)}
        try:
            write_text(self.path, json.dumps({"version": DIGEST_CACHE_VERSION, "files": live}) + "\n")
            self._dirty = False
        except (OSError, DiskFullError):
            pass  # a read-only or full results folder: hash again next time


def generated_folders(config) -> list[Path]:
    """Folders whose files a rule of the run writes: the synthetic collection, a fetched annotation
    folder, the class folders of the DeformingThings4D preparation jobs and downloaded dataset folders.
    ``config``: a resolved config or its :class:`SourceOptions` (so for the functions below)."""
    from becos.sources.datasets import DatasetSpec
    from becos.sources.dt4d import preparation_plan

    src = SourceOptions.of(config)
    folders = [Path(src.synthetic["out"])] if src.synthetic["enabled"] else []
    if src.annotations_archive:
        folders.append(Path(src.annotations))
    folders += [Path(job.stamp).parent for job in preparation_plan(src.data_dir, src.datasets, src.annotations)]
    for name in src.download:
        folders.append(Path(src.data_dir) / DatasetSpec.load(name).folder)
    return folders


def _outside(folders: list[Path]):
    """A predicate: whether a path lies outside every folder of ``folders``."""
    skip = [p.absolute() for p in folders]

    def outside(path: Path) -> bool:
        path = path.absolute()
        return not any(path == g or g in path.parents for g in skip)

    return outside


def dataset_input_files(config) -> list[Path]:
    """Each enabled dataset's mesh files that no job of the run writes (:func:`generated_folders`), as
    :meth:`becos.sources.datasets.DatasetSpec.list_names` finds them, non-regular entries included (so that the
    check runs again and names them). A dataset folder that does not exist contributes nothing (the
    check reports it)."""
    from becos.errors import BecosError
    from becos.sources.datasets import DatasetSpec

    src = SourceOptions.of(config)
    outside = _outside(generated_folders(src))
    out: list[Path] = []
    data_dir = Path(src.data_dir)
    for name in src.datasets:
        try:
            spec = DatasetSpec.load(name)
        except BecosError:  # an unknown or broken registry entry: the check names it
            continue
        folder = data_dir / spec.folder
        if outside(folder):
            out += [p for p in folder.glob(spec.mesh_glob) if outside(p)]
    return sorted(set(out))


def annotation_input_files(config) -> list[Path]:
    """The annotation folder's :data:`ANNOTATION_INPUTS` (none when a job of the run fetches the folder
    or the synthetic collection writes it)."""
    src = SourceOptions.of(config)
    root = Path(src.annotations)
    if not _outside(generated_folders(src))(root):
        return []
    patterns = list(ANNOTATION_INPUTS)
    if src.original_settings:
        patterns.append("precomputed_triangle_ids/*/*")
    return sorted({p for pattern in patterns for p in root.glob(pattern) if not p.is_dir()})


def check_input_files(config) -> list[Path]:
    """Every file the dataset check reads that no job of the run writes: :func:`dataset_input_files` and
    :func:`annotation_input_files`."""
    src = SourceOptions.of(config)
    return sorted({*dataset_input_files(src), *annotation_input_files(src)})
