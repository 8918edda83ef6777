"""The dataset part of the check, and :func:`check_datasets`, the whole check (:mod:`becos.sources.check`).

Per enabled dataset (``_check_one_dataset``): its folder below the data root (if missing: where to
get it, its licence, the folder to create, the config key to change), entries named like a mesh file
that are no regular file, stray files no class rule matches, the shape count (total and per class;
missing files named from the published pair lists), every mesh file (cheap check, or the full
inspection), and the shapes that share their class template's triangulation against the template.
"""

from __future__ import annotations

import contextlib
from functools import partial
from pathlib import Path

from becos.core.formats import not_a_mesh_file, not_a_regular_file
from becos.core.formats.problems import TRUNCATED_FIX
from becos.errors import BecosError, ConfigError, InputFileError
from becos.process_split import ProcessSplit
from becos.sources.check.annotations import check_annotations
from becos.sources.check.meshes import check_mesh_file, inspect_mesh_file
from becos.sources.check.templates import CLASS_FIX, check_classes

MAX_LISTED_MESHES = 20
"""At most this many bad mesh files are named per dataset in the error message (the report has all)."""


class DatasetCheckError(ConfigError):
    """The dataset / annotation check failed. ``report`` holds the full report (JSON-able dict),
    ``problems`` the list of problem texts (also joined into the message)."""

    def __init__(self, message: str, report: dict, problems: list[str]):
        super().__init__(message)
        self.report = report
        self.problems = problems


_PUBLISHED_CACHE: dict[str, dict[str, set[str]]] = {}


def _published_names(root: Path | None) -> dict[str, set[str]]:
    """Dataset -> shape names used by the published pair lists in ``root/config`` (empty if absent)."""
    if root is None:
        return {}
    key = str(root)
    if key not in _PUBLISHED_CACHE:
        out: dict[str, set[str]] = {}
        for setting in ("full_full", "partial_partial"):
            path = Path(root) / "config" / f"pairings_original_{setting}.pkl"
            if not path.is_file():
                continue
            try:
                from becos.build.published import load_published

                for split in load_published(path):
                    for pair in split:
                        for shape in pair:
                            out.setdefault(str(shape["org_dataset"]), set()).add(str(shape["name"]))
            except Exception:  # an unreadable list only loses the names in a message
                continue
        _PUBLISHED_CACHE[key] = out
    return _PUBLISHED_CACHE[key]


def _missing_dataset_text(spec, folder: Path, data_dir: Path) -> str:
    s = spec.source
    parts = [
        f"dataset '{spec.name}' ({spec.title}) not found: folder {folder} does not exist.",
        f"Get it: {s.get('instructions', '').strip().rstrip('.')}.",
    ]
    if s.get("url"):
        parts.append(f"Site: {s['url']} .")
    if s.get("licence"):
        parts.append(f"Licence: {s['licence'].strip().rstrip('.')}.")
    if spec.layout == "dt4d":
        from becos.sources.dt4d import dataset_kind, source_folder

        kind = dataset_kind(spec)
        source = source_folder(data_dir, kind)
        parts.append(
            f"Put it there: unpack the download into {data_dir / 'DeformingThings4D'} (data_dir + "
            f"'DeformingThings4D'); the workflow then prepares {folder} from {source} "
            f"(`becos prepare-dt4d`)."
        )
        if source.is_dir():
            parts.append(
                f"{source} is present but not prepared yet: run the workflow (it plans one preparation "
                f"job per class once the annotation folder's data/{spec.info_file} exists), or "
                f"`becos prepare-dt4d --data-dir {data_dir} --info <annotations>/data/{spec.info_file} "
                f"--kind {kind}`."
            )
    else:
        parts.append(
            f"Put it there: create {folder} (data_dir {data_dir} + '{spec.folder}') and place the "
            f"{spec.file_type.upper()} files in it."
        )
    if spec.archive is not None:
        parts.append(
            f"Or let the workflow download it: add '{spec.name}' to the config key `download` (you accept "
            f"its licence), or run `becos download-dataset {spec.name} --data-dir {data_dir}`."
        )
    parts.append(
        f"Or change the config: set `data_dir` to the folder that holds '{spec.folder}', or remove "
        f"'{spec.name}' from `datasets`."
    )
    return " ".join(parts)


