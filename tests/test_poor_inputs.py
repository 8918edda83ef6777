"""Clear one-line messages for the POOR cases of issue #21 (each case: the fault, injected into real
files or real calls, and the message that names the file, the problem and the fix)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from becos.build.record import PairRecord
from becos.errors import BecosError, InputFileError
from becos.products.store import DamagedStoreError, PairKeyError, open_benchmark, write_store


@pytest.fixture
def store(pair_record_files, tmp_path) -> Path:
    return write_store(pair_record_files["full_full"], tmp_path / "full_full.zarr", setting="full_full", progress=False)


@pytest.mark.parametrize("key", [1.5, True, None, [0]])
def test_a_pair_key_that_is_no_row_nor_pair_id_is_refused(store, key):
    bench = open_benchmark(store)
    with pytest.raises(
        PairKeyError, match=r"a pair is chosen by its row \(an int\) or its pair_id \(a str\), not"
    ) as err:
        bench.record(key)
    assert isinstance(err.value, TypeError) and isinstance(err.value, BecosError)
    assert bench.record(1).pair_id == bench.table["pair_id"][1]  # an int still works


def test_a_store_of_a_newer_format_says_so(store):
    meta = json.loads((store / "zarr.json").read_text())
    meta["attributes"]["becos_store"]["format"] += 1
    (store / "zarr.json").write_text(json.dumps(meta))
    with pytest.raises(
        InputFileError,
        match=r"was written by a newer becos: store format 3, this becos reads format 2"
        r"\. Fix: upgrade becos",
    ):
        open_benchmark(store)


def test_a_store_rewritten_under_a_reader_is_a_named_error(store, pair_record_files):
    bench = open_benchmark(store)
    first = bench.record(0)
    records = [PairRecord.load(p) for p in pair_record_files["full_full"]]
    folder = store.parent / "one"
    folder.mkdir()
    records[1].save(folder / "only.npz")
    write_store([folder / "only.npz"], store, setting="full_full", progress=False)  # another store, same path
    with pytest.raises(
        DamagedStoreError,
        match=r"was rewritten or removed while this reader had it open \(reading "
        r"pairs 0:1\)\. Fix: open it again",
    ) as err:
        bench.record(0)
    assert err.value.path == store
    with pytest.raises(DamagedStoreError, match="was rewritten or removed"):
        bench.read_metas()
    assert open_benchmark(store).record(0).pair_id == records[1].pair_id != first.pair_id


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["catalog", "--options", "{bad", "--data-dir", "RESULTS", "--annotations", "RESULTS"],
            "becos catalog: --options: not valid JSON (Expecting property name enclosed "
            "in double quotes at line 1 column 2: '{bad'). Fix: pass the JSON",
        ),
        (
            ["catalog", "--options", "[1, 2]", "--data-dir", "RESULTS", "--annotations", "RESULTS"],
            "becos catalog: --options: a JSON object {...} is needed, not a JSON list",
        ),
        (
            ["catalog", "--options", "{}", "--data-dir", "RESULTS", "--annotations", "RESULTS"],
            "becos catalog: --options: lacks the key 'results' (given keys: []). Fix: ",
        ),
        (
            ["remesh", "--options", "{}", "--shape", "{x", "--tokens", "v0", "--out-dir", "RESULTS"],
            "becos remesh: --shape: not valid JSON",
        ),
        (
            [
                "ground-truth",
                "--options",
                '{"results": "RESULTS", "annotations": "x", "template_file": "t", "remesh": true}',
                "--annotations",
                "x",
                "--setting",
                "full_full",
                "--chunk",
                "0",
                "--manifest",
                "RESULTS/full_full/manifest.csv",
                "--catalog",
                "RESULTS/catalog.csv",
                "--remesh-files",
                "RESULTS/full_full/remesh_files.json",
            ],
            "becos ground-truth: RESULTS/catalog.csv: not found (an input of this stage). "
            "Fix: run the stages before `becos ground-truth`",
        ),
    ],
    ids=["not_json", "not_an_object", "missing_key", "bad_shape", "missing_input"],
)
def test_bad_options_of_a_stage_command_are_one_line_errors(argv, message, tmp_path, capsys):
    from becos.cli import main

    results = str(tmp_path / "nothing")
    argv = [a.replace("RESULTS", results) for a in argv]
    argv += [] if "--out-dir" in argv else ["--out", str(tmp_path / "out")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(message.replace("RESULTS", results)), err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


# --- the dataset check and read_mesh -------------------------------------------------------------------
def _wolves(tmp_path: Path, tosca_dir: Path, edit) -> tuple[Path, str]:
    """data/tosca-off with links to wolf0/1/2, ``edit(folder)`` applied; the dataset check's message."""
    from test_faults import small_registry

    from becos.sources.check import DatasetCheckError, check_datasets

    folder = tmp_path / "data" / "tosca-off"
    folder.mkdir(parents=True)
    for name in ("wolf0", "wolf1", "wolf2"):
        (folder / f"{name}.off").symlink_to(tosca_dir / f"{name}.off")
    edit(folder)
    with pytest.raises(DatasetCheckError) as err:
        check_datasets(
            ["tosca"], tmp_path / "data", tosca_dir.parents[1], config_dir=small_registry(tmp_path, {"wolf": 3})
        )
    return folder, str(err.value)


