"""The stage functions: the work of one job of each kind (``becos <sub-command>``, :mod:`becos.cli.workflow`)."""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from becos.atomic import link_or_copy, remove_stale_temporaries, write_text
from becos.build.ground_truth_file import (
    ground_truth_intact,
    load_ground_truth,
    save_ground_truth,
)
from becos.errors import ConfigError
from becos.workflow.layout import centre_file, pair_file, remesh_token, variant_file
from becos.workflow.options import (
    GROUND_TRUTH_VERSION,
    RECORD_VERSION,
    CatalogOptions,
    ExportOptions,
    GroundTruthOptions,
    ManifestOptions,
    PairsOptions,
    RemeshOptions,
    SourceOptions,
    digest,
    pairs_options,
)
from becos.workflow.plan import (
    build_catalog,
    build_manifest,
    chunk_remesh_files,
    remesh_target,
    uses_published_views,
)
from becos.workflow.shapes import RemeshFiles, ShapeKey, ShapeStore, visit_order

if TYPE_CHECKING:
    import pandas as pd  # imported where used: write-config, metadata and remesh jobs start without it

    from becos.core.surface_map import SurfaceMap


def _log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def write_catalog_stage(options: CatalogOptions | dict, out: Path) -> pd.DataFrame:
    """Write the catalog (``options``: the catalog's, or a resolved config) to ``out``."""
    from becos.sources.catalog import write_catalog

    catalog = build_catalog(CatalogOptions.of(options))
    write_catalog(catalog, out)
    counts = catalog.groupby(["dataset", "split"]).size().to_dict()
    _log(f"catalog: {len(catalog)} shapes -> {out}; per dataset/split: {counts}")
    return catalog


def write_manifest_stage(
    options: ManifestOptions | dict, setting: str, catalog_path: Path, out: Path, remesh_files: Path | None = None
) -> pd.DataFrame:
    """Write the pair manifest of ``setting`` (``options``: the manifest's, or a resolved config) to ``out``
    and, to ``remesh_files``, the remesh files each of its chunks reads (:func:`chunk_remesh_files`, JSON)."""
    from becos.build.sampling import write_manifest
    from becos.sources.catalog import read_catalog

    manifest = build_manifest(ManifestOptions.of(options), setting, read_catalog(catalog_path))
    write_manifest(manifest, out)
    if remesh_files is not None:
        lists = chunk_remesh_files(manifest, options)
        write_text(remesh_files, json.dumps(lists, indent=1, sort_keys=True) + "\n")
    report = manifest.attrs.get("report", {})
    _log(f"manifest {setting}: {len(manifest)} pairs -> {out}; {json.dumps(report, sort_keys=True)}")
    return manifest


