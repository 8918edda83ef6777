"""Downloading the public dataset archives (KIDS, SHREC'20) from a real HTTP server on loopback.

Stand-in archives with the published inner layout (``off/*.off`` for KIDS,
``SHREC20b_hires/models/*.obj`` for SHREC'20; tiny valid meshes) are served by
``tests/archive_server.py``: fresh download, resume after a kill and after a dropped connection, a
server that ignores ``Range``, checksum records and mismatches, wrong layouts, unsafe members,
network errors, the config keys, and the workflow fetching KIDS before its dataset check.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest
import yaml
from archive_server import ArchiveServer
from snakemake_cmd import snakemake_cmd
from standin import SHREC20_MODELS

from becos.cli import main as becos_main
from becos.errors import ConfigError, InputFileError
from becos.sources.check import DatasetCheckError, check_datasets
from becos.sources.datasets import CONFIG_DIR, DatasetSpec
from becos.sources.download import (
    RECORD_NAME,
    ArchiveLayoutError,
    ChecksumMismatchError,
    CorruptArchiveError,
    DownloadError,
    UnsafeArchiveError,
    download_dataset,
    partial_path,
)
from becos.workflow import resolve_config

REPO = Path(__file__).resolve().parents[1]
KIDS_NAMES = [f"000{kid}.isometry.{i}" for kid in (1, 2) for i in range(1, 16)] + ["0001.null.0", "0002.null.0"]


# --- stand-in archives -----------------------------------------------------------------------------
def _off(i: int) -> bytes:
    """A tetrahedron as OFF, its apex moved by ``i`` (so every file differs)."""
    return (f"OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 {1 + i / 10:.1f}\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 2 0 3\n").encode()


def _obj(i: int) -> bytes:
    return (f"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 {1 + i / 10:.1f}\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 3 1 4\n").encode()


def kids_members() -> dict[str, bytes]:
    """What kids.zip holds: ``off/<name>.off`` for the 32 KIDS shapes."""
    return {f"off/{n}.off": _off(i) for i, n in enumerate(KIDS_NAMES)}


def shrec_members() -> dict[str, bytes]:
    return {f"SHREC20b_hires/models/{n}.obj": _obj(i) for i, n in enumerate(SHREC20_MODELS)}


def zip_bytes(members: dict[str, bytes], links: dict[str, str] | None = None) -> bytes:
    """A zip of ``members`` (name -> content), names written as given (``..`` and ``/`` included), plus
    symbolic-link members ``links`` (name -> target)."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(zipfile.ZipInfo(name, (2024, 1, 1, 0, 0, 0)), data)
        for name, target in (links or {}).items():
            info = zipfile.ZipInfo(name, (2024, 1, 1, 0, 0, 0))
            info.external_attr = 0o120777 << 16
            zf.writestr(info, target)
    return buffer.getvalue()


def sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


@pytest.fixture(autouse=True)
def unpinned_registry(tmp_path, monkeypatch) -> Path:
    """The dataset registry with the KIDS and SHREC'20 archives unpinned (``$BECOS_DATASETS_DIR``, also
    seen by subprocesses): the stand-in archives are not the real ones, whatever the repository pins."""
    folder = tmp_path / "registry"
    shutil.copytree(CONFIG_DIR, folder)
    for dataset in ("kids", "shrec20"):
        registry_with(tmp_path, dataset, None, folder)
    monkeypatch.setenv("BECOS_DATASETS_DIR", str(folder))
    return folder


def registry_with(tmp_path: Path, dataset: str, sha256: str | None, folder: Path | None = None) -> Path:
    """A dataset registry folder holding ``dataset``'s YAML with ``source.archive.sha256`` set."""
    raw = yaml.safe_load((CONFIG_DIR / f"{dataset}.yaml").read_text())
    raw["source"]["archive"]["sha256"] = sha256
    folder = folder or tmp_path / f"registry-{(sha256 or 'null')[:8]}"
    folder.mkdir(exist_ok=True)
    (folder / f"{dataset}.yaml").write_text(yaml.safe_dump(raw, sort_keys=False))
    return folder


def installed(folder: Path) -> dict[str, bytes]:
    """Files below ``folder`` (relative names -> content), without the download record."""
    return {
        str(p.relative_to(folder)): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != RECORD_NAME
    }


