"""Validation of a benchmark store (:mod:`becos.store`): every invariant a consumer relies on.

:func:`validate_store` returns human-readable problems (empty = valid); each starts with the name
of the check that failed, then says what is wrong, in how many pairs, with example pair ids::

    index_range: corr_01 outside [-1, V_y) in 1 pair(s), e.g. pp00000000000001 (1 value(s))

Problems about the store as a whole (``store``, ``schema``, ``metadata``) name the store, array or
attribute instead of pairs. Checks (vectorised over blocks of pairs of about
:data:`VALIDATE_BLOCK_BYTES`, read with :meth:`becos.store.Benchmark.read_block`):

================  ==================================================================================
``store``         the store opens and reads: the folder exists and is a Zarr v3 becos store, every
                  array, offsets and pairs node its layout names is present with readable metadata,
                  every chunk decodes (a damaged store ends in this one problem, not a traceback)
``checksum``      every array's and offsets array's content has the sha256 recorded when the store was
                  written (``becos_store.sha256``): catches a chunk file deleted (Zarr reads it back
                  as zeros), truncated or edited afterwards; skipped for stores written before
                  becos recorded digests, and when a chunk does not decode (``store`` says which)
``schema``        keys, dtypes, trailing shapes and offset groups as in :mod:`becos.record` /
                  :mod:`becos.store`; offsets start at 0, never decrease and end at the array's rows
``metadata``      root attributes: schema version, setting, pair count, pairs per split, the
                  ``versions`` of the building libraries
``meta``          per pair: setting equals the store's, split is train/val/test, schema version
``table``         the pairs table agrees with the metas (every column :func:`becos.store.table_row`
                  derives from them) and the arrays (sizes, overlaps); index column 0..N-1; rows in
                  store order (split train, val, test, then others; by pair_id inside a split)
``pair_id``       pair ids unique
``index_range``   faces, corr_01/corr_10 (+ ``_face``), partial_to_full, full_to_partial,
                  full_face_ids, full_faces index inside their targets (-1 only where allowed)
``unmatched``     corr_01 >= 0 and corr_01_face >= 0 exactly where x_overlap_mask (same for Y);
                  weight rows of unmatched vertices are all 0 (or all NaN)
``weights``       weights of matched vertices finite, >= 0, summing to 1
``corr_face``     corr_01 is the vertex nearest its point along the surface among corr_01_face's corners
                  and its edge neighbours' far corners (same for corr_10); records of an older becos by
                  their meta ``vertex_rounding``: ``nearest_corner``, the corner nearest in 3D; none, the
                  largest-weight corner
``overlap``       s_overlap equals the mask's mean; partial_partial pairs whose meta says
                  ``accepted`` have both overlaps in [min_overlap, max_overlap] of meta ``options``
``index_maps``    partial_to_full strictly increasing, full_to_partial its inverse (-1 elsewhere)
``full_shape``    a full shape keeps every face and vertex (identity maps)
``setting``       full_full: both shapes full; partial_full: X full
``face_map``      partial shapes: partial_to_full[faces] == full_faces[full_face_ids]
``vertex_map``    partial shapes: vertices == full_vertices[partial_to_full] (to 1e-9 relative)
``connectivity``  partial shapes: one edge-connected component, every vertex on a face
``rotation``      frame, alignment and random rotations orthonormal with det +1
``alignment``     X's alignment is the identity (rotation I, translation 0)
``camera``        NaN for the shapes the setting keeps full (both in full_full, X in partial_full),
                  finite for scanned ones (a scan that happens to see every face is stored as a
                  full shape but keeps its camera)
``scalars``       full_area > 0, full_sqrt_area**2 == full_area, dataset_scale > 0, remesh_variant >= -1
``finite``        vertex coordinates, centres and translations finite
``split_classes`` no (dataset, class) in two splits — for datasets whose split rule holds classes
                  out (``by_class``, ``template_table`` or unknown; not ``slices``/``by_name``,
                  whose splits share classes by design); the X side of partial_full pairs (the
                  class template) is exempt
``centaur``       centaur shapes only in train
================  ==================================================================================

Command line: ``becos validate STORE [--json OUT] [--against OTHER [--atol TOL]]`` prints a JSON
summary; with problems it lists them on stderr and exits with status 1. With ``--against`` it then
compares STORE with OTHER (:func:`becos.compare.compare_stores`: pairs only in one store, per pair
which arrays differ and why, metadata and library versions that differ), prints the comparison's
summary on stdout and exits with status 1 when the stores differ too; ``--json`` then also holds the
full comparison under ``comparison``. Exit status 2: OTHER cannot be opened.

One module per idea: :mod:`~becos.validate.run` (:func:`validate`, the order of the checks),
:mod:`~becos.validate.opening` (``store``: opening a store, naming missing and unreadable nodes and
chunks), :mod:`~becos.validate.tables` (``schema``, ``metadata``, ``meta``, ``table``, ``pair_id``,
``split_classes``, ``centaur``), :mod:`~becos.validate.block` (the row-wise checks of a block of
pairs), :mod:`~becos.validate.content` (``checksum``) and :mod:`~becos.validate.report` (the problems
and the :class:`ValidationReport`). The comparison with ``--against`` is :mod:`becos.compare`.
"""

from becos.validate.block import ROTATION_TOL, WEIGHT_TOL, BlockChecker
from becos.validate.opening import open_for_validation
from becos.validate.report import MAX_EXAMPLES, Problems, ValidationReport
from becos.validate.run import VALIDATE_BLOCK_BYTES, validate, validate_store
from becos.validate.tables import expected_schema

__all__ = [
    "MAX_EXAMPLES",
    "ROTATION_TOL",
    "VALIDATE_BLOCK_BYTES",
    "WEIGHT_TOL",
    "BlockChecker",
    "Problems",
    "ValidationReport",
    "expected_schema",
    "open_for_validation",
    "validate",
    "validate_store",
]
