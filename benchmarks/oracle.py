"""becos under ``original_settings`` against the reference generator's own output (``reference_oracle/``).

Run: ``python benchmarks/oracle.py [--results DIR]`` (JSON on stdout, the per-pair table on stderr).

For every oracle pair (``reference_oracle/<setting>/<split>/<index>/``, ``index`` = position in that
split's list of the published pickle) this builds what the workflow builds with ``original_settings:
true`` on TOSCA (resolved config, catalog, published manifest written and read back as CSV, one
``becos remesh`` stage per shape and face target) and compares, for ``full_full``:

- ``fwd``: our remesh file (common frame), re-centred and carried forward with the info pickles'
  ``surface_area``, ``align_rotation``/``align_translation`` (Y) and ``random_rotation`` into the
  reference's output frame, against ``0_<x>.off`` / ``1_<y>.off``: max |Δ| (vertices in output units);
- ``undo``: the oracle's vertices carried back (rotation, alignment undone) against our re-centred
  remesh: max |Δ|;
- ``bitwise``: the reference's remesh of the file (:func:`becos.build.reference_remesh.reference_remesh`)
  carried forward exactly as the reference computes it: max |Δ| (0 = bit for bit);
- ``faces``: identical face arrays; ``rot``: the manifest's rotation (the one the pairs stage applies)
  bitwise equal to the info pickle's ``random_rotation``; ``area``: relative difference of our
  sqrt-area to ``surface_area``;
- ``corres``: for pairs of one TOSCA class (identity hop between the originals), the reference's
  rounded vertex maps (:attr:`ReferenceRemesh.remeshed_to_source` / ``source_to_remeshed``) composed
  equal ``corres_01`` / ``corres_10``.

For ``partial_partial`` pairs the rotations are compared (``rot``).
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def becos_code() -> Path:
    out = subprocess.run(
        [str(REPO.parent / "shared" / "unpack")], check=True, capture_output=True, text=True
    ).stdout.strip()
    return Path(out.splitlines()[-1])


def oracle_pairs(root: Path, setting: str) -> list[tuple[str, int, Path]]:
    """(split, published index, folder) of every oracle pair of ``setting``, sorted."""
    base = root / "reference_oracle" / setting
    return sorted((p.parent.name, int(p.name), p) for p in base.glob("*/*") if p.is_dir())


def oracle_side(folder: Path, side: int) -> tuple[str, np.ndarray, np.ndarray, dict]:
    """(name, vertices, faces, info) of side 0 (x) or 1 (y) of an oracle pair folder."""
    import trimesh

    off = next(p for p in folder.glob(f"{side}_*.off"))
    name = off.stem[2:]
    mesh = trimesh.load(off, process=False, maintain_order=True)
    with open(folder / f"{side}_{name}_info.pkl", "rb") as fh:
        info = pickle.load(fh)
    return name, np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64), info


def published_setup(root: Path, results: Path, settings: tuple[str, ...]) -> dict:
    """The resolved ``original_settings`` config on TOSCA, its plan and manifests (written and read
    back as the chunk jobs read them)."""
    from becos.build.sampling import read_manifest, write_manifest
    from becos.workflow import Plan, build_catalog, build_manifest, resolve_config

    config = resolve_config(
        {
            "data_dir": str(root / "data"),
            "annotations": str(root),
            "datasets": ["tosca"],
            "original_settings": True,
            "setting": list(settings),
            "results": str(results),
        }
    )
    catalog = build_catalog(config)
    manifests = {}
    for setting in settings:
        path = results / setting / "manifest.csv"
        write_manifest(build_manifest(config, setting, catalog), path)
        manifests[setting] = read_manifest(path)
    return {"config": config, "plan": Plan(config, catalog, manifests), "manifests": manifests}


def manifest_row(manifest, split: str, index: int) -> dict:
    rows = manifest[(manifest["split"] == split) & (manifest["published_index"] == index)]
    if len(rows) != 1:
        raise LookupError(f"published pair {split}/{index} is not in the manifest ({len(rows)} rows)")
    return rows.iloc[0].to_dict()


class StageRemeshes:
    """Remesh files written by the workflow's own remesh stage (one per shape and token), kept."""

    def __init__(self, setup: dict):
        from becos.workflow import job_options

        self.plan = setup["plan"]
        self.options = json.loads(job_options(setup["config"], "remesh"))
        self.seconds: dict[tuple[str, str], float] = {}
        self._done: dict[tuple[str, str], object] = {}

    def get(self, dataset: str, name: str, token: str):
        from becos.build.remesh import load_remeshed
        from becos.workflow import remesh_stage

        key = (name, token)
        if key not in self._done:
            # the stage writes a folder whole: one variant's, whose file then goes where the layout puts it
            folder = self.plan.layout.remeshed_folder(dataset, name) / f".{token}"
            out = self.plan.layout.remeshed(dataset, name, token)
            start = time.perf_counter()
            row = {**json.loads(self.plan.shape_json(dataset, name)), "file": self.plan.files[(dataset, name)]}
            remesh_stage(self.options, row, [token], folder, ply=False)
            os.replace(folder / out.name, out)
            shutil.rmtree(folder)
            self.seconds[key] = time.perf_counter() - start
            self._done[key] = load_remeshed(out)
        return self._done[key]