# --- fresh download, records, checksums -------------------------------------------------------------
@pytest.mark.parametrize("dataset", ["kids", "shrec20"])
def test_fresh_download_installs_the_archive_and_records_its_unpinned_digest(tmp_path, caplog, dataset):
    members = kids_members() if dataset == "kids" else shrec_members()
    archive = zip_bytes(members)
    spec = DatasetSpec.load(dataset)
    assert spec.archive.sha256 is None  # unpinned (fixture unpinned_registry)
    data = tmp_path / "data"
    with ArchiveServer({"a.zip": archive}) as server:
        result = download_dataset(dataset, data, server.url("a.zip"), progress=False)
        dest = data / spec.archive.extract_to
        assert installed(dest) == members
        assert sorted(os.listdir(data)) == [spec.archive.extract_to]  # no partial file, no temporary folder
        record = json.loads((dest / RECORD_NAME).read_text())
        assert record["sha256"] == result["sha256"] == sha(archive) and record["sha256_pinned"] is False
        assert record["url"] == server.url("a.zip") and record["files"] == len(members)
        # the warning says what to pin and where
        warning = " ".join(r.getMessage() for r in caplog.records if r.levelname == "WARNING")
        assert f"set source.archive.sha256 in {spec.path} to {sha(archive)}" in warning
        # the dataset check reads the installed folder
        names = spec.list_names(data)
        assert len(names) == len(members)
        # a second call downloads nothing
        again = download_dataset(dataset, data, server.url("a.zip"), progress=False)
        assert again["downloaded"] is False and again["sha256"] == sha(archive)
        assert len(server.requests) == 1
        # once pinned: the recorded digest matches and nothing is fetched; another pin is an error
        right = registry_with(tmp_path, dataset, sha(archive))
        assert download_dataset(dataset, data, server.url("a.zip"), config_dir=right)["downloaded"] is False
        wrong = registry_with(tmp_path, dataset, "ab" * 32)
        with pytest.raises(ChecksumMismatchError) as info:
            download_dataset(dataset, data, server.url("a.zip"), config_dir=wrong)
        assert sha(archive) in str(info.value) and "ab" * 32 in str(info.value)
        assert str(dest / RECORD_NAME) in str(info.value) and len(server.requests) == 1


def test_pinned_checksum_mismatch_names_both_digests_and_installs_nothing(tmp_path):
    archive = zip_bytes(kids_members())
    wrong = "0" * 64
    registry = registry_with(tmp_path, "kids", wrong)
    data = tmp_path / "data"
    with ArchiveServer({"kids.zip": archive}) as server:
        url = server.url("kids.zip")
        with pytest.raises(ChecksumMismatchError) as info:
            download_dataset("kids", data, url, config_dir=registry, progress=False)
        message = str(info.value)
        assert message.startswith(f"{url}: ")
        assert f"SHA-256 {sha(archive)}, expected {wrong}" in message and str(registry / "kids.yaml") in message
        assert os.listdir(data) == []  # nothing under the final name, the partial file removed
        # the right pin installs it
        right = registry_with(tmp_path, "kids", sha(archive))
        result = download_dataset("kids", data, url, config_dir=right, progress=False)
        assert result["sha256_pinned"] is True and installed(data / "KIDS") == kids_members()


def test_a_local_copy_is_installed_from_a_file_url(tmp_path):
    """``download_urls: {shrec20: file:///...}``: an archive the user already has, checked and unpacked."""
    archive = tmp_path / "SHREC20b_hires.zip"
    archive.write_bytes(zip_bytes(shrec_members()))
    data = tmp_path / "data"
    partial_path(data / "Shrec20.SHREC20b_hires.zip").parent.mkdir(parents=True)
    partial_path(data / "Shrec20.SHREC20b_hires.zip").write_bytes(b"stale bytes of another URL")
    result = download_dataset("shrec20", data, archive.as_uri(), progress=False)
    assert result["sha256"] == sha(archive.read_bytes()) and result["url"] == archive.as_uri()
    assert installed(data / "Shrec20") == shrec_members() and os.listdir(data) == ["Shrec20"]