def _classified(spec, name: str) -> bool:
    """Whether ``name`` matches a class and a category rule of the dataset ``spec``."""
    try:
        spec.class_of(name)
        spec.category_of(name)
    except BecosError:
        return False
    return True


def _check_one_dataset(
    name: str,
    data_dir: Path,
    annotations,
    read_meshes: bool,
    full_parse: bool,
    config_dir,
    compare_geometry: bool,
    split: ProcessSplit,
) -> tuple[dict, list[str], list]:
    """Report entry, problem texts and the listed ShapeEntry rows (empty unless the listing succeeded).
    ``split``: the check's second process, if any (:class:`becos.process_split.ProcessSplit`)."""
    from becos.sources.datasets import DatasetSpec

    entry: dict = {
        "ok": False,
        "path": None,
        "folder": None,
        "found": 0,
        "expected": None,
        "excluded_found": 0,
        "meshes_checked": 0,
        "bad_meshes": [],
        "repairs": [],
        "problems": [],
    }
    problems: list[str] = []

    def stop(problem: str) -> tuple[dict, list[str], list]:
        problems.append(problem)
        entry["problems"] = problems
        return entry, problems, []

    try:
        spec = DatasetSpec.load(name, config_dir)
    except BecosError as exc:
        return stop(f"{exc} (config key `datasets`)")
    folder = data_dir / spec.folder
    entry.update(path=str(folder), folder=spec.folder)
    if not folder.is_dir():
        entry["expected"] = spec.expected_count  # None for a generated collection (counted from its manifest)
        return stop(_missing_dataset_text(spec, folder, data_dir))
    try:
        entry["expected"], expected_per_class = spec.expected_counts(data_dir)
    except BecosError as exc:
        return stop(f"dataset '{name}': {exc}")
    if expected_per_class:
        entry["expected_per_class"] = expected_per_class
    try:
        names = spec.list_names(data_dir, annotations)
    except BecosError as exc:
        return stop(f"dataset '{name}': {exc}")
    not_files = _not_mesh_files(spec, folder, entry, problems)
    stray = _stray_files(spec, folder, names, entry, problems)
    names = [n for n in names if n not in stray]
    counts_ok = _check_counts(spec, folder, names, not_files, annotations, entry, problems)
    if read_meshes:
        _check_meshes(spec, folder, names, full_parse, entry, problems, split)
    shapes: list = []
    if counts_ok and not stray:
        try:
            shapes = spec.list_shapes(data_dir, annotations)
        except BecosError as exc:
            problems.append(f"dataset '{name}': {exc}")
    if read_meshes and compare_geometry and shapes and annotations is not None:
        _check_class_templates(spec, shapes, annotations, entry, problems, split)
    entry["problems"] = problems
    entry["ok"] = not problems
    return entry, problems, shapes


def _not_mesh_files(spec, folder: Path, entry: dict, problems: list[str]) -> dict[str, Path]:
    """``{shape name: path}`` of the entries in ``folder`` named like a mesh file that are none (a folder,
    a named pipe, a dangling link...); each is a problem, and ``entry["not_mesh_files"]`` says what it is."""
    not_files = {}
    for p in sorted(folder.glob(spec.mesh_glob)):
        odd = not_a_mesh_file(p)
        if odd is not None:
            problems.append(f"{p}: {odd[0]}. Fix: {odd[1]}")
            not_files[spec.name_of(p)] = p
    if not_files:
        entry["not_mesh_files"] = {str(p): not_a_regular_file(p) for p in not_files.values()}
    return not_files