def remesh_stage(
    options: RemeshOptions | dict, shape_row: dict, tokens: list[str], out_dir: Path, ply: bool = True
) -> None:
    """Remesh the variants ``tokens`` of one shape (prepared, common-frame mesh) into the folder ``out_dir``:
    per token its maps (:func:`becos.workflow.layout.variant_file`) and, with ``ply``, a PLY to look at; and
    the shape's centre (:func:`becos.workflow.layout.centre_file`).

    One process per shape: the mesh is loaded and prepared once and the per-shape part of the remesh
    (:class:`becos.build.remesh.RemeshInput`) is shared by the variants, each variant byte-identical to
    one remeshed alone. The folder is built aside and renamed into place when every variant is written
    (:func:`becos.atomic.atomic_folder`): a killed job leaves no ``out_dir``. ``shape_row`` is the shape's
    catalog row (:mod:`becos.sources.catalog` columns). With ``remesher: reference`` the reference's
    remesh of the file coordinates (:mod:`becos.build.reference_remesh`; a vertex target n becomes the face
    target 2n). Else becos's remesh, with the quadric decimator of config ``decimator``
    (:data:`becos.build.remesh.DECIMATORS`; its fallbacks to pymeshlab are logged). ``options``: the remesh
    stage's (or a resolved config). Logs per variant its CPU seconds by step (``remesh cpu seconds``, for
    ``benchmarks/remesh.py``; the shape's own steps, ``job_start``, ``load``, ``prepare``, with its first
    variant) and a progress line.
    """
    from becos.atomic import atomic_folder
    from becos.build.remesh import RemeshInput, remesh_with_stats, save_remeshed, write_ply

    options = RemeshOptions.of(options)
    shared = {"job_start": time.process_time()}  # CPU seconds of the shape's steps, logged with its first variant
    dataset, name = shape_row["dataset"], shape_row["name"]
    shapes = ShapeStore(options, [shape_row])
    lap = time.process_time()
    shapes.mesh(dataset, name)
    shared["load"], lap = time.process_time() - lap, time.process_time()
    prepared = shapes.prepared(dataset, name)
    shared["prepare"], lap = time.process_time() - lap, time.process_time()
    shape = None if options.remesher == "reference" else RemeshInput(prepared.mesh, source=prepared.entry.path)
    shared["shape"] = time.process_time() - lap
    with atomic_folder(out_dir) as folder:
        np.save(centre_file(folder), prepared.centre, allow_pickle=False)  # inside the folder built aside
        for i, token in enumerate(tokens):
            cpu = dict(shared) if i == 0 else {}  # CPU seconds by step, logged for benchmarks/remesh.py
            target = remesh_target(options.seed, dataset, name, token)
            lap = time.process_time()
            start = time.perf_counter()
            if shape is None:
                from becos.build.reference_remesh import remesh_like_reference

                faces = target.get("target_faces") or 2 * int(target["target_vertices"])
                result, _ = remesh_like_reference(
                    shapes.mesh(dataset, name), prepared, faces, source=prepared.entry.path
                )
                cpu["remesh"] = time.process_time() - lap
            else:
                result, stats = remesh_with_stats(
                    prepared.mesh, **target, source=prepared.entry.path, shape=shape, decimator=options.decimator
                )
                for step, seconds in stats["cpu_seconds"].items():
                    cpu[step] = cpu.get(step, 0.0) + seconds
                _log(f"remesh decimator: {json.dumps({k: stats[k] for k in ('decimator', 'decimator_fallbacks')})}")
            lap = time.process_time()
            out = variant_file(folder, token)
            save_remeshed(out, result)
            if ply:
                write_ply(out.with_suffix(".ply"), result.mesh)
            cpu["save"] = time.process_time() - lap
            _log(f"remesh cpu seconds: {json.dumps({k: round(v, 4) for k, v in cpu.items()})}")
            _log(
                f"remesh {dataset}/{name} {token} ({options.remesher}), variant {i + 1}/{len(tokens)}: "
                f"{prepared.mesh.n_vertices} -> {result.mesh.n_vertices} vertices ({target}) in "
                f"{time.perf_counter() - start:.1f} s"
            )


