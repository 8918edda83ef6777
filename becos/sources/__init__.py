"""The inputs of a benchmark: datasets, their download and preparation, the annotation folder, their check."""
