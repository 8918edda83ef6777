"""Fetching and unpacking dataset archives: resumable download, checksum, safe extraction, atomic install.

:func:`fetch` streams a URL (``http``, ``https``, ``file``) into a partial file that a later call resumes
(``Range`` with ``If-Range``), and compares the SHA-256 with the pinned digest. :func:`extract_archive`
unpacks a zip or tar after refusing unsafe members (absolute paths, ``..``, links leaving the archive,
devices). :func:`download_dataset` installs a dataset's public archive (``source.archive`` of its YAML)
and :func:`fetch_annotations` a pinned annotation archive, each under its final name only once complete,
with a ``.becos-download.json`` record. Every failure is a :class:`DownloadError` naming the URL or
file, the problem and the fix. The rules in detail: docs/design/data.md.
"""

from __future__ import annotations

import hashlib
import http.client
import json
import logging
import os
import posixpath
import re
import shutil
import stat
import sys
import tarfile
import tempfile
import time
import urllib.error
import urllib.parse
import urllib.request
import zipfile
from pathlib import Path

from becos.atomic import remove_stale_temporaries, write_text
from becos.errors import BecosError, ConfigError
from becos.sources.datasets import ARCHIVE_SCHEMES, DatasetArchive, DatasetSpec

log = logging.getLogger(__name__)

RECORD_NAME = ".becos-download.json"
"""Record written into a downloaded folder: ``{"url", "sha256", "sha256_pinned", ...}`` for a dataset,
``{"url", "sha256", "fetched_at"}`` for the annotation folder (:func:`fetch_annotations`)."""

CHUNK_BYTES = 1 << 20
"""Largest block read from the network and written to the partial file at a time."""

TIMEOUT_S = 60.0
"""Seconds without data before a connection counts as broken."""


class DownloadError(ConfigError):
    """A download or an archive failed. The message reads ``<url or file>: <problem>. Fix: <fix>``."""

    def __init__(self, where: str | Path, problem: str, fix: str):
        self.where = str(where)
        self.problem = problem
        self.fix = fix
        super().__init__(f"{self.where}: {problem}. Fix: {fix}")


class ChecksumMismatchError(DownloadError):
    """The archive (or the folder extracted from one) is not the pinned one."""


class UnsafeArchiveError(DownloadError):
    """An archive member would be written outside the extraction folder, or is a link or device."""


class ArchiveLayoutError(DownloadError):
    """The archive does not yield the files the dataset needs."""


class CorruptArchiveError(DownloadError):
    """The downloaded file is not a readable zip or tar archive."""


# --- download --------------------------------------------------------------------------------------
def partial_path(target: str | Path) -> Path:
    """The partial file of a download whose result belongs at ``target``: ``.<name>.part`` beside it."""
    target = Path(target)
    return target.parent / f".{target.name}.part"


def _sidecar(part: Path) -> Path:
    return part.with_name(part.name + ".json")


def discard_partial(part: str | Path) -> None:
    """Remove a partial file and its sidecar (after a successful install or a failed checksum)."""
    part = Path(part)
    part.unlink(missing_ok=True)
    _sidecar(part).unlink(missing_ok=True)


def _read_json(path: Path) -> dict | None:
    try:
        value = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return value if isinstance(value, dict) else None


def _open(url: str, offset: int, validator: str | None, fix: str):
    """The response to GET ``url`` (from byte ``offset`` when > 0); None when the server says the
    range is not satisfiable (HTTP 416)."""
    request = urllib.request.Request(url, headers={"User-Agent": "becos-download"})
    if offset:
        request.add_header("Range", f"bytes={offset}-")
        if validator:
            request.add_header("If-Range", validator)
    try:
        return urllib.request.urlopen(request, timeout=TIMEOUT_S)  # noqa: S310 - scheme checked by the caller
    except urllib.error.HTTPError as exc:
        exc.close()
        if exc.code == 416 and offset:
            return None
        raise DownloadError(url, f"the server answered HTTP {exc.code} ({exc.reason})", fix) from None
    except (urllib.error.URLError, OSError, ValueError) as exc:
        reason = getattr(exc, "reason", None) or exc
        if isinstance(reason, OSError) and reason.strerror:
            reason = reason.strerror  # "Connection refused", not "[Errno 111] Connection refused"
        raise DownloadError(url, f"cannot download ({reason})", fix) from None