def stored_key(path: Path, member: str) -> str | None:
    """The input key stored in an .npz (None if absent or unreadable)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            value = str(data[member]) if member in data.files else None
    except Exception:
        return None
    if value is not None and member == "__meta__":
        return json.loads(value).get("input_key")
    return value


def _chunk_rows(manifest_path: Path, chunk: int) -> pd.DataFrame:
    from becos.build.sampling import read_manifest

    manifest = read_manifest(manifest_path)
    return manifest[manifest["chunk"] == int(chunk)]


def read_remesh_files(path: Path, chunk: int) -> RemeshFiles:
    """The remesh files of ``chunk`` that the list file ``path`` names (:func:`write_manifest_stage`)."""
    from becos.errors import InputFileError

    try:
        listed = json.loads(Path(path).read_text())[str(int(chunk))]
        files = {(d, n, t): Path(p) for d, n, t, p in listed}
    except (ValueError, KeyError, TypeError) as exc:
        raise InputFileError(
            path,
            f"holds no list of chunk {chunk}'s remesh files ({type(exc).__name__}: {exc})",
            "re-run the workflow: the manifest job writes it (snakemake --forcerun manifest)",
        ) from None
    return RemeshFiles(Path(path), files)


def _progress(stage: str, setting: str, chunk: int, entries: list[dict], n_rows: int, started: float) -> None:
    """A progress line every 10 pairs and at the end of a chunk."""
    done = len(entries)
    if done % 10 == 0 or done == n_rows:
        _log(
            f"{stage} {setting} chunk {chunk}: {done}/{n_rows} pairs ({sum(e['computed'] for e in entries)} "
            f"computed, the rest up to date) {time.perf_counter() - started:.1f} s"
        )


def _remove_killed_writes(paths: list[Path]) -> None:
    """Before a job writes ``paths``: remove the temporary files a killed run of it left beside them."""
    for folder in {p.parent for p in paths}:
        n = remove_stale_temporaries(folder, [p.name for p in paths if p.parent == folder])
        if n:
            _log(f"removed {n} temporary file(s) left in {folder} by an interrupted run")


def _write_index(path: Path, setting: str, chunk: int, entries: list[dict], started: float) -> dict:
    """Write a chunk's index (pairs, their files, input keys and digests); return its counts.

    The index holds content only, so a resumed or re-ordered run writes the same bytes; what was
    computed or reused and how long it took go to the job's log."""
    computed = sum(e["computed"] for e in entries)
    index = {
        "setting": setting,
        "chunk": int(chunk),
        "n_pairs": len(entries),
        "pairs": sorted(({k: v for k, v in e.items() if k != "computed"} for e in entries), key=lambda e: e["pair_id"]),
    }
    write_text(path, json.dumps(index, indent=1) + "\n")
    _log(
        f"chunk {chunk} of {setting}: {len(entries)} pairs, {computed} computed, {len(entries) - computed} "
        f"reused, {time.perf_counter() - started:.1f} s"
    )
    return {"n": len(entries), "computed": computed}


def missing_indexed_files(index: Path) -> list[Path]:
    """The files a chunk index (:func:`_write_index`) lists that no longer exist; [] for an index that
    does not exist or cannot be read (its job reruns, or fails naming it, anyway)."""
    try:
        entries = json.loads(Path(index).read_text())["pairs"]
        paths = [Path(e["path"]) for e in entries]
    except (OSError, ValueError, KeyError, TypeError):
        return []
    return [p for p in paths if not p.is_file()]