# --- resume ----------------------------------------------------------------------------------------
def test_download_resumes_after_a_kill(tmp_path):
    """`becos download-dataset` in a subprocess is SIGKILLed mid-transfer; the rerun asks for the rest."""
    archive = zip_bytes(kids_members())
    data = tmp_path / "data"
    part = partial_path(data / "KIDS.kids.zip")
    stall = len(archive) // 2
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    with ArchiveServer({"kids.zip": archive}, stall_at=stall) as server:
        url = server.url("kids.zip")
        command = [sys.executable, "-m", "becos", "download-dataset", "kids", "--data-dir", str(data), "--url", url]
        job = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            deadline = time.monotonic() + 60
            while not (part.is_file() and part.stat().st_size == stall):
                assert job.poll() is None, job.communicate()
                assert time.monotonic() < deadline, "the download never reached the stall"
                time.sleep(0.05)
            job.send_signal(signal.SIGKILL)
            assert job.wait(10) == -signal.SIGKILL
        finally:
            if job.poll() is None:
                job.kill()
            job.communicate()
        assert part.stat().st_size == stall and not (data / "KIDS").exists()
        assert part.read_bytes() == archive[:stall]
        server.release()
        server.stall_at = None
        assert becos_main(["download-dataset", "kids", "--data-dir", str(data), "--url", url, "--no-progress"]) == 0
        assert [(r.range, r.status) for r in server.requests] == [(None, 200), (f"bytes={stall}-", 206)]
    record = json.loads((data / "KIDS" / RECORD_NAME).read_text())
    assert record["sha256"] == sha(archive) and record["bytes"] == len(archive)
    assert installed(data / "KIDS") == kids_members() and os.listdir(data) == ["KIDS"]


def test_dropped_connection_keeps_the_partial_file_and_resumes(tmp_path, capsys):
    archive = zip_bytes(kids_members())
    data = tmp_path / "data"
    part = partial_path(data / "KIDS.kids.zip")
    cut = len(archive) // 3
    with ArchiveServer({"kids.zip": archive}, drop_at=cut) as server:
        url = server.url("kids.zip")
        assert becos_main(["download-dataset", "kids", "--data-dir", str(data), "--url", url, "--no-progress"]) == 2
        err = capsys.readouterr().err.strip()
        assert f"after {cut} of {len(archive)} bytes" in err and f"it resumes from {part}" in err
        assert "Traceback" not in err and len(err.splitlines()) == 1
        assert part.read_bytes() == archive[:cut] and not (data / "KIDS").exists()
        server.drop_at = None
        download_dataset("kids", data, url, progress=False)
        assert [r.range for r in server.requests] == [None, f"bytes={cut}-"]
    assert installed(data / "KIDS") == kids_members()


def test_a_server_that_ignores_range_restarts_cleanly(tmp_path, capsys):
    archive = zip_bytes(kids_members())
    data = tmp_path / "data"
    part = partial_path(data / "KIDS.kids.zip")
    cut = len(archive) // 2
    with ArchiveServer({"kids.zip": archive}, drop_at=cut, ignore_range=True) as server:
        url = server.url("kids.zip")
        with pytest.raises(DownloadError, match="run again"):
            download_dataset("kids", data, url, progress=False)
        assert part.stat().st_size == cut
        server.drop_at = None
        result = download_dataset("kids", data, url, progress=False)
        assert [(r.range, r.status) for r in server.requests] == [(None, 200), (f"bytes={cut}-", 200)]
    assert "the server ignored the resume request (HTTP 200)" in capsys.readouterr().err
    assert result["sha256"] == sha(archive) and result["bytes"] == len(archive)  # not appended to the old part
    assert installed(data / "KIDS") == kids_members() and os.listdir(data) == ["KIDS"]