def _content_range_start(value: str | None) -> tuple[int, int | None] | None:
    """(first byte, total or None) of a ``Content-Range: bytes a-b/total`` header."""
    m = re.fullmatch(r"\s*bytes\s+(\d+)-(\d+)/(\d+|\*)\s*", value or "")
    if not m:
        return None
    return int(m.group(1)), None if m.group(3) == "*" else int(m.group(3))


def _start(url: str, offset: int, meta: dict, fix: str):
    """(response, offset, total size or None) of a transfer continuing ``part`` at ``offset`` bytes;
    offset 0 when the download starts again (the server cannot or will not resume)."""
    validator = (meta.get("etag") or meta.get("last_modified")) if offset else None
    response = _open(url, offset, validator, fix)
    if response is None:  # 416: the part is no prefix of the current file
        print(f"download: the server cannot resume {url} at byte {offset}; starting again", file=sys.stderr)
        return _start(url, 0, meta, fix)
    status = getattr(response, "status", None) or 200  # file:// has no status
    length = int(response.headers.get("Content-Length") or 0) or None
    if not offset:
        return response, 0, length
    if status != 206:
        print(
            f"download: the server ignored the resume request (HTTP {status}); starting {url} again from byte 0",
            file=sys.stderr,
        )
        return response, 0, length
    got = _content_range_start(response.headers.get("Content-Range"))
    if got is None or got[0] != offset:
        print(
            f"download: asked {url} for the bytes from {offset}, got the range "
            f"{response.headers.get('Content-Range')!r}; starting again",
            file=sys.stderr,
        )
        response.close()
        return _start(url, 0, meta, fix)
    print(f"download: resuming {url} at byte {offset}", file=sys.stderr)
    return response, offset, got[1] if got[1] is not None else (offset + length if length else None)


def _hash_file(path: Path, h) -> None:
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(CHUNK_BYTES), b""):
            h.update(block)


def fetch(
    url: str,
    part: str | Path,
    sha256: str | None = None,
    *,
    label: str | None = None,
    fix: str = "check the URL and the network connection, then run again",
    pinned_in: str | None = None,
    progress: bool = True,
) -> str:
    """Make ``part`` hold the complete download of ``url``; return its SHA-256 (hex).

    Resumes ``part`` if it holds the start of the same URL (``Range``); restarts when the server
    answers the whole file. An interruption keeps ``part`` (and its sidecar) for the next call.

    Args:
        url: ``http(s)://`` or ``file://`` URL.
        part: the partial file (:func:`partial_path`); its sidecar ``<part>.json`` is kept beside it.
        sha256: pinned digest (lowercase hex) or None.
        label: name on the progress bar (default: the URL's file name).
        fix: the fix named when the server cannot be reached or answers an error.
        pinned_in: where ``sha256`` is pinned (named in the mismatch error).
        progress: show a progress bar on stderr.

    Raises:
        DownloadError: unreachable server, HTTP error, broken or short transfer (``part`` kept).
        ChecksumMismatchError: the complete file's digest differs from ``sha256`` (``part`` removed).
    """
    part = Path(part)
    scheme = urllib.parse.urlparse(url).scheme.lower()
    if scheme not in ARCHIVE_SCHEMES:
        raise DownloadError(url, "is not an http(s):// or file:// URL", "give the full URL")
    part.parent.mkdir(parents=True, exist_ok=True)
    meta = _read_json(_sidecar(part)) or {}
    offset = part.stat().st_size if part.is_file() else 0
    if offset and meta.get("url") != url:
        print(
            f"download: the partial file {part} belongs to another URL ({meta.get('url')}); starting {url} from byte 0",
            file=sys.stderr,
        )
        offset = 0
    response, mode, total = None, "wb", None
    if not (offset and meta.get("total") == offset):  # else complete already (killed before it was unpacked)
        response, offset, total = _start(url, offset, meta, fix)
        mode = "ab" if offset else "wb"
    if response is not None:
        _transfer(response, url, part, mode, offset, total, label or Path(url).name, progress)
    h = hashlib.sha256()
    _hash_file(part, h)
    actual = h.hexdigest()
    if sha256 is not None and actual != sha256.lower():
        discard_partial(part)
        where = f" (pinned in {pinned_in})" if pinned_in else ""
        raise ChecksumMismatchError(
            url,
            f"the downloaded file has SHA-256 {actual}, expected {sha256.lower()}{where}; nothing was installed",
            "check that the URL and the pinned digest belong together (the file may have "
            "changed upstream, or a mirror serves another file)",
        )
    return actual