def compare_full_side(remeshed, oracle_vertices: np.ndarray, oracle_faces: np.ndarray, info: dict) -> dict:
    """Our remesh file vs one side of an oracle full_full pair (see the module docstring)."""
    from becos.build.reference_remesh import reference_output, sqrt_area, undo_reference_output

    ours = remeshed.mesh.vertices - np.mean(remeshed.mesh.vertices, axis=0)
    align = (info["align_rotation"], info["align_translation"]) if info["align_rotation"] is not None else (None, None)
    same_shape = ours.shape == oracle_vertices.shape
    forward = reference_output(ours, info["surface_area"], info["random_rotation"], *align)
    undone = undo_reference_output(oracle_vertices, info["random_rotation"], *align)
    return {
        "n_vertices": int(len(ours)),
        "n_faces": int(len(remeshed.mesh.faces)),
        "faces_identical": bool(np.array_equal(remeshed.mesh.faces, oracle_faces)),
        "max_abs_diff_forward": float(np.abs(forward - oracle_vertices).max()) if same_shape else float("inf"),
        "max_abs_diff_undo": float(np.abs(undone - ours).max()) if same_shape else float("inf"),
        "sqrt_area_rel_diff": abs(sqrt_area(ours, remeshed.mesh.faces) / info["surface_area"] - 1.0),
    }


def bitwise_side(
    root: Path, name: str, target_faces: int, scale: float, rot_deg, info: dict, oracle_vertices: np.ndarray
):
    """The reference's remesh of the file carried forward exactly as the reference does:
    (max |Δ| to the oracle's vertices, the :class:`ReferenceRemesh`, seconds)."""
    from becos.build.reference_remesh import open3d_rotation, reference_output, reference_pose, reference_remesh
    from becos.core.mesh import read_mesh

    start = time.perf_counter()
    ref = reference_remesh(read_mesh(root / "data" / "tosca-off" / f"{name}.off"), target_faces)
    seconds = time.perf_counter() - start
    align = (info["align_rotation"], info["align_translation"]) if info["align_rotation"] is not None else (None, None)
    posed = reference_pose(ref.mesh.vertices, scale, open3d_rotation(rot_deg))
    out = reference_output(posed, info["surface_area"], info["random_rotation"], *align)
    diff = float(np.abs(out - oracle_vertices).max()) if out.shape == oracle_vertices.shape else float("inf")
    return diff, ref, seconds


def casting_frames(root: Path, row: dict, infos: tuple[dict, dict], spec) -> tuple:
    """The reference's remeshes of a pair's shapes in its casting frame (facts §7.4): posed, Y aligned as
    the info pickle records, each divided by its sqrt-area. Returns ((vertices, faces, ReferenceRemesh)
    of x, of y)."""
    from becos.build.reference_remesh import open3d_rotation, reference_pose, reference_remesh
    from becos.core.mesh import read_mesh

    out = []
    for side, info in zip(("x", "y"), infos):
        ref = reference_remesh(
            read_mesh(root / "data" / "tosca-off" / f"{row[side + '_name']}.off"), int(row[f"{side}_face_target"])
        )
        posed = reference_pose(ref.mesh.vertices, spec.scale, open3d_rotation(spec.rotation_deg))
        if info["align_rotation"] is not None:
            posed = posed @ info["align_rotation"] + info["align_translation"]
        out.append((posed / info["surface_area"], ref.mesh.faces, ref))
    return tuple(out)