def ground_truth_stage(
    options: GroundTruthOptions | dict,
    setting: str,
    chunk: int,
    out_index: Path,
    *,
    manifest: Path,
    catalog: Path,
    remesh_files: Path,
) -> dict:
    """Ground truth both ways for every pair of a chunk; files already up to date are kept.

    Reads the setting's ``manifest``, the ``catalog``, the remesh variants of the chunk's pairs that the
    list file ``remesh_files`` names (:func:`becos.workflow.plan.chunk_remesh_files`; the paths its rule
    declares) and the original meshes the catalog names; writes ``<pair_id>.npz`` beside ``out_index``.
    ``options``: the ground-truth stage's (or a resolved config).

    Copies of a pair in the chunk (same two shapes in the same order) have the same file: it is written once
    and the other copies' names are hard links to it (:func:`becos.atomic.link_or_copy`; a copy where
    the file system has no hard links). Files are only ever replaced whole, never written in place.
    """
    from becos.sources.catalog import read_catalog

    started = time.perf_counter()
    options = GroundTruthOptions.of(options)
    remesh = options.remesh
    shapes = ShapeStore(options, read_catalog(catalog), remeshed=read_remesh_files(remesh_files, chunk))
    rows = _chunk_rows(manifest, chunk)
    folder = Path(out_index).parent
    _remove_killed_writes([*(pair_file(folder, pid) for pid in rows["pair_id"]), Path(out_index)])
    entries = []
    # the maps between the two shapes of the last computed pair, both ways: a chunk's pairs of the same
    # two shapes (copies, either order) come one after another (visit_order) and share them
    maps: dict[tuple[ShapeKey, ShapeKey], SurfaceMap] = {}
    made: dict[str, Path] = {}  # input key -> this chunk's file holding it (written or found intact)
    linked = 0
    ordered, last_used = visit_order(rows.to_dict("records"), remesh)
    for row, done in zip(ordered, last_used):
        tx, ty = remesh_token(row, "x", remesh), remesh_token(row, "y", remesh)
        key = _ground_truth_key(row, tx, ty, shapes, options)
        path = pair_file(folder, row["pair_id"])
        computed = stored_key(path, "input_key") != key
        if not computed and not ground_truth_intact(path):
            _log(
                f"{path}: its content no longer matches the digest becos recorded when writing it (edited or "
                f"replaced by hand?); recomputing it"
            )
            computed = True
        same = made.get(key) if computed else None  # a copy's file above (same shapes, same order)
        if same is not None:
            linked += link_or_copy(same, path)
        elif computed:
            x, y = shapes.entry(row["x_dataset"], row["x_name"]), shapes.entry(row["y_dataset"], row["y_name"])
            kx, ky = (x.dataset, x.name, tx), (y.dataset, y.name, ty)
            if (kx, ky) not in maps:
                rx, ry = shapes.remeshed(x.dataset, x.name, tx), shapes.remeshed(y.dataset, y.name, ty)
                gt_xy = shapes.network.ground_truth(x, y, x_remesh=rx, y_remesh=ry)
                gt_yx = shapes.network.ground_truth(y, x, x_remesh=ry, y_remesh=rx)
                maps = {(kx, ky): gt_xy, (ky, kx): gt_yx}
            gt_xy, gt_yx = maps[(kx, ky)], maps[(ky, kx)]
            save_ground_truth(path, key, gt_xy, gt_yx)
        made.setdefault(key, path)
        entries.append(
            {
                "pair_id": row["pair_id"],
                "path": str(path),
                "input_key": key,
                "computed": computed,
                "digest": shapes.file_digest(same or path),  # a link's bytes are its source's: hashed once
            }
        )
        shapes.release(done)
        _progress("ground truth", setting, chunk, entries, len(rows), started)
    if linked:
        _log(f"ground truth {setting} chunk {chunk}: {linked} file(s) hard-linked to a copy's identical file")
    return _write_index(Path(out_index), setting, chunk, entries, started)


def _ground_truth_key(row: dict, tx: str, ty: str, shapes: ShapeStore, options: GroundTruthOptions) -> str:
    """The input key of a pair's ground-truth file: the digest of its two shapes and remesh tokens
    ``tx``, ``ty``, their files, the edge files between them and the stage's options. Not the pair id:
    copies of a pair (same shapes, same order) have the same key and the same file."""
    return digest(
        {
            "version": GROUND_TRUTH_VERSION,
            "x": [row["x_dataset"], row["x_name"], tx],
            "y": [row["y_dataset"], row["y_name"], ty],
            "sources": [
                shapes.source_digest(row["x_dataset"], row["x_name"], tx),
                shapes.source_digest(row["y_dataset"], row["y_name"], ty),
            ],
            "edges": shapes.edge_digests(
                shapes.entry(row["x_dataset"], row["x_name"]), shapes.entry(row["y_dataset"], row["y_name"])
            ),
            "options": options.key_options(),
        }
    )