def _transfer(
    response, url: str, part: Path, mode: str, offset: int, total: int | None, label: str, progress: bool
) -> None:
    """Stream ``response`` (of ``url``, from byte ``offset`` of ``total`` or None) into ``part``
    (``mode`` ``"ab"`` to append, ``"wb"`` to start again), after writing its sidecar (URL, ``ETag``,
    ``Last-Modified``, total); a progress bar named ``label`` on stderr when ``progress``. Every block
    is flushed, so what arrived stays on disk if the process is killed.

    Raises:
        DownloadError: the transfer broke off or ended short (``part`` kept: a rerun resumes it).
    """
    from tqdm import tqdm

    with response:
        headers = response.headers
        write_text(
            _sidecar(part),
            json.dumps(
                {
                    "url": url,
                    "etag": headers.get("ETag"),
                    "last_modified": headers.get("Last-Modified"),
                    "total": total,
                }
            )
            + "\n",
        )
        read = getattr(response, "read1", response.read)
        done = offset
        tty = sys.stderr.isatty()
        with (
            open(part, mode) as fh,
            tqdm(
                total=total,
                initial=offset,
                unit="B",
                unit_scale=True,
                unit_divisor=1024,
                desc=label,
                file=sys.stderr,
                disable=not progress,
                mininterval=0.5 if tty else 10.0,
                ascii=not tty,
            ) as bar,
        ):
            try:
                for block in iter(lambda: read(CHUNK_BYTES), b""):
                    fh.write(block)
                    fh.flush()  # what arrived stays on disk if the process is killed
                    done += len(block)
                    bar.update(len(block))
            except (urllib.error.URLError, http.client.HTTPException, OSError, ValueError) as exc:
                raise DownloadError(
                    url,
                    f"the download broke off after {done} of {total or '?'} bytes ({exc})",
                    f"run again: it resumes from {part}",
                ) from None
        if total is not None and done != total:
            raise DownloadError(
                url, f"the download ended after {done} of {total} bytes", f"run again: it resumes from {part}"
            )


# --- extraction ------------------------------------------------------------------------------------
_UNSAFE_FIX = "the archive is unsafe and nothing was extracted; check the URL and its pinned SHA-256"
_EXTRACT_OS_FIX = "check the free space and permissions there, then run again (the downloaded archive is kept)"


def _safe_member_name(name: str, archive: str) -> str:
    """The member's relative path (``/``-separated); raises for absolute paths and ``..``."""
    norm = name.replace("\\", "/")
    if norm.startswith("/") or re.match(r"^[A-Za-z]:", norm):
        raise UnsafeArchiveError(archive, f"member '{name}' has an absolute path", _UNSAFE_FIX)
    parts = [p for p in norm.split("/") if p not in ("", ".")]
    if ".." in parts:
        raise UnsafeArchiveError(archive, f"member '{name}' points outside the archive ('..')", _UNSAFE_FIX)
    return "/".join(parts)