def _edit_wolf1(folder: Path, tosca_dir: Path, edit_lines) -> None:
    lines = (tosca_dir / "wolf1.off").read_text().splitlines()
    edit_lines(lines)
    (folder / "wolf1.off").unlink()
    (folder / "wolf1.off").write_text("\n".join(lines) + "\n")


def test_a_stray_file_is_named_as_stray_not_blamed_on_the_registry(tosca_dir, tmp_path):
    folder, text = _wolves(tmp_path, tosca_dir, lambda f: shutil.copy(tosca_dir / "cat0.off", f / "teapot.off"))
    assert "1 problem(s)" in text
    assert (
        f"{folder}: 1 file(s) there are not shapes of dataset 'tosca': teapot.off (their names match no class "
        f"rule of the dataset registry "
    ) in text
    assert f"Fix: move them out of {folder} (stray files)" in text


def test_a_dangling_symlink_is_named_as_such(tosca_dir, tmp_path):
    def edit(folder):
        (folder / "wolf2.off").unlink()
        (folder / "wolf2.off").symlink_to(tmp_path / "gone" / "wolf2.off")

    folder, text = _wolves(tmp_path, tosca_dir, edit)
    assert (
        f"{folder / 'wolf2.off'}: is a symbolic link to {tmp_path / 'gone' / 'wolf2.off'}, which does not exist "
        f"(a dangling link). Fix: point the link at the real file"
    ) in text


def test_a_quad_face_is_named_not_called_truncated(tosca_dir, tmp_path):
    from becos.core.mesh import read_mesh

    def quad(lines):
        a, b, c, d = lines[-1].split()
        lines[-1] = f"4 {b} {c} {d} 7"

    folder, text = _wolves(tmp_path, tosca_dir, lambda f: _edit_wolf1(f, tosca_dir, quad))
    expected = f"{folder / 'wolf1.off'}: face line 8684 (line 13030 of the file: b'4 "
    assert expected in text and "has 4 corners, not 3; becos needs triangle meshes" in text
    assert "truncated" not in text.split(expected)[1].split("Fix:")[0]
    with pytest.raises(InputFileError, match=r"face line 8684 \(line 13030 of the file: .*has 4 corners, not 3"):
        read_mesh(folder / "wolf1.off")


def test_a_vertex_line_with_two_coordinates_is_named_with_its_line(tosca_dir, tmp_path):
    from becos.core.mesh import read_mesh

    def two(lines):
        lines[2 + 100] = " ".join(lines[2 + 100].split()[:2])

    folder, text = _wolves(tmp_path, tosca_dir, lambda f: _edit_wolf1(f, tosca_dir, two))
    assert f"{folder / 'wolf1.off'}: vertex line 101 (line 103 of the file: " in text
    assert "holds 2 values instead of x y z" in text
    with pytest.raises(
        InputFileError,
        match=r"vertex line 101 \(line 103 of the file: .*\) holds 2 values instead "
        r"of x y z\. Fix: re-export or re-download",
    ):
        read_mesh(folder / "wolf1.off")  # what the remesh job reads