def compare_partial_pair(
    root: Path, setup: dict, row: dict, folder: Path, spec, cast: bool = True, stage: StageRemeshes | None = None
) -> dict:
    """Our views of an oracle partial_partial pair from the published cameras vs the reference's partials.

    The kept try: the one whose camera the info pickles record when its overlaps are in range, else the
    LAST try (the reference keeps the last try's geometry, facts §7.5). Per side: where the triangle
    ids came from (``file`` / ``cast``), vertex counts, identical triangle sets, identical kept full
    faces (equal whichever diagonal fills a 4-edge hole) and ``partial2full``; with ``cast``, the
    Jaccard index of our 5000² cast from the side's own camera against the file (in the pair's casting
    frame; for Y also in its own unaligned frame: a shipped file of a train shape may come from a pair
    where it was X); with ``stage`` (the
    remesh files), the overlap masks (:func:`compare_masks`)."""
    from becos.build.reference_remesh import open3d_rotation, reference_pose
    from becos.build.reference_views import (
        cast_pinhole,
        full_faces_covering,
        full_triangles,
        pair_view_files,
        read_triangle_ids,
        reference_component,
    )

    sides = [oracle_side(folder, i) for i in (0, 1)]
    infos = (sides[0][3], sides[1][3])
    cams = np.asarray(_published_cameras(setup)[row["pair_id"]])  # (2, 10, 3)
    k_cam = int(np.flatnonzero(np.all(cams[0] == infos[0]["cam_pos"], axis=1))[0])
    lo, hi = setup["config"]["min_overlap"], setup["config"]["max_overlap"]
    accepted = all(lo <= i["overlap_percentage"] <= hi for i in infos)
    k = k_cam if accepted else len(cams[0]) - 1
    frames = casting_frames(root, row, infos, spec)
    files = pair_view_files(root, "partial_partial", row["x_name"], row["y_name"], cams[0], k)
    out = {"try": k, "accepted": accepted}
    comps = []
    for i, side in enumerate(("x", "y")):
        vertices, faces, _ = frames[i]
        start = time.perf_counter()
        if files[i].is_file():
            ids, source = read_triangle_ids(files[i], len(faces)), "file"
        else:
            ids, source = cast_pinhole(vertices, faces, cams[i][k]), "cast"
        seconds_view = time.perf_counter() - start
        comp = reference_component(vertices, faces, ids)
        jaccard = jaccard_own = None
        if cast and source == "file":  # the cast the reference would do without the file, against the file
            jaccard = _jaccard(cast_pinhole(vertices, faces, cams[i][k]), ids)
            if i == 1:  # Y in its own, unaligned frame (as when it was the X of another pair)
                own = reference_pose(frames[1][2].mesh.vertices, spec.scale, open3d_rotation(spec.rotation_deg))
                jaccard_own = _jaccard(cast_pinhole(own / infos[1]["surface_area"], faces, cams[i][k]), ids)
        _, o_vertices, o_faces, info = sides[i]
        out[side] = {
            "view_source": source,
            "seconds_view": round(seconds_view, 2),
            "cast_jaccard_vs_file": jaccard,
            "cast_unaligned_jaccard_vs_file": jaccard_own,
            "n_partial_vertices": int(len(comp.partial_vertices)),
            "n_oracle_vertices": int(len(o_vertices)),
            "same_triangles": full_triangles(comp.partial_faces, comp.partial_to_full)
            == full_triangles(o_faces, info["partial2full"]),
            "same_kept_full_faces": bool(
                np.array_equal(
                    comp.kept_faces, full_faces_covering(faces, len(vertices), info["partial2full"][o_faces])[0]
                )
            ),
            "same_partial2full": bool(np.array_equal(comp.partial_to_full, info["partial2full"])),
            "fill_faces_not_in_full_mesh": comp.unmatched_faces,
        }
        comps.append(comp)
    if stage is not None:
        out["masks"] = compare_masks(setup, stage, row, folder, comps, [f[2] for f in frames])
    return out