def _stray_files(spec, folder: Path, names: list[str], entry: dict, problems: list[str]) -> list[str]:
    """The listed ``names`` no class rule of the dataset matches (stray files: one problem, and
    ``entry["stray_files"]``)."""
    stray = [n for n in names if not _classified(spec, n)]
    if stray:
        shown = ", ".join(f"{n}.{spec.file_type}" for n in stray[:MAX_LISTED_MESHES])
        problems.append(
            f"{folder}: {len(stray)} file(s) there are not shapes of dataset '{spec.name}': {shown} (their "
            f"names match no class rule of the dataset registry {spec.path}). Fix: move them out of {folder} "
            f"(stray files); only if they are shapes of '{spec.name}', add class and category rules for them "
            f"to {spec.path}"
        )
        entry["stray_files"] = [f"{n}.{spec.file_type}" for n in stray]
    return stray


def _check_counts(
    spec, folder: Path, names: list[str], not_files: dict[str, Path], annotations, entry: dict, problems: list[str]
) -> bool:
    """Whether the dataset's shape count (total, and per class where the registry has one) is the expected
    one; entries that are no mesh file count as present (named already, not called missing). A short
    count names the missing files the published pair lists know (``entry["missing_published"]``)."""
    from becos.sources.catalog import natural_key

    name = spec.name
    expected_count, expected_per_class = entry["expected"], entry.get("expected_per_class", {})
    used = [n for n in names if n not in spec.excluded]
    entry.update(found=len(used), excluded_found=len(names) - len(used))
    counts_ok = not not_files  # named above; counted below as present, so that they are not called missing
    there = [*used, *(n for n in not_files if n not in spec.excluded and _classified(spec, n))]
    if len(there) != expected_count:
        counts_ok = False
        published = _published_names(getattr(annotations, "root", None)).get(name, set())
        # the published lists name every shape of the reference's datasets; a registry that expects
        # another count (a subset, a newer release) gets no names
        present = set(names) | set(not_files)
        absent = sorted(published - present, key=natural_key) if len(published) == expected_count else []
        entry["missing_published"] = absent
        named = ""
        if absent:
            shown = ", ".join(f"{n}.{spec.file_type}" for n in absent[:MAX_LISTED_MESHES])
            more = f" and {len(absent) - MAX_LISTED_MESHES} more" if len(absent) > MAX_LISTED_MESHES else ""
            named = f"; missing files named by the published BeCoS pair lists: {shown}{more}"
        problems.append(
            f"dataset '{name}': found {len(there)} shapes ({spec.file_glob}) in {folder}, expected "
            f"{expected_count}{named}. Fix: complete or re-extract the download "
            f"({spec.download_help()}), or check `data_dir`"
        )
    if expected_per_class:
        per_class: dict[str, int] = {}
        for n in there:
            c = spec.class_of(n)
            per_class[c] = per_class.get(c, 0) + 1
        entry["found_per_class"] = per_class
        diff = {
            c: (per_class.get(c, 0), expected_per_class.get(c, 0))
            for c in sorted(set(per_class) | set(expected_per_class))
            if per_class.get(c, 0) != expected_per_class.get(c, 0)
        }
        if diff:
            counts_ok = False
            problems.append(
                f"dataset '{name}': shapes per class (found, expected) differ in {folder}: {diff}. "
                f"Fix: complete or re-extract the download"
            )
    return counts_ok


def _listed(rows: list[dict], text) -> str:
    """``text(row)`` of the first :data:`MAX_LISTED_MESHES` rows joined by ``; ``, and how many more there
    are (all in the report)."""
    listed = "; ".join(text(b) for b in rows[:MAX_LISTED_MESHES])
    more = f"; and {len(rows) - MAX_LISTED_MESHES} more (all in the report)" if len(rows) > MAX_LISTED_MESHES else ""
    return listed + more