def test_a_flattened_mesh_is_refused(tosca_dir, tmp_path):
    from test_faults import write_off

    from becos.core.mesh import read_mesh

    wolf = read_mesh(tosca_dir / "wolf1.off")
    flat = wolf.vertices.copy()
    flat[:, 2] = 0.0
    folder, text = _wolves(
        tmp_path, tosca_dir, lambda f: (f / "wolf1.off").unlink() or write_off(f / "wolf1.off", flat, wolf.faces)
    )
    assert f"{folder / 'wolf1.off'}: all its 4344 vertices lie in one plane (thickness 0 of its largest extent)" in text
    with pytest.raises(
        InputFileError,
        match=r"all its 4344 vertices lie in one plane .*\. Fix: use the dataset's "
        r"original 3-D mesh",
    ):
        read_mesh(folder / "wolf1.off")  # the remesh job and `check --full-parse`


def test_a_non_manifold_vertex_is_refused(tosca_dir, tmp_path):
    """Two far-apart vertices of wolf1 welded into one: its two fans touch only there (a bow-tie)."""
    from becos.build.remesh import remesh
    from becos.core.mesh import non_manifold_vertices, read_mesh, surface_for_remeshing

    wolf = read_mesh(tosca_dir / "wolf1.off")
    a, b = 100, int(np.argmax(np.linalg.norm(wolf.vertices - wolf.vertices[100], axis=1)))
    faces = np.where(wolf.faces == b, a, wolf.faces)
    assert non_manifold_vertices(wolf.faces, wolf.n_vertices).size == 0
    assert non_manifold_vertices(faces, wolf.n_vertices).tolist() == [a]
    welded = type(wolf)(wolf.vertices, faces)
    with pytest.raises(
        InputFileError,
        match=r"wolf1.off: 1 vertices are non-manifold \(their faces form several fans "
        r"that touch only at the vertex, e.g. vertex 100 of the file\)",
    ) as err:
        surface_for_remeshing(welded, source=tosca_dir / "wolf1.off")
    assert "Repair non Manifold Vertices" in err.value.fix
    with pytest.raises(InputFileError, match="1 vertices are non-manifold"):
        remesh(welded, target_vertices=2000, source=tosca_dir / "wolf1.off")


# --- the workflow's rules ------------------------------------------------------------------------------
def test_every_path_in_a_rules_shell_command_is_quoted():
    """A results folder with a space must not split a job's command line: every {input}, {output}, {log}
    (and {params.out}) in the rules' shell commands is written ``{x:q}``."""
    import re

    rules = sorted((Path(__file__).resolve().parents[1] / "workflow" / "rules").glob("*.smk"))
    shell = re.compile(r'^\s*"(?:becos |\s*-)[^"]*"|^\s*" [^"]*"', re.MULTILINE)
    found, unquoted = 0, []
    for path in rules:
        for command in shell.findall(path.read_text()):
            for placeholder in re.findall(r"\{(input|output|log|params\.out)(\.[A-Za-z_]+)?(:q)?\}", command):
                found += 1
                if not placeholder[2]:
                    unquoted.append(f"{path.name}: {command.strip()}")
    assert found >= 40 and not unquoted, unquoted


def test_a_results_path_with_a_space_is_quoted_in_the_jobs(becos_code, tmp_path):
    import subprocess

    from snakemake_cmd import snakemake_cmd
    from tiny_tosca import tosca_config, write_config_file

    workdir = write_config_file(tmp_path / "run", tosca_config(becos_code, results="my results"))
    dry = subprocess.run(snakemake_cmd(workdir, "-n", "-p", "--cores", "1"), capture_output=True, text=True)
    assert dry.returncode == 0, dry.stderr[-3000:]
    assert "--out 'my results/checks/datasets.json'" in dry.stdout, dry.stdout[-3000:]
    assert "--out 'my results/config.json'" in dry.stdout