def pair_ground_truth(setup: dict, stage: StageRemeshes, row: dict):
    """``([Remeshed x, Remeshed y], {"xy": SurfaceMap, "yx": SurfaceMap})``: the remesh stage's files and
    becos's exact ground truth between them (the network, as the ground-truth stage computes it)."""
    from becos.workflow import ShapeStore, remesh_token

    key = ("gt", row["x_name"], row["y_name"])
    if key not in setup:
        if "shapes" not in setup:
            setup["shapes"] = ShapeStore(setup["config"], setup["plan"].catalog)
        shapes = setup["shapes"]
        names = (row["x_name"], row["y_name"])
        remeshed = [stage.get("tosca", n, remesh_token(row, s, True)) for n, s in zip(names, ("x", "y"))]
        entries = [shapes.entry("tosca", n) for n in names]
        setup[key] = (
            remeshed,
            {
                "xy": shapes.network.ground_truth(entries[0], entries[1], x_remesh=remeshed[0], y_remesh=remeshed[1]),
                "yx": shapes.network.ground_truth(entries[1], entries[0], x_remesh=remeshed[1], y_remesh=remeshed[0]),
            },
        )
    return setup[key]


def compare_published_try(root: Path, setup: dict, stage: StageRemeshes, row: dict, folder: Path) -> dict:
    """becos's own run of a published P2P pair (:func:`becos.build.reference_views.published_p2p`: its casting
    frames from the remesh files and its exact ground truth, views from the shipped files or cast) vs the
    oracle: the kept try, the recorded camera's try, the reference rule's overlaps against the info
    pickles' ``overlap_percentage``, the kept full faces, becos's exact rule's try, and the angle
    between our alignment and the recorded ``align_rotation``."""
    from becos.build.reference_views import PublishedViews, casting_frames, full_faces_covering, published_p2p

    remeshed, gt = pair_ground_truth(setup, stage, row)
    x, y = remeshed[0].mesh, remeshed[1].mesh
    infos = [oracle_side(folder, i) for i in (0, 1)]
    cams = np.asarray(_published_cameras(setup)[row["pair_id"]])
    frames = casting_frames(x, y, gt["xy"])
    views = PublishedViews(
        root, row["x_name"], row["y_name"], cams, (frames.x_vertices, frames.y_vertices), (x.faces, y.faces)
    )
    config = setup["config"]
    start = time.perf_counter()
    got = published_p2p(
        x, y, gt["xy"], gt["yx"], views, config["n_cam_pos"], config["min_overlap"], config["max_overlap"]
    )
    seconds = time.perf_counter() - start
    k_cam = int(np.flatnonzero(np.all(cams[0] == infos[0][3]["cam_pos"], axis=1))[0])
    lo, hi = config["min_overlap"], config["max_overlap"]
    accepted = all(lo <= i[3]["overlap_percentage"] <= hi for i in infos)
    expected = [
        full_faces_covering(m.faces, m.n_vertices, i[3]["partial2full"][i[2]])[0] for m, i in zip((x, y), infos)
    ]
    cos = (np.trace(frames.rotation.T @ infos[1][3]["align_rotation"]) - 1) / 2
    return {
        "try": got.try_index,
        "oracle_try": k_cam if accepted else cams.shape[1] - 1,
        "camera_try": got.camera_try,
        "oracle_camera_try": k_cam,
        "accepted": got.accepted,
        "reference_rule_overlaps": [float(v) for v in got.reference_overlaps[got.try_index]],
        "oracle_overlaps": [float(infos[1][3]["overlap_percentage"]), float(infos[0][3]["overlap_percentage"])],
        "exact_overlaps": [float(v) for v in got.exact_overlaps[got.try_index]],
        "exact_try": got.exact_try,
        "exact_differs": got.exact_differs,
        "same_kept_faces": bool(np.array_equal(got.kept_x, expected[0]) and np.array_equal(got.kept_y, expected[1])),
        "alignment_angle_deg": float(np.degrees(np.arccos(np.clip(cos, -1, 1)))),
        "sources": sorted(set(views.sources.values())),
        "seconds": round(seconds, 2),
    }