def test_a_file_changed_upstream_is_fetched_again_not_appended(tmp_path, capsys):
    """The partial file's ETag goes out as If-Range: a server whose file changed sends it whole."""
    old, new = zip_bytes(kids_members()), zip_bytes({**kids_members(), "off/README.txt": b"version 2"})
    data = tmp_path / "data"
    with ArchiveServer({"kids.zip": old}, drop_at=len(old) // 2) as server:
        with pytest.raises(DownloadError, match="run again: it resumes"):
            download_dataset("kids", data, server.url("kids.zip"), progress=False)
        server.files["kids.zip"], server.drop_at = new, None
        result = download_dataset("kids", data, server.url("kids.zip"), progress=False)
        assert [(r.range, r.status) for r in server.requests] == [(None, 200), (f"bytes={len(old) // 2}-", 200)]
    assert "ignored the resume request" in capsys.readouterr().err
    assert result["sha256"] == sha(new) and (data / "KIDS" / "off" / "README.txt").read_bytes() == b"version 2"


def test_a_partial_file_longer_than_the_file_now_served_restarts(tmp_path, capsys):
    """No ETag, and the file was replaced by a shorter one: the resume is refused (HTTP 416), the
    download starts again."""
    longer = zip_bytes({**kids_members(), "off/padding.bin": os.urandom(20000)})
    shorter = zip_bytes(kids_members())
    data = tmp_path / "data"
    cut = len(shorter) + 1000
    with ArchiveServer({"kids.zip": longer}, drop_at=cut, send_etag=False) as server:
        with pytest.raises(DownloadError, match=f"after {cut} of {len(longer)} bytes"):
            download_dataset("kids", data, server.url("kids.zip"), progress=False)
        server.files["kids.zip"], server.drop_at = shorter, None
        result = download_dataset("kids", data, server.url("kids.zip"), progress=False)
        assert [(r.range, r.status) for r in server.requests] == [(None, 200), (f"bytes={cut}-", 416), (None, 200)]
    assert f"the server cannot resume {server.url('kids.zip')} at byte {cut}" in capsys.readouterr().err
    assert result["sha256"] == sha(shorter) and installed(data / "KIDS") == kids_members()


# --- layout and unsafe archives --------------------------------------------------------------------
def test_wrong_layout_or_no_archive_is_a_clear_error_and_leaves_nothing(tmp_path):
    data = tmp_path / "data"
    nested = {f"KIDS/{name}": body for name, body in kids_members().items()}  # one folder level too many
    with ArchiveServer({"kids.zip": zip_bytes(nested), "other.zip": zip_bytes(shrec_members())}) as server:
        with pytest.raises(ArchiveLayoutError) as info:
            download_dataset("kids", data, server.url("kids.zip"), progress=False)
        message = str(info.value)
        assert "no off/*.off inside" in message and "['KIDS/']" in message and "KIDS/off/0001.isometry.1.off" in message
        assert f"nothing was installed at {data / 'KIDS'}" in message
        assert os.listdir(data) == []
        with pytest.raises(ArchiveLayoutError, match=r"no off/\*\.off inside .*\['SHREC20b_hires/'\]"):
            download_dataset("kids", data, server.url("other.zip"), progress=False)
        assert os.listdir(data) == []
        server.files["page.zip"] = b"<html>Please log in</html>"  # what a login wall serves
        with pytest.raises(CorruptArchiveError, match="not a readable zip or tar archive"):
            download_dataset("kids", data, server.url("page.zip"), progress=False)
        assert os.listdir(data) == []


@pytest.mark.parametrize("kind", ["dotdot", "absolute", "symlink"])
def test_unsafe_members_are_refused_and_nothing_is_written(tmp_path, kind, capsys):
    members = kids_members()
    links = None
    outside = tmp_path / "evil.off"
    if kind == "dotdot":
        members["../evil.off"] = b"pwned"
        members["off/../../../evil.off"] = b"pwned"
        match = r"'\.\./evil\.off' points outside the archive \('\.\.'\)"
    elif kind == "absolute":
        members[str(outside)] = b"pwned"
        match = f"'{outside}' has an absolute path"
    else:
        links = {"off/link.off": "../../evil.off"}
        match = "'off/link.off' is a symbolic link"
    data = tmp_path / "data"
    with ArchiveServer({"kids.zip": zip_bytes(members, links)}) as server:
        with pytest.raises(UnsafeArchiveError, match=match):
            download_dataset("kids", data, server.url("kids.zip"), progress=False)
        assert os.listdir(data) == [] and not outside.exists()
        assert sorted(p.name for p in tmp_path.iterdir()) == ["data", "registry"]
        # the command line: one line naming the URL, exit 2
        assert (
            becos_main(
                ["download-dataset", "kids", "--data-dir", str(data), "--url", server.url("kids.zip"), "--no-progress"]
            )
            == 2
        )
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"becos download-dataset: {server.url('kids.zip')}: member ") and "Traceback" not in err
        assert os.listdir(data) == []