def _extract_tar(path: Path, out: Path, label: str) -> None:
    try:
        tar = tarfile.open(path, "r:*")
    except (tarfile.TarError, OSError) as exc:
        raise CorruptArchiveError(label, f"not a readable zip or tar archive ({exc})", "check the URL") from None
    with tar:
        members = tar.getmembers()
        for m in members:
            name = _safe_member_name(m.name, label)
            if m.issym() or m.islnk():
                target = m.linkname.replace("\\", "/")
                if target.startswith("/"):
                    raise UnsafeArchiveError(label, f"link '{m.name}' -> '{m.linkname}' is absolute", _UNSAFE_FIX)
                base = posixpath.dirname(name) if m.issym() else ""
                resolved = posixpath.normpath(posixpath.join(base, target))
                if resolved == ".." or resolved.startswith("../"):
                    raise UnsafeArchiveError(
                        label, f"link '{m.name}' -> '{m.linkname}' escapes the archive", _UNSAFE_FIX
                    )
            elif not (m.isfile() or m.isdir()):
                raise UnsafeArchiveError(label, f"member '{m.name}' is a device or pipe", _UNSAFE_FIX)
        try:
            tar.extractall(out, members=members, filter="data")
        except tarfile.TarError as exc:
            raise CorruptArchiveError(
                label, f"extraction failed ({exc})", "the archive is corrupt; download it again"
            ) from None
        except OSError as exc:
            raise DownloadError(label, f"extraction into {out} failed ({exc})", _EXTRACT_OS_FIX) from None


def _extract_zip(path: Path, out: Path, label: str) -> None:
    try:
        with zipfile.ZipFile(path) as zf:
            for info in zf.infolist():
                _safe_member_name(info.filename, label)
                if stat.S_ISLNK(info.external_attr >> 16):
                    raise UnsafeArchiveError(label, f"member '{info.filename}' is a symbolic link", _UNSAFE_FIX)
            zf.extractall(out)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError) as exc:
        raise CorruptArchiveError(
            label, f"not a readable zip archive ({exc})", "the archive is corrupt; download it again"
        ) from None
    except OSError as exc:
        raise DownloadError(label, f"extraction into {out} failed ({exc})", _EXTRACT_OS_FIX) from None


def extract_archive(path: str | Path, out: str | Path, label: str) -> None:
    """Extract the zip or tar archive ``path`` (any compression tarfile reads) into folder ``out``.

    Every member is checked before anything is written (absolute paths, ``..``, symbolic links in
    zips, links leaving a tar archive, devices). ``label`` names the archive in errors (its URL).

    Raises:
        UnsafeArchiveError: a refused member. CorruptArchiveError: unreadable archive. DownloadError: the
            files cannot be written (disk full, permissions).
    """
    path, out = Path(path), Path(out)
    if zipfile.is_zipfile(path):
        _extract_zip(path, out, label)
    else:
        _extract_tar(path, out, label)


# --- datasets --------------------------------------------------------------------------------------
def dataset_archive(name: str, config_dir=None):
    """(spec, archive) of a dataset that has a public archive.

    Raises:
        ConfigError: unknown dataset, or one that cannot be downloaded automatically (the message says
            where to get it by hand and where to put it).
    """
    spec = DatasetSpec.load(name, config_dir)
    if spec.archive is None:
        raise ConfigError(
            f"dataset '{name}' ({spec.title}) cannot be downloaded automatically: it needs an account, "
            f"a password or a request form ({spec.source.get('licence', 'see its licence')}). "
            f"Fix: get it by hand ({spec.download_help()}), place it so that "
            f"<data_dir>/{spec.folder} holds its {spec.file_type.upper()} files, and remove '{name}' "
            f"from `download`"
        )
    return spec, spec.archive


def archive_url(name: str, overrides: dict | None = None, config_dir=None) -> str:
    """The URL ``name``'s archive is downloaded from: ``overrides[name]`` (config key ``download_urls``,
    a mirror) or the YAML's ``source.archive.url``."""
    if overrides and overrides.get(name):
        return str(overrides[name])
    return dataset_archive(name, config_dir)[1].url