def pairs_stage(
    options: PairsOptions | dict,
    setting: str,
    chunk: int,
    gt_index: Path,
    out_index: Path,
    *,
    manifest: Path,
    catalog: Path,
    remesh_files: Path,
    triangle_ids: Path | None = None,
) -> dict:
    """Pair records (partiality, alignment, rotation, annotations) for every pair of a chunk.

    Reads the setting's ``manifest``, the ``catalog``, the ground-truth files listed in ``gt_index``, the
    remesh variants the list file ``remesh_files`` names and, for published P2P views, the shipped triangle ids in the
    folder ``triangle_ids`` (None: every view is cast); writes ``<pair_id>.npz`` beside ``out_index``.
    ``options``: the pairs stage's of ``setting`` (or a resolved config).
    """
    from becos.build.record import is_intact
    from becos.sources.catalog import read_catalog

    started = time.perf_counter()
    stage = pairs_options(options, setting)
    shapes = ShapeStore(stage, read_catalog(catalog), remeshed=read_remesh_files(remesh_files, chunk))
    gt_files = {e["pair_id"]: e for e in json.loads(Path(gt_index).read_text())["pairs"]}
    rows = _chunk_rows(manifest, chunk)
    folder = Path(out_index).parent
    _remove_killed_writes([*(pair_file(folder, pid) for pid in rows["pair_id"]), Path(out_index)])
    build = _RecordBuilder(stage, shapes, gt_index, triangle_ids)
    entries = []
    ordered, last_used = visit_order(rows.to_dict("records"), stage.remesh)
    for row, done in zip(ordered, last_used):
        gt = gt_files.get(row["pair_id"])
        if gt is None:
            raise ConfigError(
                f"{gt_index}: no ground truth for pair {row['pair_id']}; re-run the workflow "
                "(the ground-truth index is older than the manifest)"
            )
        key = build.input_key(row, gt)
        path = pair_file(folder, row["pair_id"])
        computed = stored_key(path, "__meta__") != key
        if not computed and not is_intact(path):
            _log(
                f"{path}: its content no longer matches the digest becos recorded when writing it (edited or "
                f"replaced by hand?); rebuilding it"
            )
            computed = True
        if computed:
            build.record(row, gt, key).save(path, sources=build.sources(row, gt))
        entries.append(
            {
                "pair_id": row["pair_id"],
                "path": str(path),
                "input_key": key,
                "computed": computed,
                "split": row["split"],
                "digest": shapes.file_digest(path),
            }
        )
        shapes.release(done)
        _progress("pairs", setting, chunk, entries, len(rows), started)
    return _write_index(Path(out_index), setting, chunk, entries, started)


