"""DeformingThings4D (DT4D) preparation: ``.anime`` animations -> the OBJ frames the BeCoS annotations index.

``becos prepare-dt4d --data-dir DATA --info INFO_JSON --kind animals|humanoids [--classes C ...]`` reads
``DATA/DeformingThings4D/<kind>/<class>_<action>/<class>_<action>.anime`` and writes
``DATA/dt4d_<kind>/<class>/<action><frame:03d>.obj`` for every frame ``INFO_JSON`` lists, exactly as the
reference's ``preprocess_dt4d.py`` (trimesh's split, the largest component, trimesh's OBJ export), since
the annotation files index its vertex and face rows. Units and frame are the file's (metres, z up). A
stamp per class (:data:`STAMP_NAME`) keeps an OBJ unless its ``.anime`` changed. The ``.anime`` format,
the stamp and the rules: docs/design/data.md.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from becos.atomic import remove_stale_temporaries, write_text
from becos.errors import BecosError, ConfigError, InputFileError

KINDS = ("animals", "humanoids")
SOURCE_FOLDER = "DeformingThings4D"
"""Folder below the data root holding the DeformingThings4D download (``<kind>/<class>_<action>/``)."""
STAMP_NAME = ".becos-dt4d.json"
STAMP_FORMAT = 1
HEADER_BYTES = 12
REQUEST = (
    "request DeformingThings4D through the form linked at https://github.com/rabbityl/DeformingThings4D "
    "(non-commercial research licence) and unpack it so that DATA/DeformingThings4D/<animals|humanoids>/"
    "<class>_<action>/<class>_<action>.anime exist"
)
_REDOWNLOAD = "re-download or re-extract this animation of DeformingThings4D (the file is damaged)"


def output_folder(data_dir: str | Path, kind: str) -> Path:
    """``DATA/dt4d_<kind>``: the OBJ folder (the dataset YAML's ``folder``)."""
    return Path(data_dir) / f"dt4d_{kind}"


def source_folder(data_dir: str | Path, kind: str) -> Path:
    """``DATA/DeformingThings4D/<kind>``: the folder of the ``.anime`` animations."""
    return Path(data_dir) / SOURCE_FOLDER / kind


def anime_path(data_dir: str | Path, kind: str, cls: str, action: str) -> Path:
    name = f"{cls}_{action}"
    return source_folder(data_dir, kind) / name / f"{name}.anime"


def stamp_path(data_dir: str | Path, kind: str, cls: str) -> Path:
    return output_folder(data_dir, kind) / cls / STAMP_NAME


# --- the info file --------------------------------------------------------------------------------
def read_info(path: str | Path) -> dict[str, dict[str, list[int]]]:
    """``{class: {action: [frame ids]}}`` of an info JSON (frame ids as ints, in the file's order)."""
    path = Path(path)
    fix = "use the BeCoS annotation folder's data/info_dt4d_<kind>.json ({class: {action: [frame ids]}})"
    if not path.is_file():
        raise InputFileError(path, "the DT4D class/action/frame list is missing", fix)
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
        info = {
            str(c): {str(a): [int(k) for k in frames] for a, frames in actions.items()} for c, actions in raw.items()
        }
    except (ValueError, AttributeError, TypeError) as exc:
        raise InputFileError(path, f"is not a {{class: {{action: [frame ids]}}}} JSON ({exc})", fix) from exc
    return info


# --- .anime files ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Animation:
    """A parsed ``.anime`` file.

    Attributes:
        path: the file.
        frame0: (nv, 3) float32 (little-endian) vertices of frame 0.
        faces: (nt, 3) int32 faces, 0-based, checked to lie in [0, nv).
        offsets: (nf - 1, nv, 3) float32 offsets of frames 1 .. nf-1 from frame 0.
        (Read-only views of the file's bytes.)
        sha256: hex digest of the file's bytes (the bytes parsed).
    """

    path: Path
    frame0: np.ndarray
    faces: np.ndarray
    offsets: np.ndarray
    sha256: str

    @property
    def n_frames(self) -> int:
        return len(self.offsets) + 1

    def frame(self, k: int) -> np.ndarray:
        """(nv, 3) float32 vertices of frame ``k`` (``frame0 + offsets[k - 1]`` in float32)."""
        if not 0 <= k < self.n_frames:
            raise InputFileError(
                self.path,
                f"frame {k} is asked for but the animation has {self.n_frames} frames (ids 0..{self.n_frames - 1})",
                "list only frames the animation has (use the annotation folder's unmodified info "
                "file with the original DeformingThings4D download)",
            )
        if k == 0:
            return self.frame0
        return self.frame0 + self.offsets[k - 1]


def read_anime(path: str | Path) -> Animation:
    """Parse and check a ``.anime`` file (the layout: docs/design/data.md).

    Raises:
        InputFileError: missing file, truncated file, counts inconsistent with the file size, or face
            indices outside ``[0, nv)``. NaN / infinite positions are found per frame by :func:`make_frame`.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(path, "the animation file is missing", REQUEST)
    data = path.read_bytes()
    size = len(data)
    if size < HEADER_BYTES:
        raise InputFileError(
            path,
            f"is truncated: {size} bytes, shorter than the {HEADER_BYTES}-byte header (int32 nf, nv, nt)",
            _REDOWNLOAD,
        )
    nf, nv, nt = (int(x) for x in np.frombuffer(data, dtype="<i4", count=3))
    if nf < 1 or nv < 1 or nt < 1:
        raise InputFileError(
            path,
            f"the header's counts nf={nf}, nv={nv}, nt={nt} are not all positive (not a .anime file, or a damaged one)",
            _REDOWNLOAD,
        )
    frame0_end = HEADER_BYTES + 12 * nv
    faces_end = frame0_end + 12 * nt
    if size < faces_end:
        raise InputFileError(
            path,
            f"is truncated: {size} bytes, but its header (nv={nv} vertices, nt={nt} faces) "
            f"needs {faces_end} bytes for frame 0 and the faces alone",
            _REDOWNLOAD,
        )
    expected = faces_end + 12 * (nf - 1) * nv
    if size != expected:
        held = (size - faces_end) / (12 * nv)
        raise InputFileError(
            path,
            f"its counts are inconsistent with the file size: the header announces nf={nf} "
            f"frames of nv={nv} vertices and nt={nt} faces ({expected} bytes), but the file has "
            f"{size} bytes (offsets for {held:.6g} frames instead of {nf - 1})"
            + (" -- it is truncated" if size < expected else ""),
            _REDOWNLOAD,
        )
    frame0 = np.frombuffer(data, dtype="<f4", count=3 * nv, offset=HEADER_BYTES).reshape(nv, 3)
    faces = np.frombuffer(data, dtype="<i4", count=3 * nt, offset=frame0_end).reshape(nt, 3)
    offsets = np.frombuffer(data, dtype="<f4", count=3 * nv * (nf - 1), offset=faces_end).reshape(nf - 1, nv, 3)
    low, high = int(faces.min()), int(faces.max())
    if low < 0 or high >= nv:
        bad = int(((faces < 0) | (faces >= nv)).any(axis=1).sum())
        raise InputFileError(
            path, f"{bad} faces use vertex indices outside [0, {nv}) (they span [{low}, {high}])", _REDOWNLOAD
        )
    return Animation(path, frame0, faces, offsets, hashlib.sha256(data).hexdigest())  # read-only views, no copy


def make_frame(animation: Animation, k: int):
    """The reference's mesh of frame ``k``: trimesh's split of the whole frame, the component with the
    most vertices (a ``trimesh.Trimesh``, vertex and face order as trimesh's split makes them).

    Raises:
        InputFileError: ``k`` is not a frame of the animation, or the frame has NaN / infinite positions.
    """
    import trimesh

    vertices = animation.frame(k)
    finite = np.isfinite(vertices).all(axis=1)
    if not finite.all():
        raise InputFileError(
            animation.path,
            f"frame {k} has {int((~finite).sum())} vertices with NaN or infinite "
            f"coordinates (e.g. vertex {int(np.flatnonzero(~finite)[0])})",
            _REDOWNLOAD,
        )
    mesh = trimesh.Trimesh(vertices, animation.faces, process=False, maintain_order=True)
    parts = mesh.split(only_watertight=False)
    return max(parts, key=lambda part: len(part.vertices))


def obj_text(mesh) -> str:
    """trimesh's OBJ export of ``mesh`` (its header comment, ``v`` lines with 8 decimals, then ``f`` lines;
    no normals, colours or texture): the bytes of the reference's ``mesh.export(path)``."""
    from trimesh.exchange.obj import export_obj

    return export_obj(mesh, include_normals=False, include_color=False, include_texture=False)


# --- preparing a class ----------------------------------------------------------------------------
def _sha256_file(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 22), b""):
            digest.update(block)
    return digest.hexdigest()


