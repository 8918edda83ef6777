"""Exports of a benchmark in layouts that existing matching code already reads.

Writers take an iterable of :class:`~becos.build.record.PairRecord` (a store's ``Benchmark.records()``)
and stream it: :mod:`.released` (the released BeCoS layout), :mod:`.psmal`, :mod:`.dpfm`,
:mod:`.ulrssm` (its MAT files: :mod:`.mat`), and :mod:`.geodesics` (geodesic matrices where loaders
read them; DeepShapeMatchingKit's cache names: :mod:`.dsmk`). :mod:`.staging` holds what they share (folders renamed into place, per-split numbering, ids, logs), :mod:`.text`
the OFF/VTS text. Layouts, files and keys: ``docs/released-layout.md``.
"""

from becos.build.record import full_shape
from becos.core.formats.write import off_text, vts_text
from becos.products.export.dpfm import DPFM_NONE_MAPS, dpfm_shape_id, write_dpfm
from becos.products.export.dsmk import DSMK_FOLDER, dsmk_cache_name
from becos.products.export.geodesics import (
    GEODESIC_FOLDER,
    GEODESIC_LAYOUTS,
    mesh_sqrt_areas,
    symmetric_block,
    write_geodesic_matrices,
    write_geodesics,
)
from becos.products.export.mat import MAT_MAX_VERTICES, mat_prefix, mat_size, write_symmetric_mat
from becos.products.export.psmal import psmal_shape_id, write_psmal
from becos.products.export.released import (
    PICKLE_PROTOCOL,
    info_pickle_bytes,
    mesh_id,
    released_file_stem,
    released_infos,
    released_stem,
    write_released,
)
from becos.products.export.staging import IDS_FILE, LAYOUT_VERSION, LOGS_DIR, SIDES, DiskEstimateError, ExportError
from becos.products.export.ulrssm import ulrssm_geodesic_estimate, ulrssm_template_vts, write_ulrssm

__all__ = [
    "DPFM_NONE_MAPS",
    "DSMK_FOLDER",
    "GEODESIC_FOLDER",
    "GEODESIC_LAYOUTS",
    "IDS_FILE",
    "LAYOUT_VERSION",
    "LOGS_DIR",
    "MAT_MAX_VERTICES",
    "PICKLE_PROTOCOL",
    "SIDES",
    "DiskEstimateError",
    "ExportError",
    "dpfm_shape_id",
    "dsmk_cache_name",
    "full_shape",
    "info_pickle_bytes",
    "mat_prefix",
    "mat_size",
    "mesh_id",
    "mesh_sqrt_areas",
    "off_text",
    "psmal_shape_id",
    "released_file_stem",
    "released_infos",
    "released_stem",
    "symmetric_block",
    "ulrssm_geodesic_estimate",
    "ulrssm_template_vts",
    "vts_text",
    "write_dpfm",
    "write_geodesic_matrices",
    "write_geodesics",
    "write_psmal",
    "write_released",
    "write_symmetric_mat",
    "write_ulrssm",
]