def test_a_killed_extraction_leaves_no_folder_under_the_final_name_and_is_cleaned_up(tmp_path):
    data = tmp_path / "data"
    stale = data / ".KIDS.k1ll3d.tmp-extract" / "KIDS" / "off"  # what a run killed while extracting leaves
    stale.mkdir(parents=True)
    (stale / "0001.null.0.off").write_bytes(b"OFF\n4 4 0\n")
    with ArchiveServer({"kids.zip": zip_bytes(kids_members())}) as server:
        download_dataset("kids", data, server.url("kids.zip"), progress=False)
    assert os.listdir(data) == ["KIDS"] and installed(data / "KIDS") == kids_members()


def test_an_existing_folder_is_used_or_left_alone(tmp_path):
    data = tmp_path / "data"
    mine = data / "KIDS" / "off"
    mine.mkdir(parents=True)
    (mine / "0001.null.0.off").write_bytes(_off(0))
    with ArchiveServer({"kids.zip": zip_bytes(kids_members())}) as server:
        # the user's own copy: nothing downloaded, nothing written into it
        result = download_dataset("kids", data, server.url("kids.zip"), progress=False)
        assert result["downloaded"] is False and result["files"] == 1 and not (data / "KIDS" / RECORD_NAME).exists()
        # a folder of something else is never overwritten
        (mine / "0001.null.0.off").unlink()
        (data / "KIDS" / "notes.txt").write_text("keep")
        with pytest.raises(ArchiveLayoutError, match="was not made by `becos download-dataset`"):
            download_dataset("kids", data, server.url("kids.zip"), progress=False)
        assert (data / "KIDS" / "notes.txt").read_text() == "keep" and server.requests == []


# --- network errors --------------------------------------------------------------------------------
def test_network_errors_are_one_line_messages(tmp_path, capsys):
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        refused = f"http://127.0.0.1:{sock.getsockname()[1]}/kids.zip"  # nothing listens once closed
    with ArchiveServer({}) as server:
        missing = server.url("kids.zip")
        for url, problem in (
            (refused, "cannot download (Connection refused)"),
            (missing, "the server answered HTTP 404 (Not Found)"),
        ):
            code = becos_main(
                ["download-dataset", "kids", "--data-dir", str(tmp_path / "data"), "--url", url, "--no-progress"]
            )
            err = capsys.readouterr().err.strip()
            assert code == 2 and err.startswith(f"becos download-dataset: {url}: {problem}. Fix: ")
            assert "download_urls" in err and len(err.splitlines()) == 1


# --- config keys, datasets that cannot be downloaded -----------------------------------------------
def _config(**overrides) -> dict:
    return {
        "synthetic": {"enabled": False},
        "data_dir": "data",
        "annotations": "ann",
        "datasets": ["kids"],
        **overrides,
    }


@pytest.mark.parametrize("dataset", ["faust", "scape", "smal", "dt4d_animal"])
def test_download_of_a_dataset_behind_an_account_is_a_config_error(dataset):
    spec = DatasetSpec.load(dataset)
    with pytest.raises(ConfigError) as info:
        resolve_config(_config(datasets=[dataset], download=[dataset]))
    message = str(info.value)
    assert f"dataset '{dataset}' ({spec.title}) cannot be downloaded automatically" in message
    assert spec.source["url"] in message and f"<data_dir>/{spec.folder}" in message


def test_download_config_keys():
    assert resolve_config(_config())["download"] == [] and resolve_config(_config())["download_urls"] == {}
    ok = resolve_config(_config(download=["kids"], download_urls={"kids": "http://mirror.example/kids.zip"}))
    assert ok["download"] == ["kids"]
    for overrides, problem in (
        ({"download": ["shrec20"]}, "download lists 'shrec20', which is not in `datasets`"),
        (
            {"download": ["kids"], "download_urls": {"shrec20": "http://m/s.zip"}},
            "download_urls names 'shrec20', which is not in `download`",
        ),
        ({"download": ["kids"], "download_urls": {"kids": "ftp://m/kids.zip"}}, "download_urls"),
    ):
        with pytest.raises(ConfigError, match=problem):
            resolve_config(_config(**overrides))


