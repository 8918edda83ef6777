"""The workflow's stages as library functions: config -> plan -> the work of one job.

Snakemake (``Snakefile``, ``workflow/rules/*.smk``) only names files; every job runs one ``becos``
sub-command, which calls one function of :mod:`becos.workflow.stages` (or of :mod:`becos.store`,
:mod:`becos.export`, :mod:`becos.validate`, :mod:`becos.report`). One idea per module:

    config    the schema (``becos/data/schema.yaml``, the only statement of the defaults), config files
    digests   content digests of the input files (what reruns the dataset check and a remesh)
    options   the options builder, the one reader of the resolved config: one frozen dataclass per
              stage (its fields are the keys that rerun it), the options JSON a job receives, the
              checks across keys, ``remesher: auto`` resolved
    layout    where every file under ``results`` lives, which remesh file a pair side uses
    plan      catalog, manifests and the jobs they imply (what Snakemake needs to build the job graph)
    shapes    a chunk job's shapes, kept while its pairs use them
    stages    one function per job kind

Every public name is importable from ``becos.workflow`` itself (``import becos.workflow as bw``).

Files under ``results`` (config key ``results``)::

    config.json                         the resolved configuration (defaults filled in)
    checks/datasets.json                what the dataset check found
    catalog.csv                         every shape of the enabled datasets (becos.catalog)
    remeshed/<dataset>/<name>/<v>.npz   one remesh variant: mesh + maps to/from the original (.ply beside)
    <setting>/manifest.csv              the pairs of a setting (becos.sampling)
    <setting>/ground_truth/chunk_<k>.json  index of the chunk's ground-truth files <pair_id>.npz
    <setting>/pairs/chunk_<k>.json      index of the chunk's pair records <pair_id>.npz (becos.record)
    <setting>/benchmark.zarr            the store (becos.store), validated into validation.json
    cache/                              parsed meshes and edge files (safe to delete)

Incremental rebuilds. A pair's chunk job is a contiguous range of fixed hash buckets of its id
(:func:`becos.sampling.assign_chunks`; the manifest's ``chunk`` column records the grouping), so
growth adds pairs to chunks and moves one only when the number of chunk jobs doubles; a moved pair
keeps its files (named by pair id; the chunk is not part of any input key). A chunk job reruns when
the manifest or catalog is rewritten or its stage's options change (they are its Snakemake
``params``, :func:`job_options`); a remesh job only when its shape's catalog row or target changes.
Inside a chunk job, a pair's file is rewritten only when the pair's *input key* changed: the digest
of its manifest row (except its chunk), the stage options and the digests of the files
it reads (remesh variants, ground truth). So enabling another dataset recomputes only the new or
re-partnered pairs, and changing ``min_overlap`` recomputes records but no remesh and no ground truth.
"""

from becos.workflow.config import (
    CONFIG_DOCS,
    SCHEMA_PATH,
    check_config_files,
    load_config,
    read_config_file,
    resolve_config,
    schema_problems,
)
from becos.workflow.digests import (
    DigestCache,
    annotation_input_files,
    check_input_files,
    dataset_input_files,
    generated_folders,
)
from becos.workflow.layout import (
    Layout,
    pair_file,
    remesh_token,
    remeshed_file,
)
from becos.workflow.options import (
    GROUND_TRUTH_VERSION,
    PAIRS_OPTIONS,
    RECORD_VERSION,
    REMESH_VERSION,
    STAGE_OPTIONS,
    STORE_STAGES,
    AnnotationOptions,
    CatalogOptions,
    CheckOptions,
    ExportOptions,
    GroundTruthOptions,
    ManifestOptions,
    PairsOptions,
    PartialFullPairsOptions,
    PartialPartialPairsOptions,
    RemeshOptions,
    SourceOptions,
    StageOptions,
    check_config,
    digest,
    job_options,
    pairs_options,
    settings_of,
    stage_options,
    store_keys,
)
from becos.workflow.plan import (
    Plan,
    annotation_source,
    build_catalog,
    build_manifest,
    edge_files_between,
    published_views_folder,
    remesh_target,
    uses_published_views,
)
from becos.workflow.shapes import (
    MESHES_KEPT,
    SHAPES_KEPT,
    ShapeKey,
    ShapeStore,
    pair_shape_keys,
    shape_entry,
    visit_order,
)
from becos.workflow.stages import (
    export_pairings_stage,
    ground_truth_intact,
    ground_truth_stage,
    load_ground_truth,
    missing_indexed_files,
    narrow_faces,
    pair_options,
    pair_published_rotations,
    pair_published_views,
    pairs_stage,
    published_parts,
    remesh_stage,
    store_metadata,
    stored_key,
    write_catalog_stage,
    write_manifest_stage,
)

__all__ = [
    "DigestCache",
    "check_input_files",
    "generated_folders",
    "dataset_input_files",
    "annotation_input_files",
    "pair_file",
    "remeshed_file",
    "published_views_folder",
    "uses_published_views",
    "GROUND_TRUTH_VERSION",
    "RECORD_VERSION",
    "REMESH_VERSION",
    "STAGE_OPTIONS",
    "PAIRS_OPTIONS",
    "STORE_STAGES",
    "StageOptions",
    "AnnotationOptions",
    "CheckOptions",
    "CatalogOptions",
    "ManifestOptions",
    "RemeshOptions",
    "ExportOptions",
    "GroundTruthOptions",
    "PairsOptions",
    "PartialFullPairsOptions",
    "PartialPartialPairsOptions",
    "SourceOptions",
    "digest",
    "stage_options",
    "pairs_options",
    "job_options",
    "store_keys",
    "SCHEMA_PATH",
    "resolve_config",
    "CONFIG_DOCS",
    "schema_problems",
    "check_config",
    "settings_of",
    "load_config",
    "read_config_file",
    "check_config_files",
    "Layout",
    "remesh_token",
    "annotation_source",
    "build_catalog",
    "build_manifest",
    "Plan",
    "remesh_target",
    "edge_files_between",
    "SHAPES_KEPT",
    "MESHES_KEPT",
    "shape_entry",
    "ShapeKey",
    "pair_shape_keys",
    "visit_order",
    "ShapeStore",
    "write_catalog_stage",
    "write_manifest_stage",
    "remesh_stage",
    "stored_key",
    "ground_truth_stage",
    "narrow_faces",
    "load_ground_truth",
    "ground_truth_intact",
    "missing_indexed_files",
    "pair_options",
    "pairs_stage",
    "pair_published_views",
    "pair_published_rotations",
    "store_metadata",
    "published_parts",
    "export_pairings_stage",
]
