"""becos: build full and partial 3D shape-matching benchmarks with exact ground truth.

One module per idea; the table of modules and what each does is in docs/architecture.md.
"""

__version__ = "0.1.0"
