"""Stage 7, "report": counts, the overlap histogram and ground-truth renders of a benchmark.

Headless (matplotlib's Agg canvas) and written atomically. :func:`render_pair` draws X and Y side by
side, orthographic, in X's common frame (random rotations undone), Y coloured by the colour of its X
counterpart ``corr_10`` (grey :data:`NO_MATCH_GREY` where -1). :func:`write_report` writes
``counts.csv``, ``overlap_histogram.csv``/``.png``, ``summary.json``, ``renders/<pair_id>.png`` and a
static ``index.html``; for a P2P store the overlap histogram is shown beside the published one.
Colours, the view direction and the Snakemake report captions: docs/design/report.md.
"""

from __future__ import annotations

import io
import json
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from becos.atomic import write_bytes, write_text
from becos.build.record import PairRecord
from becos.products.report_page import index_html
from becos.products.store.layout import TABLE_COLUMNS
from becos.settings import SETTING_LABELS, SPLITS

#: RGB of Y vertices without a counterpart on X (``corr_10 == -1``), before shading.
NO_MATCH_GREY = (0.62, 0.62, 0.62)
#: Page background of renders: pure white (the only other achromatic colour in a render).
BACKGROUND = (1.0, 1.0, 1.0)
#: Text colour: a dark blue, so anti-aliased text never blends into a neutral grey.
TEXT_COLOUR = "#1d2c57"
#: Overlap histogram bin edges: 10 % wide over [0, 1] (centres 5 %, ..., 95 %), [k/10, (k+1)/10) with 1.0 in the
#: last bin.
HIST_EDGES = np.linspace(0.0, 1.0, 11)
#: Table columns :func:`write_report` needs.
REQUIRED_COLUMNS = ("pair_id", "split", "category", "x_dataset", "y_dataset", "x_overlap", "y_overlap")
#: Output -> its caption file in ``workflow/report/`` (``report(..., caption=...)`` of rule ``report``).
CAPTIONS = {"report": "index.rst"}

_AMBIENT = 0.3  # Lambert: shade = ambient + (1 - ambient) * |n . l|
_UP = {"x": np.array([1.0, 0.0, 0.0]), "y": np.array([0.0, 1.0, 0.0]), "z": np.array([0.0, 0.0, 1.0])}
_FIXED_VIEWS = {
    "front": np.array([0.0, 0.0, 1.0]),
    "back": np.array([0.0, 0.0, -1.0]),
    "side": np.array([1.0, 0.0, 0.0]),
    "top": np.array([0.0, 1.0, 0.0]),
}


# ----------------------------------------------------------------------------------------------------
# Colours, frames, projection
# ----------------------------------------------------------------------------------------------------


def common_vertices(record: PairRecord, shape: str) -> np.ndarray:
    """(V_s, 3) vertices of shape ``'x'`` or ``'y'`` in the common frame (random rotation undone).

    Y's common frame is X's (Y was aligned onto X before its random rotation). Units as stored
    (dataset scale, or divided by the full shape's sqrt-area when ``area_normalised``).
    """
    rotation = np.asarray(record[f"{shape}_random_rotation"], dtype=np.float64)
    return np.asarray(record[f"{shape}_vertices"], dtype=np.float64) @ rotation.T


def position_colours(vertices: np.ndarray) -> np.ndarray:
    """(V, 3) RGB in [0, 1]: a smooth, saturated colour of each vertex's position.

    Positions are normalised to the bounding box of ``vertices`` ((V, 3), any frame); hue follows the
    longest box side (0 -> 0.8, red to violet, no wrap-around), value the second (0.6 -> 1) and
    saturation the third (0.55 -> 1). Saturation >= 0.55 keeps every colour far from grey, so grey
    in a render always means "no counterpart".
    """
    from matplotlib.colors import hsv_to_rgb

    vertices = np.asarray(vertices, dtype=np.float64)
    if len(vertices) == 0:
        return np.zeros((0, 3))
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    extent = high - low
    u = (vertices - low) / np.where(extent > 0, extent, 1.0)
    order = np.argsort(-extent, kind="stable")
    hsv = np.stack([0.8 * u[:, order[0]], 0.55 + 0.45 * u[:, order[2]], 0.6 + 0.4 * u[:, order[1]]], axis=1)
    return hsv_to_rgb(hsv)