class _RecordBuilder:
    """The pair records of a pairs job: each pair's input key and, when it changed, its record."""

    def __init__(self, stage: PairsOptions, shapes: ShapeStore, gt_index: Path, triangle_ids: Path | None):
        self.stage, self.shapes, self.gt_index, self.triangle_ids = stage, shapes, gt_index, triangle_ids
        self.options = stage.pair_options()
        self.labels = _labeller(shapes) if stage.propagate_annotations else None

    def tokens(self, row: dict) -> tuple[str, str]:
        return remesh_token(row, "x", self.stage.remesh), remesh_token(row, "y", self.stage.remesh)

    def input_key(self, row: dict, gt: dict) -> str:
        """The digest of what the pair's record is made from: its manifest row (but its chunk), the stage's
        options, its ground-truth file and the shape files it reads."""
        tx, ty = self.tokens(row)
        return digest(
            {
                "version": RECORD_VERSION,
                "row": {k: row[k] for k in sorted(row) if k != "chunk"},
                "options": self.stage.key_options(),
                "ground_truth": gt["digest"],
                "sources": [
                    self.shapes.source_digest(row["x_dataset"], row["x_name"], tx),
                    self.shapes.source_digest(row["y_dataset"], row["y_name"], ty),
                ],
            }
        )

    def sources(self, row: dict, gt: dict):
        """The files the pair's record is made from (:class:`becos.build.record_sources.RecordSources`): its
        ground-truth file and each remeshed side's remesh file; the record file leaves out what they give."""
        from becos.build.record_sources import RecordSources

        (tx, ty), shapes = self.tokens(row), self.shapes
        sides = {
            side: (row[f"{side}_dataset"], row[f"{side}_name"], token)
            for side, token in (("x", tx), ("y", ty))
            if token != "original"
        }
        return RecordSources(
            **{side: shapes.remesh_path(*shape) for side, shape in sides.items()},
            ground_truth=Path(gt["path"]),
            digests={  # hashed already, for the input key
                "ground_truth": gt["digest"],
                **{side: shapes.source_digest(*shape) for side, shape in sides.items()},
            },
        )

    def record(self, row: dict, gt: dict, key: str):
        """The pair's :class:`becos.build.record.PairRecord` (ground truth from the file ``gt`` indexes)."""
        from becos.build.pairs import build_pair

        shapes, (tx, ty) = self.shapes, self.tokens(row)
        x = shapes.instance(row["x_dataset"], row["x_name"], tx)
        y = shapes.instance(row["y_dataset"], row["y_name"], ty)
        _require_indexed(Path(gt["path"]), gt["digest"], self.gt_index, shapes)
        gt_xy, gt_yx = load_ground_truth(Path(gt["path"]))
        pair_scanners = (None, None)
        if self.stage.setting != "full_full":
            pair_scanners = tuple(shapes.scanner(s.dataset, s.name, t, s.mesh) for s, t in ((x, tx), (y, ty)))
        record = build_pair(
            x,
            y,
            gt_xy,
            gt_yx,
            pair_id=row["pair_id"],
            seed=int(row["seed"]),
            split=row["split"],
            options=self.options,
            scanners=pair_scanners,
            rotations=pair_published_rotations(row),
            published_views=pair_published_views(self.stage, row, self.options, self.triangle_ids),
        )
        if self.labels is not None:
            for side, s, t in (("x", x, tx), ("y", y, ty)):
                full = self.labels(s.dataset, s.name, t)
                if full is not None:
                    record.arrays[f"{side}_annotation"] = full[record[f"{side}_partial_to_full"]]
        record.meta.update(
            input_key=key, category=row["category"], copy=int(row["copy"]), x_token=tx, y_token=ty
        )  # no chunk: regrouping keeps the record
        return record


def _require_indexed(path: Path, recorded: str, index: Path, shapes: ShapeStore) -> None:
    """Raise unless the ground-truth file at ``path`` is the one its chunk ``index`` records (digest
    ``recorded``): an edited or replaced file must not reach a pair record."""
    from becos.errors import InputFileError

    if not path.is_file():
        raise InputFileError(
            path,
            f"is missing, though {index} lists it",
            "rebuild the ground truth: snakemake --forcerun ground_truth (the other pairs' files are kept)",
        )
    found = shapes.file_digest(path)
    if found != recorded:
        raise InputFileError(
            path,
            f"is not the file the ground-truth job wrote: its digest is {found}, {index} records {recorded} "
            "(edited or replaced after the job)",
            "rebuild it: snakemake --forcerun ground_truth (it recomputes exactly the files that changed), then "
            "run snakemake again",
        )