def test_missing_manual_datasets_say_where_to_get_them_and_where_to_put_them(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    names = ["faust", "scape", "smal"]
    with pytest.raises(DatasetCheckError) as info:
        check_datasets(names, data, None, read_meshes=False)
    problems = info.value.problems
    for name in names:
        spec = DatasetSpec.load(name)
        text = next(p for p in problems if p.startswith(f"dataset '{name}'"))
        assert f"Site: {spec.source['url']} ." in text  # where to get it
        assert spec.source["licence"].rstrip(".") in text
        assert f"Put it there: create {data / spec.folder}" in text  # where to put it
        assert f"place the {spec.file_type.upper()} files in it" in text
        assert "download" not in text.split("Put it there")[1]  # no automatic download offered
    # KIDS can be downloaded: its message says how
    with pytest.raises(DatasetCheckError) as info:
        check_datasets(["kids"], data, None, read_meshes=False)
    assert "add 'kids' to the config key `download`" in info.value.problems[0]
    assert f"becos download-dataset kids --data-dir {data}" in info.value.problems[0]


@pytest.mark.parametrize(
    "archive, problem",
    [
        ({"url": "kids.zip", "sha256": None, "extract_to": "KIDS"}, "is not an http(s):// or file:// URL"),
        ({"url": "https://h/kids.zip", "sha256": "abc", "extract_to": "KIDS"}, "is not 64 hex digits"),
        ({"url": "https://h/kids.zip", "sha256": None, "extract_to": "../KIDS"}, "is not a folder below the data root"),
        (
            {"url": "https://h/kids.zip", "sha256": None, "extract_to": "Shrec20"},
            "is not inside source.archive.extract_to",
        ),
        ({"url": "https://h/kids.zip", "sha256": None}, "must have exactly the keys url, sha256, extract_to"),
    ],
)
def test_a_bad_archive_entry_in_a_dataset_yaml_names_the_file(tmp_path, archive, problem):
    raw = yaml.safe_load((CONFIG_DIR / "kids.yaml").read_text())
    raw["source"]["archive"] = archive
    (tmp_path / "kids.yaml").write_text(yaml.safe_dump(raw))
    with pytest.raises(InputFileError, match=re.escape(problem)) as info:
        DatasetSpec.load("kids", tmp_path)
    assert info.value.path == tmp_path / "kids.yaml"


# --- the workflow ----------------------------------------------------------------------------------
def test_workflow_downloads_kids_before_the_dataset_check(becos_code, tmp_path):
    """`download: [kids]` with a mirror URL on loopback: the download job runs, then the dataset check
    finds the 32 KIDS shapes in the downloaded folder."""
    archive = zip_bytes(kids_members())
    workdir = tmp_path / "run"
    workdir.mkdir()
    data = tmp_path / "data"
    env = dict(
        os.environ, PYTHONUNBUFFERED="1", PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    )
    snakemake = snakemake_cmd(workdir, "--cores", "1")
    with ArchiveServer({"mirror/kids.zip": archive}) as server:
        config = {
            "synthetic": {"enabled": False},
            "data_dir": str(data),
            "annotations": str(becos_code),
            "datasets": ["kids"],
            "download": ["kids"],
            "download_urls": {"kids": server.url("mirror/kids.zip")},
        }
        (workdir / "config.yaml").write_text(yaml.safe_dump(config))
        dry = subprocess.run(
            [*snakemake, "-n", "results/checks/datasets.json"], capture_output=True, text=True, env=env
        )
        assert dry.returncode == 0, dry.stderr[-3000:]
        assert "rule download_dataset:" in dry.stdout and "checkpoint check_datasets:" in dry.stdout
        assert dry.stdout.index("rule download_dataset:") < dry.stdout.index("checkpoint check_datasets:")
        assert server.requests == [] and not data.exists()
        run = subprocess.run([*snakemake, "results/checks/datasets.json"], capture_output=True, text=True, env=env)
        assert run.returncode == 0, run.stderr[-4000:]
        assert [r.path for r in server.requests] == ["/mirror/kids.zip"]
    log = (workdir / "logs" / "download" / "kids.log").read_text()
    assert f"installed {data / 'KIDS'}" in log and "not pinned" in log
    stamp = json.loads((workdir / "results" / "downloads" / "kids.json").read_text())
    assert stamp["sha256"] == sha(archive) and stamp["downloaded"] is True
    report = json.loads((workdir / "results" / "checks" / "datasets.json").read_text())
    assert report["kids"]["ok"] and report["kids"]["found"] == 32
    assert report["kids"]["path"] == str(data / "KIDS" / "off")