def transfer_colours(x_colours: np.ndarray, corr_10: np.ndarray) -> np.ndarray:
    """(V_y, 3) RGB of Y's vertices: the colour of the X vertex ``corr_10`` points to, grey where -1.

    ``x_colours`` (V_x, 3); ``corr_10`` (V_y,) int, X vertex index or -1.
    """
    corr_10 = np.asarray(corr_10, dtype=np.int64)
    out = np.empty((len(corr_10), 3))
    matched = corr_10 >= 0
    out[matched] = np.asarray(x_colours)[corr_10[matched]]
    out[~matched] = NO_MATCH_GREY
    return out


def view_direction(record: PairRecord, view: str | Sequence[float] = "auto") -> np.ndarray:
    """(3,) unit vector from the shapes towards the viewer, in X's common frame.

    ``view``: ``"auto"`` (see docs/design/report.md), ``"front"`` (+z), ``"back"`` (-z), ``"side"`` (+x),
    ``"top"`` (+y), or any (3,) direction in the common frame.
    """
    if isinstance(view, str):
        if view in _FIXED_VIEWS:
            return _FIXED_VIEWS[view].copy()
        if view != "auto":
            raise ValueError(f"view must be 'auto', one of {sorted(_FIXED_VIEWS)} or a 3-vector, got {view!r}")
        directions = []
        for shape in ("x", "y"):
            camera = np.asarray(record[f"{shape}_camera"], dtype=np.float64)
            if camera.shape == (3, 3) and np.isfinite(camera[:2]).all():
                d = camera[0] - camera[1]  # position - target, in the shape's common frame before alignment
                if shape == "y":
                    d = d @ np.asarray(record["y_align_rotation"], dtype=np.float64)
                if np.linalg.norm(d) > 0:
                    directions.append(d / np.linalg.norm(d))
        up = _up_vector(record)
        if directions:
            d = np.sum(directions, axis=0)
            if np.linalg.norm(d) > 1e-9:
                return d / np.linalg.norm(d)
        xc = common_vertices(record, "x")
        horizontal = [a for a in np.eye(3) if abs(a @ up) < 0.5]
        extent = [np.ptp(xc @ a) if len(xc) else 0.0 for a in horizontal]
        axis = horizontal[int(np.argmin(extent))]
        d = np.cos(np.radians(20.0)) * axis + np.sin(np.radians(20.0)) * up
        return d / np.linalg.norm(d)
    d = np.asarray(view, dtype=np.float64).reshape(3)
    if not np.isfinite(d).all() or np.linalg.norm(d) == 0:
        raise ValueError(f"view direction must be a finite non-zero 3-vector, got {d}")
    return d / np.linalg.norm(d)


def _up_vector(record: PairRecord) -> np.ndarray:
    options = record.meta.get("options") or {}
    return _UP.get(options.get("up_axis", "y"), _UP["y"]).copy()