def _read_stamp(path: Path, kind: str, cls: str) -> dict:
    """The class's stamp, or an empty one (missing, unreadable or of another format: everything is redone)."""
    try:
        stamp = json.loads(path.read_text(encoding="utf-8"))
        if (
            stamp.get("format") == STAMP_FORMAT
            and stamp.get("kind") == kind
            and stamp.get("class") == cls
            and isinstance(stamp.get("animations"), dict)
        ):
            return stamp
    except (OSError, ValueError, AttributeError):
        pass
    return {}


def prepare_class(
    data_dir: str | Path,
    kind: str,
    cls: str,
    actions: dict[str, list[int]],
    info_path: Path | None = None,
    anime: set[Path] | None = None,
) -> dict[str, int]:
    """Write the OBJ frames of one class (``actions``: ``{action: [frame ids]}``) and its stamp.

    ``anime``: the ``.anime`` files the job was given (its rule's inputs); an action whose file
    (:func:`anime_path`) is not among them is missing. None: every file under ``data_dir``.

    Returns counts ``{"written", "kept", "animations_read"}``.

    Raises:
        InputFileError: a listed ``.anime`` is missing or damaged, or a listed frame is not in it.
    """
    import trimesh

    data_dir = Path(data_dir)
    out = output_folder(data_dir, kind) / cls
    spath = out / STAMP_NAME
    old = _read_stamp(spath, kind, cls).get("animations", {})
    # this class's job is the only writer of its folder: drop what a killed run's atomic writes left
    remove_stale_temporaries(out, [STAMP_NAME] + [f"{a}{k:03d}.obj" for a, frames in actions.items() for k in frames])
    stamp = {"format": STAMP_FORMAT, "kind": kind, "class": cls, "trimesh": trimesh.__version__, "animations": {}}
    counts = {"written": 0, "kept": 0, "animations_read": 0}
    for action, frames in actions.items():
        source = anime_path(data_dir, kind, cls, action)
        listed = f" (animation {cls}/{action}, listed in {info_path})" if info_path else f" ({cls}/{action})"
        if not source.is_file() or (anime is not None and source not in anime):
            raise InputFileError(source, f"the animation file is missing{listed}", REQUEST)
        st = source.stat()
        record = old.get(action) or {}
        targets = {k: out / f"{action}{k:03d}.obj" for k in frames}
        same = bool(record) and record.get("size") == st.st_size and record.get("mtime_ns") == st.st_mtime_ns
        if record and not same and record.get("size") == st.st_size:
            same = _sha256_file(source) == record.get("sha256")  # e.g. re-extracted, same bytes
        todo = [k for k, t in targets.items() if not (same and t.is_file())]
        sha = record.get("sha256") if same else None
        if todo:
            animation = _listed_animation(source, todo, listed, f"{cls}/{action}", info_path)
            counts["animations_read"] += 1
            sha = animation.sha256
            for k in todo:
                mesh = make_frame(animation, k)
                write_text(targets[k], obj_text(mesh))
            counts["written"] += len(todo)
        counts["kept"] += len(targets) - len(todo)
        stamp["animations"][action] = {
            "anime": str(source.relative_to(data_dir)),
            "size": st.st_size,
            "mtime_ns": st.st_mtime_ns,
            "sha256": sha,
            "frames": sorted(targets),
        }
        # the stamp so far plus the old records not yet visited: an interrupted run keeps what it did
        partial = {
            **stamp,
            "animations": {
                **{a: r for a, r in old.items() if a in actions and a not in stamp["animations"]},
                **stamp["animations"],
            },
        }
        write_text(spath, json.dumps(partial, indent=1, sort_keys=True) + "\n")
    if not actions:
        write_text(spath, json.dumps(stamp, indent=1, sort_keys=True) + "\n")
    return counts