# --- a full disk -----------------------------------------------------------------------------------------
def _in_a_full_filesystem(tmp_path: Path, script: str) -> subprocess.CompletedProcess:
    """Run ``script`` (Python; ``FULL`` is a folder on a real, full 64 KiB tmpfs) in a private user and mount
    namespace (``unshare``: no root needed, nothing is mounted outside the child)."""
    import os
    import sys

    mount = tmp_path / "tiny"
    mount.mkdir()
    runner = tmp_path / "full.py"
    runner.write_text(f"FULL = {str(mount)!r}\n" + script)
    shell = (
        f"mount -t tmpfs -o size=64k none {mount} && head -c 1000000 /dev/zero > {mount}/filler 2>/dev/null; "
        f"exec {sys.executable} {runner}"
    )
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    result = subprocess.run(
        ["unshare", "--user", "--map-root-user", "--mount", "sh", "-c", shell], capture_output=True, text=True, env=env
    )
    if "mount:" in result.stderr or "unshare:" in result.stderr:
        pytest.skip(f"cannot mount a private tmpfs here: {result.stderr.strip()[:200]}")
    return result


def test_a_full_disk_is_a_named_error(tmp_path):
    script = """
import sys
from becos.cli import main
from becos.errors import DiskFullError
from becos.atomic import save_npz
import numpy as np
try:
    save_npz(FULL + "/gt.npz", a=np.zeros(100000))
except DiskFullError as exc:
    print("LIBRARY", exc)
sys.exit(main(["write-config", "--options", '{"data_dir": "d", "annotations": "a", "datasets": ["tosca"]}',
                "--out", FULL + "/config.json"]))
"""
    result = _in_a_full_filesystem(tmp_path, script)
    mount = tmp_path / "tiny"
    assert f"LIBRARY {mount}/gt.npz: cannot be written: No space left on device (" in result.stdout, result
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith(
        f"becos write-config: {mount}/config.json: cannot be written: No space left on device ("
    ), result.stderr
    assert "Fix: free disk space, or set `results` to a folder on a larger disk, and run again" in result.stderr
    assert "Traceback" not in result.stderr


def test_an_ascii_ply_header_announcing_fewer_faces_than_the_file_holds(tosca_dir, tmp_path):
    """BAD 2 for ASCII PLY: the header says one face fewer than the file holds."""
    from becos.core.mesh import read_mesh
    from becos.sources.check import check_mesh_file

    wolf = read_mesh(tosca_dir / "wolf0.off")
    header = [
        "ply",
        "format ascii 1.0",
        f"element vertex {wolf.n_vertices}",
        "property float x",
        "property float y",
        "property float z",
        f"element face {wolf.n_faces - 1}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    body = [f"{x} {y} {z}" for x, y, z in wolf.vertices.tolist()] + [
        f"3 {a} {b} {c}" for a, b, c in wolf.faces.tolist()
    ]
    path = tmp_path / "wolf0.ply"
    path.write_text("\n".join(header + body) + "\n")
    with pytest.raises(
        InputFileError,
        match=r"the PLY header announces 4344 vertices and 8683 faces but 13028 data "
        r"lines follow, 1 more than announced",
    ) as err:
        check_mesh_file(path)
    assert err.value.path == path and "correct the header's counts" in err.value.fix


# --- an entry that is no regular file --------------------------------------------------------------------
def _make_fifo(path: Path) -> None:
    import os

    os.mkfifo(path)


NOT_A_FILE = {  # kind: (how wolf1.off is made, what the check calls it)
    "fifo": (_make_fifo, "is a named pipe (FIFO), not a mesh file"),
    "folder": (lambda p: (p.mkdir(), (p / "wolf1.off").write_text("OFF\n")), "is a folder, not a mesh file"),
    "link_to_dev_zero": (
        lambda p: p.symlink_to("/dev/zero"),
        "is a symbolic link to /dev/zero, a device file (character device), not a mesh file",
    ),
}