def camera_basis(direction: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(3, 3) orthonormal columns (right, screen-up, towards-viewer) for an orthographic view.

    ``points @ basis`` gives screen x, screen y and depth (larger = nearer the viewer). When
    ``direction`` is parallel to ``up`` the screen-up falls back to -z (or +x).
    """
    w = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
    for candidate in (np.asarray(up, dtype=np.float64), np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0])):
        right = np.cross(candidate, w)
        if np.linalg.norm(right) > 1e-6:
            break
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(w, right), w], axis=1)


def shaded_face_colours(
    vertices: np.ndarray, faces: np.ndarray, vertex_colours: np.ndarray, light: np.ndarray
) -> np.ndarray:
    """(F, 3) RGB: mean vertex colour of each face times its two-sided Lambert shade.

    ``vertices`` (V, 3) and ``light`` (3,) unit, towards the light, in the same frame; degenerate faces
    get the ambient shade only.
    """
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(n, axis=1)
    cosine = np.abs(n @ light) / np.where(length > 0, length, 1.0)
    shade = _AMBIENT + (1.0 - _AMBIENT) * np.where(length > 0, cosine, 0.0)
    return vertex_colours[faces].mean(axis=1) * shade[:, None]


# ----------------------------------------------------------------------------------------------------
# Rendering
# ----------------------------------------------------------------------------------------------------


def render_pair(
    record: PairRecord, path: str | Path, *, size: tuple[int, int] = (900, 450), view: str | Sequence[float] = "auto"
) -> Path:
    """Write a PNG of ``size`` = (width, height) pixels showing X (left) and Y (right) with colour transfer.

    See docs/design/report.md for frames, colours and the view. Both panels share one scale (units of
    the record's common frame) so relative sizes are true. Returns ``path``.
    """
    from matplotlib.figure import Figure

    width, height = (int(v) for v in size)
    if width < 100 or height < 80:
        raise ValueError(f"render size must be at least 100 x 80 pixels, got {size}")
    dpi = 100
    up = _up_vector(record)
    basis = camera_basis(view_direction(record, view), up)
    light = basis @ np.array([-0.35, 0.5, 1.0])  # from the viewer's upper left, in the common frame
    light /= np.linalg.norm(light)

    panels = _projected_panels(record, basis, light)
    fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor=BACKGROUND)
    _draw_panels(fig, record, panels, width, height)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, facecolor=BACKGROUND)
    path = Path(path)
    write_bytes(path, buffer.getvalue())
    return path


def _projected_panels(record: PairRecord, basis: np.ndarray, light: np.ndarray) -> list[tuple]:
    """X's and Y's panel: ``(shape, tri2d, face_rgb, screen)`` with ``screen`` the (V, 3) vertices in the
    camera ``basis`` (columns right, up, towards the viewer), ``tri2d`` the (F, 3, 2) screen triangles
    sorted far to near and ``face_rgb`` their (F, 3) shaded colours (light: (3,) unit, common frame)."""
    xc, yc = common_vertices(record, "x"), common_vertices(record, "y")
    x_colours = position_colours(xc)
    colours = {"x": x_colours, "y": transfer_colours(x_colours, record["corr_10"])}
    panels = []
    for shape, vertices in (("x", xc), ("y", yc)):
        faces = np.asarray(record[f"{shape}_faces"], dtype=np.int64)
        screen = vertices @ basis
        tri = screen[faces]
        order = np.argsort(tri[:, :, 2].mean(axis=1), kind="stable")  # far to near
        face_rgb = shaded_face_colours(vertices, faces, colours[shape], light)
        panels.append((shape, tri[order, :, :2], face_rgb[order], screen))
    return panels


def _draw_panels(fig, record: PairRecord, panels: list[tuple], width: int, height: int) -> None:
    """Draw :func:`_projected_panels` side by side at one scale into ``fig`` (``width`` x ``height``
    pixels), with each panel's label, the pair's title and the colour legend."""
    from matplotlib.collections import PolyCollection

    title_h = 0.16 if height >= 200 else 0.22
    label_h = 0.08
    panel_w, panel_h = 0.5, 1.0 - title_h - label_h
    # one scale for both panels: half the world units per pixel that fit the larger shape (+6 % margin)
    half = 1e-9
    for _, _, _, screen in panels:
        if len(screen):
            half = max(
                half, 0.5 * np.ptp(screen[:, 0]) / panel_w / width, 0.5 * np.ptp(screen[:, 1]) / panel_h / height
            )
    half *= 1.06
    for i, (shape, tri2d, face_rgb, screen) in enumerate(panels):
        ax = fig.add_axes((i * panel_w, label_h, panel_w, panel_h))
        ax.set_axis_off()
        ax.set_facecolor(BACKGROUND)
        cx, cy = (screen[:, :2].min(axis=0) + screen[:, :2].max(axis=0)) / 2 if len(screen) else (0.0, 0.0)
        ax.set_xlim(cx - half * panel_w * width, cx + half * panel_w * width)
        ax.set_ylim(cy - half * panel_h * height, cy + half * panel_h * height)
        if len(tri2d):
            ax.add_collection(
                PolyCollection(
                    tri2d, facecolors=np.clip(face_rgb, 0, 1), edgecolors="none", linewidths=0, antialiased=False
                )
            )
        fig.text(
            i * panel_w + panel_w / 2,
            label_h / 2,
            _panel_label(record, shape),
            ha="center",
            va="center",
            fontsize=9,
            color=TEXT_COLOUR,
        )
    fig.text(
        0.5,
        1.0 - title_h * 0.33,
        _title(record),
        ha="center",
        va="center",
        fontsize=11,
        color=TEXT_COLOUR,
        weight="bold",
    )
    fig.text(
        0.5,
        1.0 - title_h * 0.75,
        "Y coloured by its ground-truth X vertex (corr_10); grey = no counterpart",
        ha="center",
        va="center",
        fontsize=8,
        color=TEXT_COLOUR,
    )


def _title(record: PairRecord) -> str:
    meta = record.meta
    setting = meta.get("setting", "?")
    parts = [str(meta.get("pair_id", "?")), f"{SETTING_LABELS.get(setting, setting)} ({setting})"]
    if meta.get("split"):
        parts.append(str(meta["split"]))
    if meta.get("area_normalised"):
        parts.append("area-normalised")
    if meta.get("accepted") is False:
        parts.append("NOT accepted")
    return "  ·  ".join(parts)


def _panel_label(record: PairRecord, shape: str) -> str:
    info = record.meta.get(shape) or {}
    name = f"{info.get('dataset', '?')}/{info.get('name', '?')}"
    if info.get("class"):
        name += f" ({info['class']})"
    overlap = float(np.asarray(record[f"{shape}_overlap"]))
    kind = "partial" if (np.asarray(record[f"{shape}_full_to_partial"]) < 0).any() else "full"
    n_vertices = len(record[f"{shape}_vertices"])
    return f"{shape.upper()}: {name}, {kind}, {n_vertices:,} V, overlap {overlap:.1%}"


# ----------------------------------------------------------------------------------------------------
# Tables, histogram, report folder
# ----------------------------------------------------------------------------------------------------


def split_order(splits: Iterable[str]) -> list[str]:
    """Distinct split names, train / val / test first, then the others sorted."""
    present = set(splits)
    return [s for s in SPLITS if s in present] + sorted(present - set(SPLITS))  # the others follow, sorted


def select_render_ids(table, n: int) -> list[str]:
    """``n`` pair ids to render, deterministically: round robin over the splits (train, val, test, ...),
    taking each split's pair ids in sorted order (the smallest first)."""
    if n <= 0 or len(table) == 0:
        return []
    per_split = {
        s: sorted(table.loc[table["split"] == s, "pair_id"].astype(str))
        for s in split_order(table["split"].astype(str))
    }
    chosen: list[str] = []
    depth = 0
    while len(chosen) < n and any(depth < len(ids) for ids in per_split.values()):
        for ids in per_split.values():
            if depth < len(ids) and len(chosen) < n:
                chosen.append(ids[depth])
        depth += 1
    return chosen


def table_from_records(records: Iterable[PairRecord]):
    """A pairs table (pandas DataFrame) built from records' meta and overlaps, for records not in a store.

    Columns as the store's table (``pair_id, split, category, seed, x_dataset, x_name, x_class,
    x_category, y_..., x_n_vertices, y_n_vertices, x_overlap, y_overlap, n_tries, accepted``), sorted
    like a store (split train, val, test, then pair_id). ``category`` is the pair's pool: Y's category
    for P2F, X's otherwise (as in :mod:`becos.build.sampling`).
    """
    import pandas as pd

    rows = []
    for record in records:
        meta = record.meta
        row = {
            "pair_id": str(record.pair_id),
            "setting": meta.get("setting"),
            "split": meta.get("split"),
            "seed": meta.get("seed"),
        }
        for s in ("x", "y"):
            info = meta.get(s) or {}
            row.update(
                {
                    f"{s}_dataset": info.get("dataset"),
                    f"{s}_name": info.get("name"),
                    f"{s}_class": info.get("class"),
                    f"{s}_category": info.get("category"),
                }
            )
        row["category"] = row["y_category"] if meta.get("setting") == "partial_full" else row["x_category"]
        for s in ("x", "y"):
            row[f"{s}_n_vertices"] = int(len(record[f"{s}_vertices"]))
            row[f"{s}_overlap"] = float(np.asarray(record[f"{s}_overlap"]))
        row.update(n_tries=meta.get("n_tries"), accepted=bool(meta.get("accepted", True)))
        rows.append(row)
    columns = ["pair_id", "setting", *TABLE_COLUMNS[TABLE_COLUMNS.index("split") :]]  # the store's, by setting
    table = pd.DataFrame(rows, columns=columns)
    if len(table):
        rank = {s: i for i, s in enumerate(split_order(table["split"].astype(str)))}
        table = table.assign(_rank=table["split"].astype(str).map(rank)).sort_values(["_rank", "pair_id"])
        table = table.drop(columns="_rank").reset_index(drop=True)
    return table


def count_table(table):
    """Pair counts as a tidy DataFrame: columns ``group, value, <split>..., total``.

    Groups: ``split``, ``category``, ``x_dataset``, ``y_dataset``, ``dataset_pair`` (``"x/y"``).
    """
    import pandas as pd

    splits = split_order(table["split"].astype(str))
    frame = table.assign(
        split=table["split"].astype(str),
        dataset_pair=table["x_dataset"].astype(str) + "/" + table["y_dataset"].astype(str),
    )
    blocks = []
    for group in ("split", "category", "x_dataset", "y_dataset", "dataset_pair"):
        counts = pd.crosstab(frame[group].astype(str), frame["split"]).reindex(columns=splits, fill_value=0)
        counts = counts.sort_index()
        if group == "split":
            counts = counts.reindex(splits)
        counts["total"] = counts.sum(axis=1)
        counts.columns.name = None
        blocks.append(counts.rename_axis("value").reset_index().assign(group=group))
    if not blocks or len(table) == 0:
        return pd.DataFrame(columns=["group", "value", *splits, "total"])
    out = pd.concat(blocks, ignore_index=True)
    return out[["group", "value", *splits, "total"]].astype({c: "int64" for c in (*splits, "total")})


def overlap_histogram(table) -> dict:
    """Overlap counts in 10 % bins (:data:`HIST_EDGES`), both directions of every pair.

    ``x_overlap`` is the share of X's vertices with a counterpart on Y, ``y_overlap`` the converse.
    Returns ``{"edges": [11 floats], "x": [10 ints], "y": [10 ints], "total": [10 ints],
    "n_directions": int}``; ``sum(total) == n_directions == 2 * len(table)`` (values outside [0, 1]
    or NaN would be a bug upstream and raise ``ValueError``).
    """
    result = {"edges": [round(float(e), 10) for e in HIST_EDGES]}
    total = np.zeros(len(HIST_EDGES) - 1, dtype=np.int64)
    for shape in ("x", "y"):
        values = np.asarray(table[f"{shape}_overlap"], dtype=np.float64)
        bad = ~np.isfinite(values) | (values < 0) | (values > 1)
        if bad.any():
            raise ValueError(
                f"{shape}_overlap has {int(bad.sum())} values outside [0, 1] or NaN, e.g. pair "
                f"{table['pair_id'].iloc[int(np.argmax(bad))]}; the store's table is inconsistent, "
                "rebuild the store"
            )
        # bin k holds [k/10, (k+1)/10); the tolerance puts exact decimal edges (0.3 = 3/10) in the upper bin
        index = np.clip(np.floor(values * (len(HIST_EDGES) - 1) + 1e-9), 0, len(HIST_EDGES) - 2).astype(np.int64)
        counts = np.bincount(index, minlength=len(HIST_EDGES) - 1)
        result[shape] = [int(c) for c in counts]
        total += counts
    result["total"] = [int(c) for c in total]
    result["n_directions"] = int(total.sum())
    return result


def published_overlap_comparison(hist: Mapping) -> dict:
    """Our P2P overlap histogram beside the published one (:data:`becos.build.published.P2P_OVERLAP_HISTOGRAM`).

    ``hist``: :func:`overlap_histogram` of a P2P table. Returns ``{"bin_centre_percent": [10 ints],
    "count": [10], "share": [10], "published_count": [10], "published_share": [10], "n_directions",
    "n_published_directions", "total_variation", "source"}``; shares are fractions of all directions
    (of ours, of the published benchmark's), ``total_variation`` = ½ Σ |share − published_share|
    (0: same shape of histogram, 1: disjoint; ``None`` without pairs).
    """
    from becos.build.published import P2P_OVERLAP_HISTOGRAM

    edges = np.asarray(hist["edges"], dtype=np.float64)
    counts = np.asarray(hist["total"], dtype=np.int64)
    published = np.asarray(P2P_OVERLAP_HISTOGRAM, dtype=np.int64)
    if counts.shape != published.shape:
        raise ValueError(f"the published histogram has {len(published)} bins, ours {len(counts)}")
    n = int(counts.sum())
    share = counts / n if n else np.zeros(len(counts))
    published_share = published / published.sum()
    return {
        "bin_centre_percent": np.round(100 * (edges[:-1] + edges[1:]) / 2).astype(int).tolist(),
        "count": counts.tolist(),
        "share": share.tolist(),
        "published_count": published.tolist(),
        "published_share": published_share.tolist(),
        "n_directions": n,
        "n_published_directions": int(published.sum()),
        "total_variation": float(0.5 * np.abs(share - published_share).sum()) if n else None,
        "source": "BeCoS paper (SGP 2025), P2P overlap histogram: becos.build.published.P2P_OVERLAP_HISTOGRAM",
    }


def plot_overlap_histogram(
    hist: Mapping, path: str | Path, *, title: str = "", size=(700, 420), published: Mapping | None = None
) -> Path:
    """Bar chart of :func:`overlap_histogram` (X->Y and Y->X stacked) as a PNG.

    Without ``published``: counts, totals on top. With ``published``
    (:func:`published_overlap_comparison`): shares of all directions, ours (stacked) and the published
    benchmark's (grey) side by side in each bin, shares in per cent on top.
    """
    from matplotlib.figure import Figure

    edges = np.asarray(hist["edges"])
    centres = 100 * (edges[:-1] + edges[1:]) / 2
    fig = Figure(figsize=(size[0] / 100, size[1] / 100), dpi=100)
    ax = fig.add_axes((0.11, 0.13, 0.86, 0.75))
    x_counts, y_counts = np.asarray(hist["x"]), np.asarray(hist["y"])
    if published is None:
        ax.bar(centres, x_counts, width=9.0, color="#3b6fb6", label="x_overlap (share of X matched on Y)")
        ax.bar(
            centres, y_counts, width=9.0, bottom=x_counts, color="#e08a2e", label="y_overlap (share of Y matched on X)"
        )
        for c, t in zip(centres, x_counts + y_counts):
            ax.text(c, t, str(int(t)), ha="center", va="bottom", fontsize=8)
        ax.set_ylabel("directions (pairs × 2)")
    else:
        n = max(int(hist["n_directions"]), 1)
        ours, theirs = centres - 2.25, centres + 2.25
        ax.bar(ours, 100 * x_counts / n, width=4.4, color="#3b6fb6", label="ours: x_overlap")
        ax.bar(ours, 100 * y_counts / n, width=4.4, bottom=100 * x_counts / n, color="#e08a2e", label="ours: y_overlap")
        ax.bar(
            theirs,
            100 * np.asarray(published["published_share"]),
            width=4.4,
            color="#8c8c8c",
            label=f"published BeCoS ({published['n_published_directions']:,} directions)",
        )
        for c, t in zip(ours, published["share"]):
            ax.text(c, 100 * t, f"{100 * t:.0f}", ha="center", va="bottom", fontsize=7)
        for c, t in zip(theirs, published["published_share"]):
            ax.text(c, 100 * t, f"{100 * t:.0f}", ha="center", va="bottom", fontsize=7, color="#555555")
        ax.set_ylabel("share of directions (%)")
    ax.set_xticks(centres)
    ax.set_xticklabels([f"{int(round(c))}" for c in centres])
    ax.set_xlim(0, 100)
    ax.set_xlabel("overlap (%), 10 %-bins, centre shown")
    ax.margins(y=0.12)
    ax.legend(fontsize=8, loc="best", frameon=False)
    fig.suptitle(title or f"Overlap histogram ({hist['n_directions']} directions)", fontsize=11)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    write_bytes(path, buffer.getvalue())
    return Path(path)


def write_report(
    records: Iterable[PairRecord],
    table,
    out_dir: str | Path,
    *,
    n_renders: int = 8,
    metadata: Mapping | None = None,
    size: tuple[int, int] = (900, 450),
) -> dict:
    """Write the report folder ``out_dir`` and return its summary (also written as ``summary.json``).

    Args:
        records: pair records; only those chosen by :func:`select_render_ids` are rendered (others are
            skipped without rendering; iteration stops once all chosen ones were seen), so passing just
            the chosen records is enough.
        table: the pairs table (pandas DataFrame, one row per pair, with :data:`REQUIRED_COLUMNS`).
        out_dir: output folder (created).
        n_renders: number of sample renders.
        metadata: the store's metadata (setting, config hash, versions, ...), copied into the summary.

    Returns:
        The summary dict: ``setting``, ``n_pairs``, ``counts`` (group -> value -> split/total -> n),
        ``overlap_histogram`` (:func:`overlap_histogram`), ``published_overlap_histogram`` (P2P:
        :func:`published_overlap_comparison`, else ``None``), ``overlap`` (mean/min/max per direction),
        ``renders`` (list of {pair_id, split, file}), ``missing_renders``, ``files`` (kind -> path
        relative to ``out_dir``), ``metadata``.
    """
    missing = [c for c in REQUIRED_COLUMNS if c not in getattr(table, "columns", ())]
    if missing:
        raise ValueError(
            f"pairs table lacks columns {missing}; pass the store's table (Benchmark.table), "
            f"which has {list(REQUIRED_COLUMNS)}"
        )
    out = Path(out_dir)
    (out / "renders").mkdir(parents=True, exist_ok=True)
    metadata = dict(metadata or {})

    counts = count_table(table)
    write_text(out / "counts.csv", counts.to_csv(index=False))
    hist = overlap_histogram(table)
    renders, not_found, settings = _render_samples(records, table, out, n_renders, size)
    setting = metadata.get("setting") or (settings.pop() if len(settings) == 1 else "mixed" if settings else None)

    label = SETTING_LABELS.get(setting or "", setting or "")
    published = published_overlap_comparison(hist) if setting == "partial_partial" else None
    hist_frame = _histogram_frame(hist, published)
    write_text(out / "overlap_histogram.csv", hist_frame.to_csv(index=False))
    plot_overlap_histogram(
        hist,
        out / "overlap_histogram.png",
        published=published,
        title=f"{label} overlap histogram: {len(table)} pairs, {hist['n_directions']} directions"
        + (" vs published" if published else ""),
    )
    summary = _summary(table, setting, counts, hist, published, renders, not_found, metadata)
    write_text(out / "summary.json", json.dumps(summary, indent=2, sort_keys=False) + "\n")
    write_text(out / "index.html", index_html(summary, counts, hist_frame))
    return summary


def _render_samples(records, table, out: Path, n_renders: int, size) -> tuple[list[dict], list[str], set[str]]:
    """Render the pairs :func:`select_render_ids` chooses to ``out/renders/<pair_id>.png``. Returns the
    renders (``pair_id``, ``split``, ``file``) in chosen order, the chosen ids not found among
    ``records`` (sorted), and the settings seen in the table and the records read."""
    chosen = select_render_ids(table, n_renders)
    wanted = set(chosen)
    rendered: dict[str, dict] = {}
    settings = set(table["setting"].astype(str)) if "setting" in table.columns else set()
    for record in records:
        if not wanted:
            break
        pid = str(record.pair_id)
        settings.add(str(record.meta.get("setting")))
        if pid not in wanted:
            continue
        file = f"renders/{pid}.png"
        render_pair(record, out / file, size=size)
        rendered[pid] = {"pair_id": pid, "split": str(record.meta.get("split", "")), "file": file}
        wanted.discard(pid)
    return [rendered[p] for p in chosen if p in rendered], sorted(wanted), settings


def _summary(table, setting, counts, hist, published, renders, not_found, metadata) -> dict:
    """The report's summary (:func:`write_report`'s return value)."""
    summary = {
        "setting": setting,
        "n_pairs": int(len(table)),
        "splits": split_order(table["split"].astype(str)),
        "counts": _nested_counts(counts),
        "overlap_histogram": hist,
        "published_overlap_histogram": published,
        "overlap": {s: _stats(table[f"{s}_overlap"]) for s in ("x", "y")},
        "renders": renders,
        "missing_renders": not_found,
        "files": {
            "counts": "counts.csv",
            "overlap_histogram": "overlap_histogram.png",
            "overlap_histogram_table": "overlap_histogram.csv",
            "summary": "summary.json",
            "index": "index.html",
            "renders": [r["file"] for r in renders],
        },
        "metadata": _jsonable(metadata),
    }
    if "accepted" in table.columns:
        summary["n_not_accepted"] = int((~table["accepted"].astype(bool)).sum())
    names = [c for c in ("x_dataset", "x_name", "y_dataset", "y_name") if c in table.columns]
    if len(names) == 4:
        shapes = set(zip(table["x_dataset"], table["x_name"])) | set(zip(table["y_dataset"], table["y_name"]))
        summary["n_distinct_shapes"] = len(shapes)
    return summary


def _histogram_frame(hist: Mapping, published: Mapping | None = None):
    """The histogram table; with ``published`` also ``share``, ``published_count``, ``published_share``."""
    import pandas as pd

    edges = np.asarray(hist["edges"])
    frame = pd.DataFrame(
        {
            "bin_low": edges[:-1],
            "bin_high": edges[1:],
            "bin_centre_percent": np.round(100 * (edges[:-1] + edges[1:]) / 2).astype(int),
            "x_overlap": hist["x"],
            "y_overlap": hist["y"],
            "total": hist["total"],
        }
    )
    if published is not None:
        frame = frame.assign(
            share=np.round(published["share"], 6),
            published_count=published["published_count"],
            published_share=np.round(published["published_share"], 6),
        )
    return frame


def _nested_counts(counts) -> dict:
    value_columns = [c for c in counts.columns if c not in ("group", "value")]
    nested: dict[str, dict] = {}
    for row in counts.to_dict("records"):
        nested.setdefault(row["group"], {})[str(row["value"])] = {c: int(row[c]) for c in value_columns}
    return nested


def _stats(values) -> dict:
    values = np.asarray(values, dtype=np.float64)
    if len(values) == 0:
        return {"mean": None, "min": None, "max": None}
    return {"mean": float(values.mean()), "min": float(values.min()), "max": float(values.max())}


def _jsonable(value):
    """A JSON-safe copy (numpy scalars/arrays to Python, unknown objects to str)."""
    return json.loads(json.dumps(value, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))