def _check_meshes(
    spec,
    folder: Path,
    names: list[str],
    full_parse: bool,
    entry: dict,
    problems: list[str],
    split: ProcessSplit,
) -> None:
    """Check every listed mesh file (cheap check, or with ``full_parse`` the full inspection, whose repairs
    go to ``entry["repairs"]``); bad files go to ``entry["bad_meshes"]`` and make one problem.
    ``split``: half of the files go to its second process (:class:`becos.process_split.ProcessSplit`)."""
    paths = [folder / f"{n}.{spec.file_type}" for n in names]
    for repair, bad in split.map(partial(_check_mesh_files, full_parse=full_parse), paths):
        if repair is not None:
            entry["repairs"].append(repair)
        if bad is not None:
            entry["bad_meshes"].append(bad)
        entry["meshes_checked"] += 1
    bad = entry["bad_meshes"]
    if bad:
        listed = _listed(
            bad, lambda b: f"{b['path']}: {b['problem']}" + (f" (fix: {b['fix']})" if b["fix"] != TRUNCATED_FIX else "")
        )
        problems.append(
            f"dataset '{spec.name}': {len(bad)} of {len(names)} mesh files are empty, truncated or corrupt: "
            f"{listed}. Fix: re-download or re-extract them ({spec.download_help()})"
        )


def _check_mesh_files(paths: list[Path], full_parse: bool) -> list[tuple[dict | None, dict | None]]:
    """:func:`_check_mesh` of each file."""
    return [_check_mesh(path, full_parse) for path in paths]


def _check_mesh(path: Path, full_parse: bool) -> tuple[dict | None, dict | None]:
    """(repair entry or None, bad-mesh entry or None) of one mesh file (:func:`_check_meshes`)."""
    try:
        if full_parse:
            repair = inspect_mesh_file(path)
            if repair.needs_attention:
                return {"path": str(path), "repair": repair.summary(), **repair.counts()}, None
        else:
            check_mesh_file(path)
    except InputFileError as exc:
        return None, {"path": str(path), "problem": exc.problem, "fix": exc.fix}
    return None, None


def _check_class_templates(
    spec, shapes: list, annotations, entry: dict, problems: list[str], split: ProcessSplit
) -> None:
    """Compare the shapes with their class templates (:func:`becos.sources.check.templates.check_classes`; files
    already named bad are left out): ``entry["class_mismatches"]``, and one problem naming them."""
    mismatched = check_classes(shapes, annotations, {b["path"] for b in entry["bad_meshes"]}, split)
    entry["class_mismatches"] = mismatched
    if mismatched:
        listed = _listed(mismatched, lambda b: f"{b['path']}: {b['problem']}")
        problems.append(
            f"dataset '{spec.name}': {len(mismatched)} mesh files do not fit their class template: "
            f"{listed}. Fix: {CLASS_FIX}"
        )


def check_datasets(
    datasets: list[str],
    data_dir: str | Path,
    annotations_dir: str | Path | None,
    *,
    read_meshes: bool = True,
    full_parse: bool = False,
    template_table: str = "templates_all.csv",
    config_dir: str | Path | None = None,
    compare_geometry: bool = True,
    processes: int = 1,
) -> dict:
    """Check the enabled datasets and the annotation folder; return the report (:mod:`becos.sources.check`).

    Args:
        datasets: enabled dataset names (registry: :func:`becos.sources.datasets.available_datasets`).
        data_dir: the data root holding each dataset's ``folder``.
        annotations_dir: the BeCoS annotation folder; None skips its checks (DT4D and SMAL listings
            then fail, as they read files from it).
        read_meshes: check every listed mesh file (cheap header/size check, see :mod:`becos.sources.check`);
            False checks folders and counts only.
        full_parse: also parse every mesh completely with :func:`becos.core.mesh.read_mesh` and report the
            repairs remeshing will apply (``<dataset>["repairs"]``; slow).
        template_table: the template table in ``<annotations>/config`` (config key ``template_file``).
        config_dir: dataset registry folder (default ``config/datasets`` or ``$BECOS_DATASETS_DIR``).
        compare_geometry: compare each shape with its class template
            (:func:`becos.sources.check.templates.compare_with_class_template`) and check edge files for plausibility
            (:func:`becos.sources.check.edges.edge_plausibility`); False only for stand-in
            meshes without real geometry (config key ``check_geometry``).
        processes: 2 checks the mesh files and class templates in two processes (the same report).

    Raises:
        DatasetCheckError (a ConfigError): one message listing every problem; ``.report`` holds the report.
    """
    # the second process (only the mesh files and class templates use it) starts now: its imports
    # overlap the annotation folder's loading
    with ProcessSplit(processes if read_meshes else 1, warm_up=(__name__,)) as split:
        return _check_datasets(
            datasets,
            data_dir,
            annotations_dir,
            split,
            read_meshes,
            full_parse,
            template_table,
            config_dir,
            compare_geometry,
        )


