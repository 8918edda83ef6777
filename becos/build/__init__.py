"""Building the benchmark: remeshing, ground truth through the shape network, partial scans, pairs."""
