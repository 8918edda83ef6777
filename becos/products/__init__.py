"""What a run delivers: the store, its validation and comparison, exports and the report."""
