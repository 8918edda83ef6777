"""Stage 1: the dataset / annotation check on the real TOSCA data and annotation folder, and fetching a
pinned annotation archive from a loopback HTTP server."""

from __future__ import annotations

import functools
import hashlib
import http.server
import io
import json
import os
import shutil
import tarfile
import threading
import zipfile
from pathlib import Path

import pytest
import yaml

from becos.cli import main as becos_main
from becos.errors import ConfigError, InputFileError
from becos.sources.annotations import AnnotationSource
from becos.sources.check import DatasetCheckError, check_datasets, check_mesh_file
from becos.sources.datasets import CONFIG_DIR
from becos.sources.download import RECORD_NAME, fetch_annotations

# what AnnotationSource needs (plus a few small files), copied into the served archive
ANNOTATION_FILES = (
    "config/adjacency_matrix.csv",
    "config/templates_all.csv",
    "config/templates_tosca_demo.csv",
    "config/templates_chirality_all.csv",
    "data/info_dt4d_humanoids.json",
    "precomputed_corr_templates/same_triangulation_dt4d_animals.txt",
)


# --- check_datasets ---------------------------------------------------------------------------------
def test_tosca_present_reports_76_shapes(becos_code):
    report = check_datasets(["tosca"], becos_code / "data", becos_code)
    tosca = report["tosca"]
    assert tosca["ok"] and report["ok"] and report["annotations"]["ok"]
    assert (tosca["found"], tosca["expected"], tosca["meshes_checked"]) == (76, 76, 76)
    assert tosca["path"] == str((becos_code / "data" / "tosca-off").absolute())
    assert tosca["found_per_class"]["michael"] == 20 and tosca["bad_meshes"] == []
    ann = report["annotations"]
    assert (ann["nodes"], ann["edges"]) == (70, 69)
    # TOSCA's 8 templates are joined through faust_tr_reg_000 (centaur top, the humans): 9 nodes, 8 edges
    assert ann["edge_files"] == {"needed": 16, "missing": []}
    assert ann["default_faces"] == {"needed": 1, "missing": []}
    assert all(
        ann["files"][k]
        for k in ("config/adjacency_matrix.csv", "config/templates_all.csv", "precomputed_corr_templates")
    )
    json.dumps(report)  # JSON-able


def test_missing_dataset_says_where_to_get_it_and_where_to_put_it(becos_code, tmp_path, capsys):
    data = tmp_path / "data"
    data.mkdir()
    out = tmp_path / "report.json"
    args = [
        "check",
        "--datasets",
        "tosca",
        "faust",
        "--data-dir",
        str(data),
        "--annotations",
        str(becos_code),
        "--out",
        str(out),
    ]
    assert becos_main(args) == 2
    message = capsys.readouterr().err
    faust_folder = data / "MPI-FAUST" / "training" / "registrations"
    assert "https://faust-leaderboard.is.tuebingen.mpg.de/download" in message
    assert f"create {faust_folder}" in message and "account required" in message
    assert (
        "http://tosca.cs.technion.ac.il/book/resources_data.html" in message
        and f"create {data / 'tosca-off'}" in message
    )
    assert "`data_dir`" in message and "`datasets`" in message and "2 problem(s)" in message
    report = json.loads(out.read_text())  # the report is written on failure too
    assert report["ok"] is False and report["faust"]["ok"] is False and report["faust"]["found"] == 0
    assert report["faust"]["path"] == str(faust_folder) and report["faust"]["expected"] == 100
    # the annotation folder itself is fine; an absent dataset does not make it demand default faces
    assert report["annotations"]["ok"] is True
    # a missing annotation folder names the config key
    with pytest.raises(ConfigError, match=r"annotation folder .*nowhere not found.*`annotations`"):
        check_datasets(["tosca"], becos_code / "data", tmp_path / "nowhere", read_meshes=False)


def _small_tosca(tmp_path: Path, tosca_dir: Path, names: tuple[str, ...]) -> tuple[Path, Path]:
    """A data root with a few TOSCA files and a registry whose tosca.yaml expects exactly those."""
    data = tmp_path / "data" / "tosca-off"
    data.mkdir(parents=True)
    for name in names:
        shutil.copyfile(tosca_dir / f"{name}.off", data / f"{name}.off")
    raw = yaml.safe_load((CONFIG_DIR / "tosca.yaml").read_text())
    raw["expected_count"] = len(names)
    raw["expected_per_class"] = {"wolf": len(names)}
    registry = tmp_path / "registry"
    registry.mkdir()
    (registry / "tosca.yaml").write_text(yaml.safe_dump(raw))
    return tmp_path / "data", registry