def pair_published_views(config, row: dict, options, triangle_ids: Path | None = None):
    """``original_settings`` P2P with the reference remesh: the views of the pair's published cameras
    (:func:`becos.build.reference_views.published_scan`), else None (the pairs stage draws cameras).

    ``triangle_ids``: the folder of the shipped view files (:func:`published_views_folder`, as the rule
    declares it); None: where the config's annotation folder has them (a view without its file is cast).
    """
    if not uses_published_views(config, options.setting) or "x_cam_pos_0" not in row:
        return None
    from becos.build.reference_views import published_scan

    n = sum(1 for k in row if k.startswith("x_cam_pos_"))
    cameras = np.array([[row[f"{side}_cam_pos_{i}"] for i in range(n)] for side in "xy"], dtype=np.float64).reshape(
        2, -1, 3
    )
    # published_scan names each file under the annotation folder: <root>/precomputed_triangle_ids/<setting>/
    root = PairsOptions.of(config).annotations if triangle_ids is None else Path(triangle_ids).parents[1]
    return lambda x, y, gt_xy, gt_yx: published_scan(
        x,
        y,
        gt_xy,
        gt_yx,
        root,
        row["x_name"],
        row["y_name"],
        cameras,
        options.n_cam_pos,
        options.min_overlap,
        options.max_overlap,
    )


def pair_published_rotations(row: dict):
    """The published lists' random rotations of a pair (``original_settings``), else None."""
    if "x_random_rot_0" not in row or math.isnan(float(row["x_random_rot_0"])):
        return None
    return tuple(
        np.array([row[f"{side}_random_rot_{i}"] for i in range(9)], dtype=np.float64).reshape(3, 3)
        for side in ("x", "y")
    )


def _labeller(shapes: ShapeStore):
    """``labels(dataset, name, token) -> (V,) int8 or None``: propagated left/right labels of a full shape."""
    from becos.build.propagation import labels_for_instance

    cache: dict = {}

    def labels(dataset: str, name: str, token: str):
        key = (dataset, name, token)
        if key not in cache:
            cache[key] = labels_for_instance(
                shapes.network, shapes.entry(dataset, name), remesh=shapes.remeshed(dataset, name, token)
            )
        return cache[key]

    return labels


def store_metadata(config: dict, setting: str) -> dict:
    """Metadata for a setting's store: config and its digest, datasets with licence and citation."""
    from becos.sources.datasets import DatasetSpec

    datasets = {}
    for name in SourceOptions.of(config).datasets:
        spec = DatasetSpec.load(name)
        datasets[name] = {"title": spec.title, **{k: spec.source.get(k) for k in ("url", "licence", "citation")}}
    return {
        "setting": setting,
        "config": config,
        "config_hash": digest(config),
        "datasets": datasets,
        "generator": "becos workflow",
        "follows_published_lists": published_parts(config, setting),
    }


def published_parts(config, setting: str) -> dict[str, bool | None]:
    """Per part of a setting's benchmark, whether it follows the published pair lists (None: the
    setting has no such part). P2P views follow them with the reference remesh (their triangle ids
    index its faces; :mod:`becos.build.reference_views`); P2F has no published list. ``config``: a resolved
    config or the pairs stage's options."""
    options = PairsOptions.of(config)
    original, remesh = options.original_settings, options.remesh
    reference = original and remesh and options.remesher == "reference"
    return {
        "pairs": original,
        "rotations": original,
        "face_targets": original and remesh,
        "remesh": reference,
        "views": None if setting == "full_full" else (reference and setting == "partial_partial"),
    }


def export_pairings_stage(
    options: ExportOptions | dict, setting: str, out: Path, store: Path, *, manifest: Path, catalog: Path
) -> None:
    """The manifest in the published pickle schema (share a benchmark as pair lists + code), with the
    random rotations, cameras and face counts the store's records actually used (docs/released-layout.md,
    section "Published pair lists"). Reads the setting's ``manifest``, the ``catalog`` and ``store``."""
    from becos.build.published import store_pair_facts, write_published_pickle
    from becos.build.sampling import read_manifest
    from becos.products.store import open_benchmark
    from becos.sources.catalog import read_catalog

    facts = store_pair_facts(open_benchmark(store))
    write_published_pickle(
        read_manifest(manifest),
        out,
        read_catalog(catalog),
        random_rotations=facts["random_rotations"],
        cameras=facts["cameras"],
        pair_face_targets=facts["face_targets"],
        data_root=ExportOptions.of(options).data_dir,
    )