def download_config_problems(
    download: list[str], download_urls: dict, datasets: list[str], config_dir=None
) -> list[str]:
    """Problems of the workflow keys ``download`` (dataset names) and ``download_urls`` (name -> URL), given
    the enabled ``datasets`` (checked with the config)."""
    wanted = list(download or [])
    urls = dict(download_urls or {})
    enabled = set(datasets or [])
    problems = []
    for name in wanted:
        if name not in enabled:
            problems.append(
                f"download lists '{name}', which is not in `datasets`: add it to `datasets` or remove it "
                f"from `download`"
            )
        try:
            dataset_archive(name, config_dir)
        except BecosError as exc:
            problems.append(f"download: {exc}")
    for name in urls:
        if name not in wanted:
            problems.append(
                f"download_urls names '{name}', which is not in `download`: add it to `download` or remove the URL"
            )
    return problems


def _matches(root: Path, pattern: str) -> list[Path]:
    return sorted(p for p in root.glob(pattern) if p.is_file() and not p.is_symlink())


def _layout_problem(root: Path, pattern: str) -> str:
    """What the extracted ``root`` holds instead of ``pattern`` (for the layout error)."""
    top = sorted(p.name + ("/" if p.is_dir() else "") for p in root.iterdir())
    suffix = pattern.rsplit(".", 1)[-1] if "." in pattern else ""
    elsewhere = sorted(str(p.relative_to(root)) for p in root.rglob(f"*.{suffix}"))[:3] if suffix else []
    text = f"its top level holds {top[:8]}{' ...' if len(top) > 8 else ''}"
    if elsewhere:
        text += f"; {suffix} files lie at e.g. {elsewhere}"
    return text


def _record(folder: Path) -> dict | None:
    return _read_json(folder / RECORD_NAME)


def download_dataset(
    name: str, data_dir: str | Path, url: str | None = None, *, config_dir=None, progress: bool = True
) -> dict:
    """Download and install dataset ``name``'s public archive below ``data_dir`` (docs/design/data.md).

    Nothing is downloaded when ``<data_dir>/<extract_to>`` already yields the dataset's files (a
    previous download, or the user's own copy). A folder under the final name is never half
    extracted: the archive is unpacked beside it and renamed into place.

    Args:
        name: dataset name (``kids``, ``shrec20``).
        data_dir: the data root.
        url: another URL of the same archive (a mirror); default the YAML's ``source.archive.url``.
        config_dir: dataset registry folder (default ``config/datasets`` or ``$BECOS_DATASETS_DIR``).
        progress: progress bar on stderr.

    Returns:
        ``{"dataset", "folder", "url", "sha256", "sha256_pinned", "downloaded", "files"}``; ``downloaded``
        is False when the data was already there (``url``/``sha256`` then come from its record, or None).

    Raises:
        DownloadError (ChecksumMismatchError, UnsafeArchiveError, ArchiveLayoutError): see :func:`fetch`,
        :func:`extract_archive`; the archive lacks the expected files; the folder exists but holds
        other things, or was recorded from another archive than the pinned one.
        ConfigError: the dataset has no public archive.
    """
    spec, archive = dataset_archive(name, config_dir)
    url = url or archive.url
    data_dir = Path(data_dir).expanduser().absolute()
    dest = data_dir / archive.extract_to
    yaml_key = f"source.archive.sha256 in {spec.path}"
    installed = _installed(name, spec, archive, dest, yaml_key)
    if installed is not None:
        return installed
    fix = (
        f"check the URL and the network connection; behind a mirror or proxy set `download_urls: {{{name}: URL}}` "
        f"in the config (or --url); or get it by hand: {spec.source.get('instructions', spec.title)}"
    )
    part = partial_path(data_dir / f"{archive.extract_to}.{Path(urllib.parse.urlparse(url).path).name or 'archive'}")
    pinned = archive.sha256
    digest = fetch(url, part, pinned, label=f"{name} {Path(url).name}", fix=fix, pinned_in=yaml_key, progress=progress)
    result = _install(part, url, digest, name, spec, archive, dest)
    discard_partial(part)
    print(
        f"download-dataset: {name}: installed {dest} ({result['files']} files {archive.expected}, SHA-256 {digest})",
        file=sys.stderr,
    )
    if pinned is None:
        log.warning(
            "download-dataset: %s: the archive's SHA-256 is not pinned; this download has SHA-256 %s "
            "(recorded in %s). Pin it so that later downloads are checked: set %s to %s",
            name,
            digest,
            dest / RECORD_NAME,
            yaml_key,
            digest,
        )
    return result