def _check_datasets(
    datasets: list[str],
    data_dir: str | Path,
    annotations_dir: str | Path | None,
    split: ProcessSplit,
    read_meshes: bool,
    full_parse: bool,
    template_table: str,
    config_dir: str | Path | None,
    compare_geometry: bool,
) -> dict:
    """:func:`check_datasets`, its second process (if any) in ``split``."""
    from becos.sources.annotations import AnnotationSource, user_cache_dir
    from becos.sources.datasets import DatasetSpec

    data_dir = Path(data_dir).expanduser().absolute()
    enabled = list(dict.fromkeys(str(d) for d in datasets))
    report: dict = {}
    problems = _setup_problems(enabled, data_dir)

    source = None
    root = Path(annotations_dir).expanduser().absolute() if annotations_dir is not None else None
    if root is not None and root.is_dir():
        try:
            source = AnnotationSource(root, cache_dir=user_cache_dir(), template_table=template_table)
        except BecosError:
            source = None  # reported by the annotation check below
    specs = {}
    present: dict[str, list] = {}
    for name in enabled:
        entry, ds_problems, shapes = _check_one_dataset(
            name, data_dir, source, read_meshes, full_parse, config_dir, compare_geometry, split
        )
        report[name] = entry
        problems += ds_problems
        with contextlib.suppress(BecosError):  # a registry problem is in the dataset's own entry
            specs[name] = DatasetSpec.load(name, config_dir)
        if shapes:
            present[name] = shapes
    if root is None:
        report["annotations"] = {"ok": None, "path": None, "notes": ["not checked (no annotation folder given)"]}
    else:
        report["annotations"], ann_problems = check_annotations(
            root, template_table, enabled, present, specs, check_edges=read_meshes, compare_geometry=compare_geometry
        )
        problems += ann_problems
    report["ok"] = not problems
    report["data_dir"] = str(data_dir)
    if problems:
        lines = "\n".join(f"  {i + 1}. {p}" for i, p in enumerate(problems))
        raise DatasetCheckError(
            f"the dataset check found {len(problems)} problem(s) (data_dir {data_dir}, "
            f"annotations {root}, datasets {enabled}):\n{lines}",
            report,
            problems,
        )
    return report


def _setup_problems(enabled: list[str], data_dir: Path) -> list[str]:
    """Problems of the check's own settings: no dataset enabled, a reserved dataset name, no data root."""
    problems: list[str] = []
    if not enabled:
        problems.append("no dataset is enabled. Fix: list at least one dataset under `datasets`")
    if "annotations" in enabled or "ok" in enabled or "data_dir" in enabled:
        problems.append(
            "dataset names 'annotations', 'ok' and 'data_dir' are reserved in the check report. "
            "Fix: rename the dataset YAML"
        )
    if not data_dir.is_dir():
        problems.append(
            f"data root {data_dir} does not exist. Fix: set `data_dir` to the folder that holds the "
            f"dataset folders (e.g. tosca-off, MPI-FAUST)"
        )
    return problems