def _listed_animation(source: Path, frames: list[int], listed: str, name: str, info_path: Path | None):
    """The animation ``source`` (class/action ``name``), checked to hold every frame id in ``frames``;
    ``listed`` says where the info file lists it (appended to a read error)."""
    try:
        animation = read_anime(source)
    except InputFileError as exc:
        raise InputFileError(exc.path, exc.problem + listed, exc.fix) from None
    for k in frames:
        if not 0 <= k < animation.n_frames:
            raise InputFileError(
                source,
                f"frame {k} of {name} is listed in {info_path or 'the info file'} but the animation has "
                f"{animation.n_frames} frames (ids 0..{animation.n_frames - 1})",
                "use the annotation folder's unmodified info file with the original DeformingThings4D download",
            )
    return animation


def prepare_dt4d(
    data_dir: str | Path,
    info_path: str | Path,
    kind: str,
    classes: list[str] | None = None,
    log=None,
    anime: list[str | Path] | None = None,
) -> dict[str, int]:
    """Prepare every class of ``info_path`` (or only ``classes``); counts summed over the classes.
    ``anime``: the ``.anime`` files to read (the workflow rule's inputs); None: every listed one."""
    if kind not in KINDS:
        raise ConfigError(f"--kind must be one of {KINDS}, got {kind!r}")
    info_path = Path(info_path)
    info = read_info(info_path)
    chosen = list(info) if not classes else list(dict.fromkeys(classes))
    unknown = [c for c in chosen if c not in info]
    if unknown:
        raise InputFileError(
            info_path,
            f"lists no class {unknown} (it has {len(info)} classes)",
            "name classes of the info file, or use the info file of the right kind",
        )
    if not source_folder(data_dir, kind).is_dir():
        raise InputFileError(source_folder(data_dir, kind), "the DeformingThings4D folder is missing", REQUEST)
    total = {"classes": 0, "written": 0, "kept": 0, "animations_read": 0}
    for cls in chosen:
        given = None if anime is None else {Path(p) for p in anime}
        counts = prepare_class(data_dir, kind, cls, info[cls], info_path, given)
        total["classes"] += 1
        for key, value in counts.items():
            total[key] += value
        if log is not None:
            log(
                f"prepare-dt4d: {kind}/{cls}: {counts['written']} frames written, {counts['kept']} kept "
                f"({counts['animations_read']} of {len(info[cls])} animations read)"
            )
    return total


