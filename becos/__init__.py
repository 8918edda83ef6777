"""becos: build full and partial 3D shape-matching benchmarks with exact ground truth.

Modules, one idea each:

- :mod:`becos.mesh` -- triangle meshes, reading mesh files, the parsed-array cache.
- :mod:`becos.geometry` -- areas, barycentric coordinates, closest points on a surface.
- :mod:`becos.surface_map` -- maps from vertices to points on another surface, their composition.
- :mod:`becos.annotations` -- the BeCoS annotation folder (network, template tables, edge files).
- :mod:`becos.datasets` -- the dataset registry (``config/datasets/*.yaml``) and shape catalog.
- :mod:`becos.network` -- paths through the shape network and ground-truth maps between shapes.
- :mod:`becos.remesh` -- remeshing with both vertex maps to and from the original surface.
- :mod:`becos.cameras`, :mod:`becos.visibility`, :mod:`becos.partiality`, :mod:`becos.align` -- virtual
  scans, partial shapes and their overlap, rigid alignment.
- :mod:`becos.pairs`, :mod:`becos.record` -- one matching instance (F2F, P2F, P2P) as a pair record.
- :mod:`becos.catalog`, :mod:`becos.sampling`, :mod:`becos.published` -- shape catalog, pair manifests,
  the published pair lists.
- :mod:`becos.propagation` -- left/right labels through the network.
- :mod:`becos.check`, :mod:`becos.workflow` -- dataset checks; configuration, plan and stages of the
  Snakemake workflow.
- :mod:`becos.store`, :mod:`becos.validate`, :mod:`becos.export`, :mod:`becos.report` -- the Zarr store
  and its validation, released/PSMAL layouts, reports.
- :mod:`becos.geodesics`, :mod:`becos.metrics`, :mod:`becos.evaluate`, :mod:`becos.baselines` -- scoring.
- :mod:`becos.synthetic` -- the built-in synthetic shape collection.
"""

__version__ = "0.1.0"