@pytest.mark.parametrize("kind", sorted(NOT_A_FILE))
def test_an_entry_that_is_no_regular_file_is_named_not_called_missing(becos_code, tmp_path, kind):
    """Issue #29: a FIFO, a folder or a link to /dev/zero named wolf1.off used to be skipped by the listing
    and reported as `found 75 shapes … missing files named by the published BeCoS pair lists: wolf1.off`,
    although an entry of that name is there. The check (the real `becos check`, in a subprocess with a
    timeout: opening the FIFO or reading /dev/zero would never end) names it and what it is."""
    import os
    import sys

    make, what = NOT_A_FILE[kind]
    tosca = tmp_path / "data" / "tosca-off"
    tosca.mkdir(parents=True)
    for mesh in (becos_code / "data" / "tosca-off").glob("*.off"):
        if mesh.name != "wolf1.off":
            (tosca / mesh.name).symlink_to(mesh)
    make(tosca / "wolf1.off")
    command = [sys.executable, "-m", "becos", "check", "--datasets", "tosca", "--data-dir", str(tmp_path / "data")]
    result = subprocess.run(
        [*command, "--annotations", str(becos_code), "--out", str(tmp_path / "report.json")],
        capture_output=True,
        text=True,
        timeout=300,
        env=dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1])),
    )
    assert result.returncode == 2, result.stderr[-3000:]
    text = result.stderr
    assert f"{tosca / 'wolf1.off'}: {what}. Fix: " in text, text[-3000:]
    assert "missing files named by the published" not in text and "found 75 shapes" not in text, text[-3000:]
    assert "Traceback" not in text
    report = json.loads((tmp_path / "report.json").read_text())["tosca"]
    assert report["not_mesh_files"] == {str(tosca / "wolf1.off"): what.removesuffix(", not a mesh file")[3:]}


def test_what_an_entry_that_is_no_regular_file_is(tosca_dir, tmp_path):
    """:func:`becos.core.formats.not_a_regular_file` by ``stat`` alone (a FIFO is never opened: the calls would
    block; an alarm fails the test instead), and the readers of a single mesh (the cheap check,
    ``read_mesh`` of the remesh job) name it."""
    import os
    import signal
    import socket

    from becos.core.formats import not_a_regular_file
    from becos.core.mesh import read_mesh
    from becos.sources.check import check_mesh_file

    os.mkfifo(tmp_path / "fifo.off")
    (tmp_path / "folder.off").mkdir()
    (tmp_path / "zero.off").symlink_to("/dev/zero")
    (tmp_path / "to_fifo.off").symlink_to(tmp_path / "fifo.off")
    (tmp_path / "loop.off").symlink_to(tmp_path / "loop.off")
    (tmp_path / "gone.off").symlink_to(tmp_path / "nothing" / "gone.off")
    (tmp_path / "mesh.off").symlink_to(tosca_dir / "wolf1.off")
    server = socket.socket(socket.AF_UNIX)
    server.bind(str(tmp_path / "sock.off"))

    def hung(signum, frame):
        raise AssertionError("a FIFO or /dev/zero was opened: the call did not return within 60 s")

    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(60)
    try:
        assert {p.name: not_a_regular_file(p) for p in sorted(tmp_path.iterdir())} == {
            "fifo.off": "a named pipe (FIFO)",
            "folder.off": "a folder",
            "gone.off": f"a symbolic link to {tmp_path / 'nothing' / 'gone.off'}, which does not exist (a dangling link)",
            "loop.off": f"a symbolic link to {tmp_path / 'loop.off'} that never reaches a file (a loop of links)",
            "mesh.off": None,
            "sock.off": "a socket",
            "to_fifo.off": f"a symbolic link to {tmp_path / 'fifo.off'}, a named pipe (FIFO)",
            "zero.off": "a symbolic link to /dev/zero, a device file (character device)",
        }
        assert not_a_regular_file(tmp_path / "absent.off") is None
        for read in (check_mesh_file, read_mesh):
            with pytest.raises(InputFileError, match=r"fifo.off: is a named pipe \(FIFO\), not a mesh file\. Fix: re"):
                read(tmp_path / "fifo.off")
            with pytest.raises(
                InputFileError, match=r"zero.off: is a symbolic link to /dev/zero, a device .*Fix: point"
            ):
                read(tmp_path / "zero.off")
            with pytest.raises(InputFileError, match="absent.off: mesh file not found"):
                read(tmp_path / "absent.off")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
        server.close()