# --- the workflow's plan --------------------------------------------------------------------------
@dataclass(frozen=True)
class PreparationJob:
    """One ``prepare_dt4d`` workflow job: a class of a DT4D dataset.

    Attributes:
        dataset: dataset name (``dt4d_animal``); kind: ``animals`` / ``humanoids``; cls: the class.
        info: the info JSON; anime: the class's ``.anime`` files that exist (a missing one is left to
            the job, whose error names it and says where to get it); stamp: the job's output.
        listing: the class's ``{action: [frame ids]}`` as canonical JSON (a rule parameter, so a change
            of this class's entry reruns this job only).
    """

    dataset: str
    kind: str
    cls: str
    info: Path
    anime: tuple[Path, ...]
    stamp: Path
    listing: str


def dataset_kind(spec) -> str | None:
    """``animals`` / ``humanoids`` of a ``dt4d``-layout dataset spec (its folder ``dt4d_<kind>``), else None."""
    if spec.layout != "dt4d":
        return None
    kind = spec.folder[len("dt4d_") :] if spec.folder.startswith("dt4d_") else None
    if kind not in KINDS:
        raise InputFileError(
            spec.path,
            f"a dt4d-layout dataset needs folder dt4d_animals or dt4d_humanoids, got '{spec.folder}'",
            "set folder to the output folder of becos prepare-dt4d",
        )
    return kind


def preparation_plan(data_dir: str | Path, datasets: list[str], annotations: str | Path | None) -> list[PreparationJob]:
    """The preparation jobs of a workflow config (keys ``data_dir``, ``datasets``, ``annotations``): one per
    class of each enabled ``dt4d`` dataset whose ``DATA/DeformingThings4D/<kind>`` folder and info file
    exist when the workflow is planned (without them the dataset check explains what to get). Class order
    as in the info file."""
    from becos.sources.datasets import DatasetSpec

    data_dir = Path(data_dir)
    jobs = []
    for name in datasets:
        try:
            spec = DatasetSpec.load(name)
            kind = dataset_kind(spec)
        except BecosError:
            continue  # the dataset check reports it
        if kind is None or not source_folder(data_dir, kind).is_dir():
            continue
        info_path = next((p for p in spec.info_file_candidates(annotations, data_dir) if p.is_file()), None)
        try:
            info = read_info(info_path) if info_path is not None else {}
        except BecosError:
            continue  # the dataset check names the file and the problem
        for cls, actions in info.items():
            jobs.append(
                PreparationJob(
                    dataset=name,
                    kind=kind,
                    cls=cls,
                    info=info_path,
                    anime=tuple(p for p in (anime_path(data_dir, kind, cls, a) for a in actions) if p.is_file()),
                    stamp=stamp_path(data_dir, kind, cls),
                    listing=json.dumps(actions, sort_keys=True, separators=(",", ":")),
                )
            )
    return jobs


__all__ = [
    "Animation",
    "PreparationJob",
    "make_frame",
    "obj_text",
    "prepare_class",
    "prepare_dt4d",
    "preparation_plan",
    "read_anime",
    "read_info",
]
