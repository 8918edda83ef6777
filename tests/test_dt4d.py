"""DeformingThings4D preparation (issue #14, item 1): ``becos prepare-dt4d`` and its workflow rule.

The ``.anime`` files are written by the test (DeformingThings4D needs a request form): an icosphere
body with one face missing (a hole trimesh's split fills), a second small component, vertex rows
shuffled over both components and face rows shuffled, animated by smooth per-frame offsets. The
output must equal the reference procedure (``trimesh.Trimesh(v, f, process=False,
maintain_order=True).split(only_watertight=False)``, then the component with the most vertices)
computed here from the raw file, read back the way becos and the reference read OBJ files.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from becos.cli import main as becos_main

REPO = Path(__file__).resolve().parents[1]


# --- synthetic .anime files ------------------------------------------------------------------------
def synthetic_animation(n_frames: int, seed: int = 0, phase: float = 0.0, subdivisions: int = 2):
    """``(frame0 (nv, 3) float32, faces (nt, 3) int32, offsets (nf-1, nv, 3) float32, n_body)``.

    Body: an ellipsoid icosphere (``n_body`` vertices) with its first face removed; a small second
    component (an icosphere of 12 vertices) beside it; vertex rows permuted over both, face rows
    shuffled (by ``seed``: one seed, one triangulation). Frames bend the body smoothly (a different
    bend per frame, shifted by ``phase``)."""
    import trimesh

    rng = np.random.default_rng(seed)
    body = trimesh.creation.icosphere(subdivisions=subdivisions)
    small = trimesh.creation.icosphere(subdivisions=0, radius=0.1)
    v_body = body.vertices * [0.5, 0.25, 0.2]  # metres-like, long along x
    v = np.vstack([v_body, small.vertices + [0.9, 0.0, 0.0]])
    f = np.vstack([body.faces[1:], small.faces + len(body.vertices)])
    perm = rng.permutation(len(v))  # new row of old vertex i: inverse[i]
    inverse = np.empty_like(perm)
    inverse[perm] = np.arange(len(v))
    v, f = v[perm], inverse[f]
    f = f[rng.permutation(len(f))]
    t = np.linspace(0.0, 2.0 * np.pi, n_frames)[1:, None] + phase
    x = v[None, :, 0]
    offsets = np.zeros((n_frames - 1, len(v), 3))
    offsets[:, :, 2] = 0.15 * np.sin(t) * x**2 + 0.01 * np.cos(3 * t)  # bend up/down along the body
    offsets[:, :, 1] = 0.05 * np.sin(2 * t) * x
    return v.astype(np.float32), f.astype(np.int32), offsets.astype(np.float32), len(body.vertices)


def write_anime(path: Path, frame0: np.ndarray, faces: np.ndarray, offsets: np.ndarray) -> Path:
    """A little-endian .anime: int32 nf, nv, nt; float32 frame 0; int32 faces; float32 offsets."""
    path.parent.mkdir(parents=True, exist_ok=True)
    header = np.array([len(offsets) + 1, len(frame0), len(faces)], dtype="<i4")
    path.write_bytes(
        header.tobytes()
        + frame0.astype("<f4").tobytes()
        + faces.astype("<i4").tobytes()
        + offsets.astype("<f4").tobytes()
    )
    return path


def reference_frame(path: Path, k: int):
    """The reference procedure (becos-code's preprocess_dt4d.py) from the raw file: np.fromfile as
    DeformingThings4D's reader does, trimesh's split, the first of the components sorted by vertex count
    (descending, stable)."""
    import trimesh

    with open(path, "rb") as fh:
        nf, nv, nt = (int(x) for x in np.fromfile(fh, dtype=np.int32, count=3))
        v = np.fromfile(fh, dtype=np.float32, count=nv * 3).reshape(-1, 3)
        f = np.fromfile(fh, dtype=np.int32, count=nt * 3).reshape(-1, 3)
        off = np.fromfile(fh, dtype=np.float32, count=-1).reshape(nf - 1, nv, 3)
    vertices = v if k == 0 else v + off[k - 1]
    parts = trimesh.Trimesh(vertices, f, process=False, maintain_order=True).split(only_watertight=False)
    return sorted(parts, key=lambda part: len(part.vertices), reverse=True)[0]


def make_download(data_dir: Path, kind: str, classes: dict[str, dict[str, int]], phase: float = 0.0) -> None:
    """``DATA/DeformingThings4D/<kind>/<class>_<action>/<class>_<action>.anime`` for ``{class: {action: nf}}``:
    one triangulation (DT4D classes listed as sharing one), a different motion per animation."""
    for i, (cls, actions) in enumerate(classes.items()):
        for j, (action, n_frames) in enumerate(actions.items()):
            frame0, faces, offsets, _ = synthetic_animation(n_frames, phase=phase + 0.7 * i + 0.3 * j)
            write_anime(
                data_dir / "DeformingThings4D" / kind / f"{cls}_{action}" / f"{cls}_{action}.anime",
                frame0,
                faces,
                offsets,
            )


def run_cli(capsys, *args) -> tuple[int, str, str]:
    code = becos_main(["prepare-dt4d", *map(str, args)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


# --- (a) the command -------------------------------------------------------------------------------
def test_prepared_frames_equal_the_reference_procedure(tmp_path, capsys):
    import trimesh

    from becos.core.mesh import read_mesh

    data = tmp_path / "data"
    make_download(data, "animals", {"catBG": {"run": 50, "walk": 12}})
    info = {"catBG": {"run": [43, 0, 7, 49], "walk": [3]}}
    (tmp_path / "info.json").write_text(json.dumps(info))
    code, out, err = run_cli(capsys, "--data-dir", data, "--info", tmp_path / "info.json", "--kind", "animals")
    assert code == 0, err
    assert json.loads(out)["written"] == 5
    n_body = synthetic_animation(2)[3]
    for action, frames in info["catBG"].items():
        anime = data / "DeformingThings4D" / "animals" / f"catBG_{action}" / f"catBG_{action}.anime"
        raw_order = np.fromfile(anime, dtype=np.float32, count=3 * 174, offset=12).reshape(-1, 3)
        for k in frames:
            path = data / "dt4d_animals" / "catBG" / f"{action}{k:03d}.obj"
            ref = reference_frame(anime, k)
            # the body (hole filled: 320 faces), not the small component; rows in trimesh's split order
            assert len(ref.vertices) == n_body and len(ref.faces) == 320
            assert not np.allclose(ref.vertices, raw_order[:n_body])  # the shuffle matters
            back = trimesh.load(path, process=False, maintain_order=True, force="mesh")
            ours = read_mesh(path)
            for got in (np.asarray(back.vertices), ours.vertices):
                assert got.shape == ref.vertices.shape
                assert np.abs(got - ref.vertices).max() <= 1e-6
            assert np.array_equal(np.asarray(back.faces), ref.faces) and np.array_equal(ours.faces, ref.faces)
            assert path.read_text() == ref.export(file_type="obj")  # the reference's mesh.export bytes
    print(
        f"\n{sum(map(len, info['catBG'].values()))} frames equal the reference procedure "
        f"({n_body} vertices, 320 faces each; max |dv| <= 1e-6; files equal to the reference's export)"
    )


def test_a_prepared_obj_is_rewritten_only_when_its_anime_changed(tmp_path, capsys):
    data = tmp_path / "data"
    make_download(data, "animals", {"catBG": {"run": 20, "walk": 20}})
    info_path = tmp_path / "info.json"
    info_path.write_text(json.dumps({"catBG": {"run": [1, 2], "walk": [3]}}))
    args = ("--data-dir", data, "--info", info_path, "--kind", "animals")
    assert run_cli(capsys, *args)[0] == 0
    objs = sorted((data / "dt4d_animals" / "catBG").glob("*.obj"))
    mtimes = {p: p.stat().st_mtime_ns for p in objs}
    stamp = json.loads((data / "dt4d_animals" / "catBG" / ".becos-dt4d.json").read_text())
    assert set(stamp["animations"]) == {"run", "walk"} and len(stamp["animations"]["run"]["sha256"]) == 64

    code, out, _ = run_cli(capsys, *args)  # unchanged: nothing read or written
    assert code == 0 and json.loads(out)["written"] == 0 and json.loads(out)["animations_read"] == 0
    run = data / "DeformingThings4D" / "animals" / "catBG_run" / "catBG_run.anime"
    os.utime(run, ns=(time.time_ns(), time.time_ns() + 10**9))  # re-extracted: same bytes, new mtime
    code, out, _ = run_cli(capsys, *args)
    assert code == 0 and json.loads(out)["written"] == 0
    assert {p: p.stat().st_mtime_ns for p in objs} == mtimes

    killed = data / "dt4d_animals" / "catBG" / ".run001.obj.k1ll3d.tmp"  # what a killed atomic write leaves
    killed.write_text("v 0 0")
    frame0, faces, offsets, _ = synthetic_animation(20, seed=99)  # new content: its frames only
    write_anime(run, frame0, faces, offsets)
    code, out, _ = run_cli(capsys, *args)
    assert code == 0 and json.loads(out)["written"] == 2
    changed = {p.name for p in objs if p.stat().st_mtime_ns != mtimes[p]}
    assert changed == {"run001.obj", "run002.obj"}
    assert not list((data / "dt4d_animals" / "catBG").glob(".*.tmp*"))


def _corrupt(path: Path, edit) -> None:
    data = bytearray(path.read_bytes())
    path.write_bytes(bytes(edit(data)))


def _set(dtype: str, offset: int, value):
    def edit(data: bytearray) -> bytearray:
        data[offset : offset + 4] = np.array([value], dtype=dtype).tobytes()
        return data

    return edit


NV, NT = 174, 339  # icosphere(2) body + 12-vertex component; 319 + 20 faces
FACES_AT = 12 + 12 * NV
OFFSETS_AT = FACES_AT + 12 * NT

BAD_INPUTS = {
    # case: (edit of the .anime bytes, listed frames, words the message must hold)
    "truncated file": (lambda d: d[: FACES_AT + 100], [1], ["is truncated", "needs"]),
    "header shorter than 12 bytes": (lambda d: d[:7], [1], ["is truncated", "12-byte header"]),
    "counts inconsistent with the size": (
        _set("<i4", 0, 30),
        [1],
        ["counts are inconsistent with the file size", "nf=30"],
    ),
    "extra bytes": (lambda d: d + bytes(24), [1], ["counts are inconsistent with the file size"]),
    "frame id beyond nf": (None, [1, 20], ["frame 20", "has 20 frames"]),
    "face index >= nv": (_set("<i4", FACES_AT + 4 * 7, NV), [1], ["outside [0, 174)"]),
    "negative face index": (_set("<i4", FACES_AT, -3), [1], ["outside [0, 174)"]),
    "NaN position": (_set("<f4", OFFSETS_AT + 12 * NV * 0 + 4 * 5, np.nan), [1], ["frame 1", "NaN or infinite"]),
    "infinite position": (_set("<f4", 12 + 8, np.inf), [0], ["frame 0", "NaN or infinite"]),
    "missing .anime": ("delete", [1], ["animation file is missing", "catBG/run", "request DeformingThings4D"]),
}


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_anime_input_names_file_problem_and_fix(tmp_path, capsys, case):
    edit, frames, words = BAD_INPUTS[case]
    data = tmp_path / "data"
    make_download(data, "animals", {"catBG": {"run": 20}})
    anime = data / "DeformingThings4D" / "animals" / "catBG_run" / "catBG_run.anime"
    assert anime.stat().st_size == OFFSETS_AT + 19 * 12 * NV
    if edit == "delete":
        anime.unlink()
    elif edit is not None:
        _corrupt(anime, edit)
    (tmp_path / "info.json").write_text(json.dumps({"catBG": {"run": frames}}))
    code, out, err = run_cli(capsys, "--data-dir", data, "--info", tmp_path / "info.json", "--kind", "animals")
    assert code == 2 and "Traceback" not in err
    assert str(anime) in err and "Fix:" in err, err
    for word in words:
        assert word in err, (case, err)
    assert not list((data / "dt4d_animals").rglob("*.obj"))
    print(f"\n{case}: {err.strip()}")


def test_the_installed_command_exits_2_without_a_traceback(tmp_path):
    data = tmp_path / "data"
    make_download(data, "animals", {"catBG": {"run": 20}})
    anime = data / "DeformingThings4D" / "animals" / "catBG_run" / "catBG_run.anime"
    _corrupt(anime, lambda d: d[: FACES_AT + 100])
    (tmp_path / "info.json").write_text(json.dumps({"catBG": {"run": [1]}}))
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "becos",
            "prepare-dt4d",
            "--data-dir",
            str(data),
            "--info",
            str(tmp_path / "info.json"),
            "--kind",
            "animals",
        ],
        capture_output=True,
        text=True,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
    )
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert f"{anime}: is truncated" in result.stderr and "Fix: re-download" in result.stderr


# --- (b) the workflow ------------------------------------------------------------------------------
def dt4d_annotations(becos_code: Path, root: Path, info: dict) -> Path:
    """The BeCoS annotation folder with ``info`` as its ``data/info_dt4d_animals.json`` (the rest linked)."""
    (root / "data").mkdir(parents=True, exist_ok=True)
    for sub in ("config", "corres_comp", "precomputed_chirality_templates", "precomputed_corr_templates"):
        if not (root / sub).exists():
            (root / sub).symlink_to(becos_code / sub)
    (root / "data" / "info_dt4d_animals.json").write_text(json.dumps(info))
    return root


def dt4d_registry(root: Path, info: dict) -> Path:
    """A dataset registry whose dt4d_animal.yaml expects the shapes ``info`` lists."""
    import yaml

    from becos.sources.datasets import CONFIG_DIR

    raw = yaml.safe_load((CONFIG_DIR / "dt4d_animal.yaml").read_text())
    raw["expected_count"] = sum(len(frames) for actions in info.values() for frames in actions.values())
    root.mkdir(parents=True, exist_ok=True)
    (root / "dt4d_animal.yaml").write_text(yaml.safe_dump(raw))
    return root


def test_workflow_prepares_catalogs_remeshes_and_pairs_dt4d(becos_code, tmp_path, monkeypatch):
    """catBG first, then leopardSLM added: only leopardSLM's preparation (and its remeshes) run again.

    Both classes are real DT4D classes with their real template rows (catBG/run043, leopardSLM/roam024,
    both train) and their real network edge, an identity one (the annotation folder lists them as
    sharing a triangulation), so the synthetic classes share one triangulation here too."""
    from snakemake_cmd import snakemake
    from test_workflow import jobs_planned
    from tiny_tosca import write_config_file

    from becos.products.store import open_benchmark

    data, workdir = tmp_path / "data", tmp_path / "run"
    first = {"catBG": {"run": [43, 7, 12]}}
    make_download(data, "animals", {"catBG": {"run": 50}})
    annotations = dt4d_annotations(becos_code, tmp_path / "becos-code", first)
    monkeypatch.setenv("BECOS_DATASETS_DIR", str(dt4d_registry(tmp_path / "registry", first)))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    write_config_file(
        workdir,
        {
            "synthetic": {"enabled": False},
            "data_dir": str(data),
            "annotations": str(annotations),
            "datasets": ["dt4d_animal"],
            "template_file": "templates_all.csv",
            "setting": "partial_partial",
            "remesh_variants": 1,
            "store_vis": False,
            "propagate_annotations": False,
            "n_chunks": 2,
            "caps": {"train": 3, "val": 0, "test": 0},
            "exports": {"released": False, "published_pickle": False, "report": False},
        },
    )
    t0 = time.perf_counter()
    snakemake(workdir, "--cores", "1")
    t1 = time.perf_counter()
    cat = data / "dt4d_animals" / "catBG"
    assert sorted(p.name for p in cat.glob("*.obj")) == ["run007.obj", "run012.obj", "run043.obj"]
    base = workdir / "results" / "partial_partial"
    assert json.loads((base / "validation.json").read_text())["valid"]
    names = set(open_benchmark(base / "benchmark.zarr").table[["x_name", "y_name"]].to_numpy().ravel())
    assert names and names <= {"catBG/run043", "catBG/run007", "catBG/run012"}
    catalog = (workdir / "results" / "catalog.csv").read_text()
    assert catalog.count("dt4d_animal,catBG/") == 3
    before = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in cat.iterdir()}
    remeshed_before = {str(p) for p in (workdir / "results" / "remeshed").rglob("*.npz")}

    second = {**first, "leopardSLM": {"roam": [24, 31]}}
    make_download(data, "animals", {"leopardSLM": {"roam": 50}}, phase=2.0)
    dt4d_annotations(becos_code, annotations, second)
    dt4d_registry(tmp_path / "registry", second)
    dry = snakemake(workdir, "-n", "--cores", "1").stdout
    planned = re.findall(r"wildcards: kind=animals, cls=(\S+)", dry)
    assert planned == ["leopardSLM"], dry[-3000:]
    assert jobs_planned(dry).get("check_datasets") == 1
    t2 = time.perf_counter()
    snakemake(workdir, "--cores", "1")
    t3 = time.perf_counter()
    assert {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in cat.iterdir()} == before  # catBG untouched
    assert sorted(p.name for p in (data / "dt4d_animals" / "leopardSLM").glob("*.obj")) == [
        "roam024.obj",
        "roam031.obj",
    ]
    remeshed_after = {str(p) for p in (workdir / "results" / "remeshed").rglob("*.npz")}
    assert remeshed_before < remeshed_after and all("leopardSLM" in p for p in remeshed_after - remeshed_before)
    assert json.loads((base / "validation.json").read_text())["valid"]
    table = open_benchmark(base / "benchmark.zarr").table
    classes = {n.split("/")[0] for n in table[["x_name", "y_name"]].to_numpy().ravel()}
    assert "leopardSLM" in classes
    # a re-extracted catBG (same bytes, new mtime) reruns its job, which keeps every OBJ: Snakemake must
    # not delete the stamp before the job (update()), and the stamp's sha256 says nothing changed.
    # (Snakemake itself skips a newer input with the recorded checksum, below --max-checksum-file-size,
    # 1 MB by default; real .anime files are larger, so 0 here.)
    anime = data / "DeformingThings4D" / "animals" / "catBG_run" / "catBG_run.anime"
    os.utime(anime, ns=(time.time_ns(), time.time_ns() + 10**9))
    snakemake(workdir, "--cores", "1", "--max-checksum-file-size", "0", str(cat / ".becos-dt4d.json"))
    assert "0 frames written, 3 kept" in (workdir / "logs" / "prepare_dt4d" / "animals" / "catBG.log").read_text()
    assert {p: p.stat().st_mtime_ns for p in cat.glob("*.obj")} == {
        p: m for p, (m, _) in before.items() if p.suffix == ".obj"
    }
    print(
        f"\nfirst run (catBG) {t1 - t0:.1f} s; second run (+leopardSLM) {t3 - t2:.1f} s, prepare jobs planned: "
        f"{planned}; pairs: "
        f"{table[['x_name', 'y_name']].to_numpy().tolist()}"
    )


def test_check_without_dt4d_says_what_to_request_and_where_to_put_it(becos_code, tmp_path):
    from becos.sources.check import DatasetCheckError, check_datasets

    data = tmp_path / "data"
    data.mkdir()
    with pytest.raises(DatasetCheckError) as info:
        check_datasets(["dt4d_animal"], data, becos_code, read_meshes=False)
    text = str(info.value)
    assert "dataset 'dt4d_animal' (DeformingThings4D animals) not found" in text
    assert "request DeformingThings4D through the Google form" in text
    assert f"unpack the download into {data / 'DeformingThings4D'}" in text
    assert f"prepares {data / 'dt4d_animals'} from {data / 'DeformingThings4D' / 'animals'}" in text
    assert "is present but not prepared yet" not in text
    (data / "DeformingThings4D" / "animals").mkdir(parents=True)  # download there, not yet prepared
    with pytest.raises(DatasetCheckError, match="is present but not prepared yet: run the workflow"):
        check_datasets(["dt4d_animal"], data, becos_code, read_meshes=False)
    print(f"\n{text}")


def test_the_plan_has_one_job_per_class_and_leaves_a_missing_anime_to_the_job(tmp_path):
    from becos.sources.dt4d import preparation_plan

    data, annotations = tmp_path / "data", tmp_path / "becos-code"
    info = {"catBG": {"run": [1, 2]}, "leopardSLM": {"roam": [3], "walk": [4]}}
    (annotations / "data").mkdir(parents=True)
    (annotations / "data" / "info_dt4d_animals.json").write_text(json.dumps(info))
    config = (data, ["tosca", "dt4d_animal"], annotations)
    assert preparation_plan(*config) == []  # no DeformingThings4D: the check explains
    make_download(data, "animals", {"catBG": {"run": 5}, "leopardSLM": {"roam": 5}})  # leopardSLM_walk missing
    jobs = {job.cls: job for job in preparation_plan(*config)}
    assert sorted(jobs) == ["catBG", "leopardSLM"]
    assert [p.name for p in jobs["leopardSLM"].anime] == ["leopardSLM_roam.anime"]
    assert jobs["catBG"].stamp == data / "dt4d_animals" / "catBG" / ".becos-dt4d.json"
    assert json.loads(jobs["leopardSLM"].listing) == info["leopardSLM"]
    code = becos_main(
        [
            "prepare-dt4d",
            "--data-dir",
            str(data),
            "--info",
            str(jobs["leopardSLM"].info),
            "--kind",
            "animals",
            "--classes",
            "leopardSLM",
        ]
    )
    assert code == 2 and not (data / "dt4d_animals" / "leopardSLM" / "walk004.obj").exists()
