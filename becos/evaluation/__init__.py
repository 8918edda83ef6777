"""Scoring correspondences against a benchmark: metrics, tables, baselines."""