def _installed(name: str, spec: DatasetSpec, archive: DatasetArchive, dest: Path, yaml_key: str) -> dict | None:
    """:func:`download_dataset`'s result when ``dest`` already yields the dataset's files (nothing to
    download; url and sha256 from its record, or None), else None when it may be installed there.

    Raises:
        ChecksumMismatchError: ``dest`` was recorded from another archive than the pinned one.
        ArchiveLayoutError: ``dest`` holds other things and was not made by becos.
    """
    expected, pinned = archive.expected, archive.sha256
    record = _record(dest) if dest.is_dir() else None
    if pinned is not None and record is not None and record.get("sha256") not in (None, pinned):
        raise ChecksumMismatchError(
            dest / RECORD_NAME,
            f"{dest} was extracted from an archive with SHA-256 "
            f"{record.get('sha256')} ({record.get('url')}), but {yaml_key} pins {pinned}",
            f"remove {dest} to download the pinned archive, or pin {record.get('sha256')} if you trust that archive",
        )
    present = _matches(dest, expected) if dest.is_dir() else []
    if present:
        print(
            f"download-dataset: {name}: {dest} already holds {len(present)} files {expected}; nothing to download",
            file=sys.stderr,
        )
        return {
            "dataset": name,
            "folder": str(dest),
            "url": (record or {}).get("url"),
            "sha256": (record or {}).get("sha256"),
            "sha256_pinned": (record or {}).get("sha256_pinned", False),
            "downloaded": False,
            "files": len(present),
        }
    if dest.exists() and record is None and (not dest.is_dir() or any(dest.iterdir())):
        raise ArchiveLayoutError(
            dest,
            f"exists but holds no {expected} and was not made by `becos download-dataset` (no {RECORD_NAME})",
            f"move {dest} away (becos never overwrites a folder it did not "
            f"make), or extract the {spec.title} archive there yourself",
        )
    return None