def compare_masks(setup: dict, stage: StageRemeshes, row: dict, folder: Path, comps, refs) -> dict:
    """Overlap masks of the kept views: becos's exact ground truth vs the reference's masks.

    Per direction (``xy``: over partial-X vertices, the reference's mask in Y's info pickle; ``yx``
    the converse): ``share_all`` = share of partial vertices whose masks agree; ``share_gt_agree``
    = the same share among the vertices where the two ground truths agree, i.e. the reference's
    rounded target vertex is a corner of our exact ground-truth face (or both have none). The
    reference's full ground truth is its rounded vertex maps composed for a pair of one TOSCA class
    (identity hop); otherwise it is known only where its partial correspondence is not -1.
    ``share_differ_at_border``: of the vertices whose ground truths agree but masks differ, the share
    whose reference target vertex lies on partial B's border (the two overlap rules differ there)."""
    from becos.build.partiality import cut, overlap_mask

    plan = setup["plan"]
    names = (row["x_name"], row["y_name"])
    remeshed, gt = pair_ground_truth(setup, stage, row)
    partials = [cut(r.mesh, c.kept_faces) for r, c in zip(remeshed, comps)]
    infos = [oracle_side(folder, i)[3] for i in (0, 1)]
    corres = {"xy": np.load(folder / "corres_01.npy"), "yx": np.load(folder / "corres_10.npy")}
    same_class = plan._catalog_rows[("tosca", names[0])]["class"] == plan._catalog_rows[("tosca", names[1])]["class"]
    out = {}
    for d, (a, b) in (("xy", (0, 1)), ("yx", (1, 0))):
        pa, pb = partials[a], partials[b]
        ours = overlap_mask(pa, gt[d], pb)
        theirs = np.asarray(infos[b]["overlap_mask"], dtype=bool)  # the reference stores it in the other side's info
        assert np.array_equal(pa.partial_to_full, infos[a]["partial2full"])
        full_rows = pa.partial_to_full
        if same_class:
            ref_target = refs[b].source_to_remeshed[refs[a].remeshed_to_source][full_rows]
        else:  # known where the reference found the image in its partial
            ref_target = np.where(corres[d] >= 0, pb.partial_to_full[np.maximum(corres[d], 0)], -2)
        face = gt[d].face[full_rows]
        corners = np.asarray(remeshed[b].mesh.faces)[np.maximum(face, 0)]
        gt_agree = np.where(face >= 0, (corners == ref_target[:, None]).any(axis=1), ref_target == -1)
        agree = ours == theirs
        # the reference counts a vertex when its target VERTEX is in partial B; becos when the target
        # POINT's face is kept: they differ where the target vertex is on partial B's border
        full_b = remeshed[b].mesh
        border = np.zeros(full_b.n_vertices, dtype=bool)
        border[np.asarray(full_b.faces)[~pb.kept_faces].ravel()] = True
        border &= pb.full_to_partial >= 0
        differ = gt_agree & ~agree
        on_border = border[np.maximum(ref_target, 0)] & (ref_target >= 0)
        off_border = gt_agree & ~on_border
        out[d] = {
            "n_differ_gt_agree": int(differ.sum()),
            "n_gt_agree_off_border": int(off_border.sum()),
            "share_gt_agree_off_border": float(agree[off_border].mean()) if off_border.any() else None,
            "share_differ_at_border": float(on_border[differ].mean()) if differ.any() else None,
            "n": int(len(ours)),
            "ours_overlap": float(ours.mean()),
            "reference_overlap": float(theirs.mean()),
            "share_all": float(agree.mean()),
            "n_gt_agree": int(gt_agree.sum()),
            "share_gt_agree": float(agree[gt_agree].mean()) if gt_agree.any() else None,
            "reference_full_gt": "rounded maps" if same_class else "partial correspondences",
        }
    return out


