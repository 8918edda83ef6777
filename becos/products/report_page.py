"""The report folder's ``index.html`` (:func:`becos.products.report.write_report`): static HTML with relative
links to the folder's files (facts, overlap histogram, the published P2P comparison, renders, counts,
store metadata); opens without Snakemake."""

from __future__ import annotations

import html
import json
from collections.abc import Mapping

from becos.settings import SETTING_LABELS


def index_html(summary: Mapping, counts, hist_frame) -> str:
    """The report's ``index.html``: facts, histogram, published comparison (P2P), renders, counts, metadata."""
    esc = html.escape
    setting = summary.get("setting") or "?"
    label = SETTING_LABELS.get(setting, setting)
    meta = summary.get("metadata") or {}
    rows = _facts_html(summary, label, setting, meta)
    gallery = (
        "\n".join(
            f'<figure><a href="{esc(r["file"])}"><img src="{esc(r["file"])}" alt="{esc(r["pair_id"])}" '
            f'loading="lazy"></a><figcaption>{esc(r["pair_id"])} ({esc(r["split"])})</figcaption></figure>'
            for r in summary["renders"]
        )
        or "<p>No renders.</p>"
    )
    missing = ""
    if summary.get("missing_renders"):
        missing = f"<p class=warn>Not found among the records: {esc(', '.join(summary['missing_renders']))}</p>"
    published = summary.get("published_overlap_histogram")
    comparison = _published_comparison_html(published) if published else ""
    count_blocks = "\n".join(
        f"<h3>{esc(group)}</h3>\n" + block.drop(columns="group").to_html(index=False, border=0, escape=True)
        for group, block in counts.groupby("group", sort=False)
    )
    return f"""<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>BeCoS benchmark report: {esc(label)}</title>
<style>
body {{ font-family: sans-serif; margin: 2em auto; max-width: 1200px; color: #1d2c57; }}
table {{ border-collapse: collapse; margin-bottom: 1em; }}
th, td {{ padding: 2px 10px; text-align: right; border-bottom: 1px solid #ddd; }}
th {{ text-align: left; }}
figure {{ display: inline-block; margin: 0 1em 1em 0; }}
figure img {{ width: 560px; border: 1px solid #ccc; }}
.warn {{ color: #a00; }}
pre {{ background: #f5f5f8; padding: 1em; overflow-x: auto; }}
</style>
</head>
<body>
<h1>BeCoS benchmark report: {esc(label)}</h1>
<table>
{rows}
</table>
<p>Files: <a href="summary.json">summary.json</a>, <a href="counts.csv">counts.csv</a>,
<a href="overlap_histogram.csv">overlap_histogram.csv</a>.</p>
<h2>Overlap histogram</h2>
<p>Share of each shape's vertices whose ground-truth point lies on the other shape, both directions of
every pair ({summary["overlap_histogram"]["n_directions"]} directions), in 10 % bins.</p>
<img src="overlap_histogram.png" alt="overlap histogram">
{hist_frame.to_html(index=False, border=0)}
{comparison}
<h2>Sample pairs</h2>
<p>X (left) is coloured by its vertex positions; each Y vertex (right) takes the colour of its ground-truth
X vertex; grey Y vertices have no counterpart on X. Random rotations undone, common y-up frame.</p>
{missing}
{gallery}
<h2>Counts</h2>
{count_blocks}
<h2>Metadata</h2>
<details><summary>store metadata (JSON)</summary>
<pre>{esc(json.dumps(meta, indent=2, sort_keys=True))}</pre>
</details>
</body>
</html>
"""


def _facts_html(summary: Mapping, label: str, setting: str, meta: Mapping) -> str:
    """The table rows of the report's facts: setting, pairs, splits, shapes, store identity."""
    esc = html.escape
    facts = [
        ("setting", f"{label} ({setting})"),
        ("pairs", summary["n_pairs"]),
        (
            "splits",
            ", ".join(
                f"{s}: {summary['counts'].get('split', {}).get(s, {}).get('total', 0)}" for s in summary["splits"]
            ),
        ),
    ]
    for key in ("n_distinct_shapes", "n_not_accepted"):
        if key in summary:
            facts.append((key.replace("n_", "").replace("_", " "), summary[key]))
    for key in ("schema_version", "config_hash", "created"):
        if key in meta:
            facts.append((key.replace("_", " "), meta[key]))
    return "\n".join(f"<tr><th>{esc(str(k))}</th><td>{esc(str(v))}</td></tr>" for k, v in facts)


def _published_comparison_html(published: Mapping) -> str:
    """The section that sets the histogram beside the published BeCoS P2P one."""
    tv = published["total_variation"]
    rows_html = "\n".join(
        f"<tr><td>{c} %</td><td>{n:,}</td><td>{100 * a:.1f} %</td><td>{m:,}</td><td>{100 * b:.1f} %</td></tr>"
        for c, n, a, m, b in zip(
            published["bin_centre_percent"],
            published["count"],
            published["share"],
            published["published_count"],
            published["published_share"],
        )
    )
    return f"""<h3>Beside the published BeCoS P2P histogram</h3>
<p>Shares of all directions (ours: {published["n_directions"]:,}; published:
{published["n_published_directions"]:,} = 2 &times; 10,464 pairs, from the BeCoS paper).
Total variation distance: {"n/a" if tv is None else f"{tv:.3f}"} (0 = same shape, 1 = disjoint).</p>
<table class=published>
<tr><th>bin centre</th><th>ours</th><th>ours share</th><th>published</th><th>published share</th></tr>
{rows_html}
</table>"""
