"""becos: build full and partial 3D shape-matching benchmarks with exact ground truth.

Modules, one idea each:

- :mod:`becos.mesh` -- triangle meshes, reading mesh files, the parsed-array cache.
- :mod:`becos.geometry` -- areas, barycentric coordinates, closest points on a surface.
- :mod:`becos.surface_map` -- maps from vertices to points on another surface, their composition.
- :mod:`becos.annotations` -- the BeCoS annotation folder (network, template tables, edge files).
- :mod:`becos.datasets` -- the dataset registry (``config/datasets/*.yaml``) and shape catalog.
- :mod:`becos.network` -- paths through the shape network and ground-truth maps between shapes.
- :mod:`becos.remesh` -- remeshing with both vertex maps to and from the original surface.
"""

__version__ = "0.1.0"