def _published_cameras(setup: dict) -> dict:
    """``{pair_id: (2, 10, 3)}`` cameras of the published partial_partial list."""
    from becos.build.published import import_published

    if "cameras" not in setup:
        config = setup["config"]
        path = Path(config["annotations"]) / "config" / "pairings_original_partial_partial.pkl"
        setup["cameras"] = import_published(
            path,
            setting="partial_partial",
            seed=config["seed"],
            n_variants=config["remesh_variants"],
            n_chunks=config["n_chunks"],
            datasets=config["datasets"],
        ).cameras
    return setup["cameras"]


def rotation_identical(row: dict, info_x: dict, info_y: dict) -> bool:
    from becos.workflow import pair_published_rotations

    rx, ry = pair_published_rotations(row)
    return bool(np.array_equal(rx, info_x["random_rotation"]) and np.array_equal(ry, info_y["random_rotation"]))


def run(results: Path) -> dict:
    from becos.sources.datasets import DatasetSpec
    from becos.workflow import remesh_token

    root = becos_code()
    t0 = time.perf_counter()
    setup = published_setup(root, results, ("full_full", "partial_partial"))
    seconds_setup = time.perf_counter() - t0
    stage = StageRemeshes(setup)
    spec = DatasetSpec.load("tosca")
    rows_out = []
    for split, index, folder in oracle_pairs(root, "full_full"):
        row = manifest_row(setup["manifests"]["full_full"], split, index)
        sides, refs = {}, {}
        infos = []
        for side_index, side in enumerate(("x", "y")):
            name, vertices, faces, info = oracle_side(folder, side_index)
            assert name == row[f"{side}_name"], (name, row[f"{side}_name"])
            token = remesh_token(row, side, True)
            result = compare_full_side(stage.get("tosca", name, token), vertices, faces, info)
            diff, ref, seconds = bitwise_side(root, name, int(token[1:]), spec.scale, spec.rotation_deg, info, vertices)
            result.update(
                name=name,
                token=token,
                max_abs_diff_bitwise=diff,
                seconds_reference_remesh=seconds,
                seconds_remesh_stage=stage.seconds.get((name, token), 0.0),
            )
            sides[side], refs[side] = result, ref
            infos.append(info)
        classes = setup["plan"]._catalog_rows
        same_class = classes[("tosca", row["x_name"])]["class"] == classes[("tosca", row["y_name"])]["class"]
        corres = None
        if same_class:
            c01, c10 = np.load(folder / "corres_01.npy"), np.load(folder / "corres_10.npy")
            corres = bool(
                np.array_equal(refs["y"].source_to_remeshed[refs["x"].remeshed_to_source], c01)
                and np.array_equal(refs["x"].source_to_remeshed[refs["y"].remeshed_to_source], c10)
            )
        rows_out.append(
            {
                "setting": "full_full",
                "split": split,
                "index": index,
                "x": sides["x"],
                "y": sides["y"],
                "random_rotation_identical": rotation_identical(row, *infos),
                "reference_maps_reproduce_corres": corres,
            }
        )
    for split, index, folder in oracle_pairs(root, "partial_partial"):
        row = manifest_row(setup["manifests"]["partial_partial"], split, index)
        (nx, *_, ix), (ny, *_, iy) = oracle_side(folder, 0), oracle_side(folder, 1)
        views = compare_partial_pair(root, setup, row, folder, spec, stage=stage)
        views["published_p2p"] = compare_published_try(root, setup, stage, row, folder)
        rows_out.append(
            {
                "setting": "partial_partial",
                "split": split,
                "index": index,
                "x": {"name": nx, **views["x"]},
                "y": {"name": ny, **views["y"]},
                "try": views["try"],
                "accepted": views["accepted"],
                "masks": views["masks"],
                "published_p2p": views["published_p2p"],
                "random_rotation_identical": rotation_identical(row, ix, iy),
            }
        )
    full = [r for r in rows_out if r["setting"] == "full_full"]
    partial = [r for r in rows_out if r["setting"] == "partial_partial"]
    summary = {
        "remesher": setup["config"]["remesher"],
        "pairs_full_full": len(full),
        "pairs_partial_partial": len(rows_out) - len(full),
        "max_abs_diff_forward": max(max(r["x"]["max_abs_diff_forward"], r["y"]["max_abs_diff_forward"]) for r in full),
        "max_abs_diff_undo": max(max(r["x"]["max_abs_diff_undo"], r["y"]["max_abs_diff_undo"]) for r in full),
        "max_abs_diff_bitwise": max(max(r["x"]["max_abs_diff_bitwise"], r["y"]["max_abs_diff_bitwise"]) for r in full),
        "all_faces_identical": all(r["x"]["faces_identical"] and r["y"]["faces_identical"] for r in full),
        "all_rotations_identical": all(r["random_rotation_identical"] for r in rows_out),
        "partial_sides_same_kept_full_faces": sum(r[s]["same_kept_full_faces"] for r in partial for s in "xy"),
        "partial_sides_same_triangles": sum(r[s]["same_triangles"] for r in partial for s in "xy"),
        "partial_sides_same_partial2full": sum(r[s]["same_partial2full"] for r in partial for s in "xy"),
        "partial_sides": 2 * len(partial),
        "cast_jaccard_vs_file_min": min(
            (r[s]["cast_jaccard_vs_file"] for r in partial for s in "xy" if r[s]["cast_jaccard_vs_file"] is not None),
            default=None,
        ),
        "cast_jaccard_vs_file_best_frame_min": min(
            (
                max(v for v in (r[s]["cast_jaccard_vs_file"], r[s]["cast_unaligned_jaccard_vs_file"]) if v is not None)
                for r in partial
                for s in "xy"
                if r[s]["cast_jaccard_vs_file"] is not None
            ),
            default=None,
        ),
        "mask_share_all": _pooled(partial, "share_all", "n"),
        "mask_share_gt_agree": _pooled(partial, "share_gt_agree", "n_gt_agree"),
        "mask_share_gt_agree_off_border": _pooled(partial, "share_gt_agree_off_border", "n_gt_agree_off_border"),
        "seconds_setup": seconds_setup,
        "seconds_remesh_stage": stage.seconds,
    }
    summary["seconds_remesh_stage"] = {f"{n} {t}": round(s, 2) for (n, t), s in stage.seconds.items()}
    return {"summary": summary, "pairs": rows_out}


