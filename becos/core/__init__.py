"""Meshes and maps between surfaces: the types and geometry every stage shares."""