def _install(
    part: Path, url: str, digest: str, name: str, spec: DatasetSpec, archive: DatasetArchive, dest: Path
) -> dict:
    """Extract the downloaded archive ``part`` (of ``url``, SHA-256 ``digest``) into a temporary folder
    beside ``dest``, check that it yields the dataset's files, write the record and rename the folder
    into place (a folder under the final name is always complete). Returns :func:`download_dataset`'s
    result.

    Raises:
        UnsafeArchiveError, CorruptArchiveError, ArchiveLayoutError: ``part`` is discarded (complete but
            unusable: a rerun must fetch it again); nothing is installed.
    """
    expected = archive.expected
    remove_stale_temporaries(dest.parent, [dest.name])  # extraction folders of killed runs
    work = Path(tempfile.mkdtemp(dir=dest.parent, prefix=f".{dest.name}.", suffix=".tmp-extract"))
    try:
        out = work / dest.name
        out.mkdir()
        try:
            extract_archive(part, out, url)
            found = _matches(out, expected)
            if not found:
                raise ArchiveLayoutError(
                    url,
                    f"the archive does not yield the {spec.title} files: no {expected} "
                    f"inside ({_layout_problem(out, expected)}); nothing was installed at {dest}",
                    f"check that the URL points at the {spec.title} archive (download_urls / "
                    f"source.archive.url in {spec.path}); becos expects "
                    f"{archive.extract_to}/{expected} below the data root",
                )
        except (UnsafeArchiveError, CorruptArchiveError, ArchiveLayoutError):
            discard_partial(part)  # complete but unusable: a rerun must fetch it again
            raise
        result = {
            "dataset": name,
            "folder": str(dest),
            "url": url,
            "sha256": digest,
            "sha256_pinned": archive.sha256 is not None,
            "downloaded": True,
            "files": len(found),
            "bytes": part.stat().st_size,
            "downloaded_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }
        write_text(out / RECORD_NAME, json.dumps(result, indent=2) + "\n")
        if dest.exists():  # an empty folder, or our own earlier download that lost its files: swap it out
            os.rename(dest, work / "previous")
        os.rename(out, dest)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return result


# --- the annotation folder ------------------------------------------------------------------------
def fetch_annotations(url: str, sha256: str, dest: str | Path) -> Path:
    """Download the pinned annotation archive ``url`` and install it as folder ``dest``.

    Steps: stream to a partial file beside ``dest`` (:func:`becos.sources.download.fetch`: progress bar, an
    interrupted download resumes), compare its SHA-256 with
    ``sha256``, extract it (tar, tar.gz/tgz, tar.bz2/xz or zip; absolute paths, ``..`` members, links
    leaving the archive and device files are rejected), drop a single top-level folder, write
    ``dest/.becos-download.json`` (url, digest) and rename the result to ``dest``. If ``dest`` already
    holds a download with this digest, nothing is done. A previous download with another digest is
    replaced; a folder without the marker is never overwritten.

    Returns:
        ``dest`` (resolved).

    Raises:
        ConfigError: bad digest text, download failure, checksum mismatch (names both digests;
            ``dest`` is left untouched), unsafe or unreadable archive, ``dest`` is someone else's folder.
    """
    dest = Path(dest).expanduser().resolve()
    expected = str(sha256).strip().lower()
    if not re.fullmatch(r"[0-9a-f]{64}", expected):
        raise ConfigError(
            f"'{sha256}' is not a SHA-256 digest (64 hex digits). Fix: pin the archive's digest (sha256sum ARCHIVE)"
        )
    marker = _record(dest) if dest.is_dir() else None
    if marker is not None and marker.get("sha256") == expected:
        print(f"fetch-annotations: {dest} already holds {expected[:12]}...; nothing to do", file=sys.stderr)
        return dest
    if dest.exists() and marker is None and (not dest.is_dir() or any(dest.iterdir())):
        raise ConfigError(
            f"{dest} already exists and was not made by `becos fetch-annotations` (no {RECORD_NAME}). "
            f"Fix: choose another --dest, or remove {dest} yourself"
        )
    dest.parent.mkdir(parents=True, exist_ok=True)
    part = partial_path(dest.parent / f"{dest.name}.{Path(urllib.parse.urlparse(url).path).name or 'archive'}")
    fetch(
        url,
        part,
        expected,
        label="annotations",
        fix="check the URL and the network connection, or download it by hand and pass a file:// URL",
        pinned_in="the annotations_archive config / --sha256",
    )
    remove_stale_temporaries(dest.parent, [dest.name])  # extraction folders of killed fetches
    work = Path(tempfile.mkdtemp(dir=dest.parent, prefix=f".{dest.name}.", suffix=".tmp-fetch"))
    try:
        out = work / "extract"
        out.mkdir()
        label = f"annotation archive {url}"
        try:
            extract_archive(part, out, label)
        except (UnsafeArchiveError, CorruptArchiveError):
            discard_partial(part)  # complete but unusable: a rerun must fetch it again
            raise
        discard_partial(part)
        entries = [p for p in out.iterdir() if p.name != "__MACOSX"]
        if not entries:
            raise ConfigError(f"{label} is empty. Fix: check the URL")
        root = entries[0] if len(entries) == 1 and entries[0].is_dir() and not entries[0].is_symlink() else out
        write_text(
            root / RECORD_NAME,
            json.dumps({"url": url, "sha256": expected, "fetched_at": time.strftime("%Y-%m-%dT%H:%M:%S%z")}, indent=2)
            + "\n",
        )
        os.chmod(root, 0o755)
        old = None
        if dest.exists():  # a previous download (other digest) or an empty folder: swap it out
            old = work / "previous"
            os.rename(dest, old)
        try:
            os.rename(root, dest)
        except OSError:
            done = _record(dest) if dest.is_dir() else None
            if done is not None and done.get("sha256") == expected:  # a parallel fetch won
                return dest
            raise
        print(f"fetch-annotations: installed {dest}", file=sys.stderr)
        return dest
    finally:
        shutil.rmtree(work, ignore_errors=True)