def test_truncated_and_empty_meshes_are_named(becos_code, tosca_dir, tmp_path):
    data, registry = _small_tosca(tmp_path, tosca_dir, ("wolf0", "wolf1", "wolf2"))
    folder = data / "tosca-off"
    full = (folder / "wolf1.off").read_bytes()
    (folder / "wolf1.off").write_bytes(full[: len(full) * 2 // 3])  # cut mid-way through the faces
    (folder / "wolf2.off").write_bytes(b"")
    ok = check_datasets(["tosca"], data, becos_code, config_dir=registry, read_meshes=False)  # counts alone pass
    assert ok["tosca"]["found"] == 3
    with pytest.raises(DatasetCheckError) as info:
        check_datasets(["tosca"], data, becos_code, config_dir=registry)
    message = str(info.value)
    assert isinstance(info.value, ConfigError)
    assert str(folder / "wolf1.off") in message and "truncated" in message
    assert str(folder / "wolf2.off") in message and "empty" in message
    assert "wolf0.off" not in message and "2 of 3 mesh files" in message
    assert "Fix: re-download or re-extract them" in message
    bad = {Path(b["path"]).name for b in info.value.report["tosca"]["bad_meshes"]}
    assert bad == {"wolf1.off", "wolf2.off"}
    # a count mismatch is listed together with the bad files, not instead of them
    (folder / "wolf0.off").unlink()
    with pytest.raises(DatasetCheckError) as info:
        check_datasets(["tosca"], data, becos_code, config_dir=registry)
    assert len(info.value.problems) == 3  # count, per-class count, bad meshes
    assert "found 2 shapes" in str(info.value) and "wolf2.off" in str(info.value)


def test_mesh_file_check_catches_cut_ply_and_obj(tosca_dir, tmp_path):
    import trimesh

    mesh = trimesh.load(tosca_dir / "wolf0.off", process=False, maintain_order=True)
    assert check_mesh_file(tosca_dir / "wolf0.off") == (4344, 8684)
    for name, kwargs in (("b.ply", {"encoding": "binary"}), ("a.ply", {"encoding": "ascii"}), ("m.obj", {})):
        path = tmp_path / name
        mesh.export(path, **kwargs)
        assert check_mesh_file(path) == (4344, 8684)
        data = path.read_bytes()
        for cut in (len(data) - 7, len(data) // 2):
            path.write_bytes(data[:cut])
            with pytest.raises(InputFileError, match="truncated"):
                check_mesh_file(path)


# --- fetch_annotations ------------------------------------------------------------------------------
class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    requests: list[str] = []

    def do_GET(self):  # noqa: N802 - http.server naming
        type(self).requests.append(self.path)
        super().do_GET()

    def log_message(self, *args):
        pass


@pytest.fixture()
def served(tmp_path):
    """A loopback HTTP server over ``tmp_path/www``: yields (base URL, folder, list of request paths)."""
    www = tmp_path / "www"
    www.mkdir()
    handler = type("Handler", (_QuietHandler,), {"requests": []})
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(handler, directory=str(www)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}", www, handler.requests
    finally:
        server.shutdown()
        server.server_close()
        thread.join(5)


def _annotation_archive(becos_code: Path, out: Path) -> str:
    """A .tar.gz of the small annotation files under one top-level folder; returns its SHA-256."""
    with tarfile.open(out, "w:gz") as tar:
        for rel in ANNOTATION_FILES:
            tar.add(becos_code / rel, arcname=f"becos-code-main/{rel}")
    return hashlib.sha256(out.read_bytes()).hexdigest()


def test_fetch_annotations_from_loopback_server(becos_code, served, tmp_path):
    base, www, requests = served
    digest = _annotation_archive(becos_code, www / "becos-code.tar.gz")
    url = f"{base}/becos-code.tar.gz"
    dest = tmp_path / "annotations"

    # wrong checksum: names both digests, installs nothing, leaves no temporary folder
    wrong = "0" * 64
    with pytest.raises(ConfigError, match=f"SHA-256 {digest}, expected {wrong}"):
        fetch_annotations(url, wrong, dest)
    assert not dest.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["www"]

    got = fetch_annotations(url, digest.upper(), dest)
    assert got == dest.resolve() and len(requests) == 2
    assert (dest / "config" / "adjacency_matrix.csv").is_file()  # the top-level folder was stripped
    assert json.loads((dest / RECORD_NAME).read_text())["sha256"] == digest
    fetched = AnnotationSource(dest, cache_dir=tmp_path / "edge-cache")
    original = AnnotationSource(becos_code, cache_dir=tmp_path / "edge-cache")
    assert sorted(fetched.graph.edges) == sorted(original.graph.edges)
    assert sorted(fetched.graph.nodes) == sorted(original.graph.nodes)
    assert fetched.template_rows() == original.template_rows()
    assert fetched.path("tosca_cat0", "tosca_horse0") == ["tosca_cat0", "tosca_dog0", "tosca_horse0"]

    # second fetch: no request, nothing rewritten
    stamp = (dest / RECORD_NAME).stat().st_mtime_ns
    assert fetch_annotations(url, digest, dest) == dest.resolve()
    assert len(requests) == 2 and (dest / RECORD_NAME).stat().st_mtime_ns == stamp

    # the fetched folder lacks the edge files: the check lists the missing ones for TOSCA
    with pytest.raises(DatasetCheckError, match="no edge file for network edge tosca_cat0 -> tosca_dog0") as info:
        check_datasets(["tosca"], becos_code / "data", dest, read_meshes=False)
    assert len(info.value.report["annotations"]["edge_files"]["missing"]) == 16


def test_fetch_cli_and_file_url_zip_without_top_folder(becos_code, tmp_path, capsys):
    archive = tmp_path / "flat.zip"
    with zipfile.ZipFile(archive, "w") as zf:
        for rel in ANNOTATION_FILES:
            zf.write(becos_code / rel, arcname=rel)
    digest = hashlib.sha256(archive.read_bytes()).hexdigest()
    dest = tmp_path / "ann"
    assert becos_main(["fetch-annotations", "--url", archive.as_uri(), "--sha256", digest, "--dest", str(dest)]) == 0
    assert capsys.readouterr().out.strip() == str(dest.resolve())
    assert AnnotationSource(dest, cache_dir=tmp_path / "c").graph.number_of_edges() == 69
    # an unrelated existing folder is never overwritten
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("keep")
    assert becos_main(["fetch-annotations", "--url", archive.as_uri(), "--sha256", digest, "--dest", str(other)]) == 2
    assert "was not made by `becos fetch-annotations`" in capsys.readouterr().err
    assert (other / "notes.txt").read_text() == "keep"


def _tar_with(path: Path, member: tarfile.TarInfo, data: bytes = b"") -> str:
    with tarfile.open(path, "w") as tar:
        ok = tarfile.TarInfo("pkg/config/ok.txt")
        ok.size = 2
        tar.addfile(ok, io.BytesIO(b"ok"))
        member.size = len(data) if member.isfile() else 0
        tar.addfile(member, io.BytesIO(data) if member.isfile() else None)
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.parametrize("kind", ["dotdot", "absolute", "symlink"])
def test_unsafe_archives_are_rejected(tmp_path, kind):
    if kind == "symlink":
        member = tarfile.TarInfo("pkg/config/link")
        member.type, member.linkname = tarfile.SYMTYPE, "../../../outside.txt"
        match = "escapes the archive"
    else:
        member = tarfile.TarInfo("pkg/../../outside.txt" if kind == "dotdot" else "/tmp/outside.txt")
        match = "'..'" if kind == "dotdot" else "absolute path"
    archive = tmp_path / "evil.tar"
    digest = _tar_with(archive, member, b"pwned")
    dest = tmp_path / "deep" / "ann"
    with pytest.raises(ConfigError, match=match):
        fetch_annotations(archive.as_uri(), digest, dest)
    assert not dest.exists() and not (tmp_path / "outside.txt").exists()
    assert os.listdir(tmp_path / "deep") == []


def _process_ids(items: list) -> list[int]:
    """The id of the process that handled each item (a module-level function: it pickles)."""
    return [os.getpid() for _ in items]


def test_one_second_process_serves_every_split():
    """A :class:`ProcessSplit` starts its second process once: the dataset check's two splits (mesh files,
    class templates) share it, so its start-up is paid once and overlaps the check's own work."""
    from becos.process_split import ProcessSplit

    with ProcessSplit(2, warm_up=("becos.sources.check.datasets",)) as split:
        first, second = split.map(_process_ids, range(4)), split.map(_process_ids, range(5))
    assert first[1::2] == second[1::2][:2] == [os.getpid()] * 2  # the caller takes every other item
    assert len(set(first[0::2] + second[0::2])) == 1 and first[0] != os.getpid()  # one second process
    with ProcessSplit(1) as split:
        assert split.map(_process_ids, range(3)) == [os.getpid()] * 3


def test_two_processes_give_the_same_report(becos_code, tosca_dir, tmp_path):
    """``processes=2`` (mesh files and class comparisons shared with a second process) reports what one
    process reports, a file off its class template included, in the same order."""
    import numpy as np

    from becos.core.formats.off import read_off

    data, registry = _small_tosca(tmp_path, tosca_dir, ("wolf0", "wolf1", "wolf2"))
    folder = data / "tosca-off"
    vertices, faces = read_off((folder / "wolf1.off").read_bytes())
    with open(folder / "wolf1.off", "w") as fh:  # in centimetres: off its template's edge lengths
        fh.write(f"OFF\n{len(vertices)} {len(faces)} 0\n")
        np.savetxt(fh, vertices * 100.0, fmt="%.6f")
        np.savetxt(fh, np.column_stack([np.full(len(faces), 3), faces]), fmt="%d")
    reports = []
    for processes in (1, 2):
        with pytest.raises(DatasetCheckError) as info:
            check_datasets(["tosca"], data, becos_code, config_dir=registry, processes=processes)
        reports.append((info.value.report, info.value.problems))
    assert reports[0] == reports[1]
    mismatches = reports[0][0]["tosca"]["class_mismatches"]
    assert [Path(m["path"]).name for m in mismatches] == ["wolf1.off"]
    assert reports[0][0]["tosca"]["meshes_checked"] == 3
