"""Stage 1 of a run: check that the enabled datasets and the annotation folder are present and sound.

:func:`check_datasets` looks at every enabled dataset below the data root (folder, shape count, a cheap
check of every mesh file) and at the BeCoS annotation folder (network, template table, edge files,
default faces) and returns a JSON-able report. Every problem is collected first; one
:class:`DatasetCheckError` then lists them all, each with where to get the data, the folder to create or
the config key to change. One module per part: ``datasets``, ``meshes``, ``templates``, ``edges``,
``annotations``. What each check looks at, and the report's keys: docs/design/data.md.
"""

from becos.sources.check.datasets import MAX_LISTED_MESHES, DatasetCheckError, check_datasets
from becos.sources.check.edges import (
    EDGE_MAX_RESIDUAL,
    EDGE_MAX_STRETCH,
    EDGE_ROW_MAX_JUMP,
    edge_plausibility,
    edge_row_jumps,
    require_plausible_edge,
)
from becos.sources.check.meshes import check_mesh_file, inspect_mesh_file, mesh_arrays
from becos.sources.check.templates import CLASS_EDGE_RATIO, compare_with_class_template

__all__ = [
    "CLASS_EDGE_RATIO",
    "EDGE_MAX_RESIDUAL",
    "EDGE_MAX_STRETCH",
    "EDGE_ROW_MAX_JUMP",
    "MAX_LISTED_MESHES",
    "DatasetCheckError",
    "check_datasets",
    "check_mesh_file",
    "compare_with_class_template",
    "edge_plausibility",
    "edge_row_jumps",
    "inspect_mesh_file",
    "mesh_arrays",
    "require_plausible_edge",
]