def _jaccard(a: np.ndarray, b: np.ndarray) -> float:
    return len(np.intersect1d(a, b)) / max(len(np.union1d(a, b)), 1)


def _pooled(rows: list[dict], share: str, count: str) -> float:
    """A mask share over all partial vertices of all pairs and both directions (weighted by count)."""
    masks = [m for r in rows for m in r["masks"].values() if m[share] is not None]
    return sum(m[share] * m[count] for m in masks) / max(sum(m[count] for m in masks), 1)


def table(report: dict) -> str:
    lines = [
        f"{'setting':15} {'pair':10} {'x / y':22} {'n verts':>12} {'fwd max|d|':>11} {'undo max|d|':>11} "
        f"{'bitwise':>9} {'faces':>6} {'rot':>5} {'corres':>6}"
    ]
    for r in report["pairs"]:
        pair = f"{r['split']}/{r['index']}"
        names = f"{r['x']['name']} / {r['y']['name']}"
        if r["setting"] == "full_full":
            x, y = r["x"], r["y"]
            lines.append(
                f"{r['setting']:15} {pair:10} {names:22} {x['n_vertices']:>5}/{y['n_vertices']:<6} "
                f"{max(x['max_abs_diff_forward'], y['max_abs_diff_forward']):>11.2e} "
                f"{max(x['max_abs_diff_undo'], y['max_abs_diff_undo']):>11.2e} "
                f"{max(x['max_abs_diff_bitwise'], y['max_abs_diff_bitwise']):>9.1e} "
                f"{str(x['faces_identical'] and y['faces_identical']):>6} "
                f"{str(r['random_rotation_identical']):>5} {str(r['reference_maps_reproduce_corres']):>6}"
            )
    lines.append("")
    lines.append(
        f"{'setting':15} {'pair':10} {'x / y':22} {'try':>3} {'acc':>5} {'source x/y':>10} "
        f"{'n verts (ours=oracle)':>22} {'same tri':>8} {'kept':>5} {'p2f':>5} {'cast J x/y/y own':>20} {'rot':>5}"
    )
    for r in report["pairs"]:
        if r["setting"] != "partial_partial":
            continue
        x, y = r["x"], r["y"]
        verts = f"{x['n_partial_vertices']}={x['n_oracle_vertices']} {y['n_partial_vertices']}={y['n_oracle_vertices']}"
        lines.append(
            f"{r['setting']:15} {r['split'] + '/' + str(r['index']):10} {x['name'] + ' / ' + y['name']:22} "
            f"{r['try']:>3} {str(r['accepted']):>5} {x['view_source'] + '/' + y['view_source']:>10} "
            f"{verts:>22} {str(x['same_triangles']) + '/' + str(y['same_triangles']):>8} "
            f"{str(x['same_kept_full_faces'] and y['same_kept_full_faces']):>5} "
            f"{str(x['same_partial2full'] and y['same_partial2full']):>5} "
            f"{_jaccards(x, y):>20} {str(r['random_rotation_identical']):>5}"
        )
    lines.append("")
    lines.append(
        f"{'published_p2p (becos)':26} {'try':>3} {'oracle':>6} {'cam':>3} {'ref-rule overlaps':>17} "
        f"{'oracle overlaps':>15} {'exact overlaps':>14} {'exact try':>9} {'kept':>5} {'align°':>7}"
    )
    for r in report["pairs"]:
        p = r.get("published_p2p")
        if p is None:
            continue
        ov = lambda v: f"{v[0]:.3f}/{v[1]:.3f}"  # noqa: E731
        lines.append(
            f"{r['split'] + '/' + str(r['index']) + ' ' + r['x']['name'] + '/' + r['y']['name']:26} "
            f"{p['try']:>3} {p['oracle_try']:>6} {p['camera_try']:>3} {ov(p['reference_rule_overlaps']):>17} "
            f"{ov(p['oracle_overlaps']):>15} {ov(p['exact_overlaps']):>14} {p['exact_try']:>9} "
            f"{str(p['same_kept_faces']):>5} {p['alignment_angle_deg']:>7.3f}"
        )
    lines.append("")
    lines.append(
        f"{'overlap masks':26} {'dir':>3} {'n':>5} {'ours':>6} {'ref':>6} {'agree':>7} {'n GT=':>6} "
        f"{'agree|GT=':>9} {'at border':>9} {'n GT= off':>9} {'agree':>7}  reference GT from"
    )
    for r in report["pairs"]:
        for d, m in sorted(r.get("masks", {}).items()):
            f = lambda v: "-" if v is None else f"{v:.4f}"  # noqa: E731
            lines.append(
                f"{r['split'] + '/' + str(r['index']) + ' ' + r['x']['name'] + '/' + r['y']['name']:26} "
                f"{d:>3} {m['n']:>5} {m['ours_overlap']:>6.3f} {m['reference_overlap']:>6.3f} "
                f"{m['share_all']:>7.4f} {m['n_gt_agree']:>6} {f(m['share_gt_agree']):>9} "
                f"{f(m['share_differ_at_border']):>9} {m['n_gt_agree_off_border']:>9} "
                f"{f(m['share_gt_agree_off_border']):>7}  {m['reference_full_gt']}"
            )
    return "\n".join(lines)


def _jaccards(x: dict, y: dict) -> str:
    f = lambda v: "-" if v is None else f"{v:.4f}"  # noqa: E731
    return f"{f(x['cast_jaccard_vs_file'])}/{f(y['cast_jaccard_vs_file'])}/{f(y['cast_unaligned_jaccard_vs_file'])}"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, help="results folder (default: a temporary one)")
    args = parser.parse_args(argv)
    if args.results is None:
        with tempfile.TemporaryDirectory() as tmp:
            report = run(Path(tmp))
    else:
        report = run(args.results)
    print(table(report), file=sys.stderr)
    print(json.dumps(report, indent=1, default=float))


if __name__ == "__main__":
    main()
