"""Meshes from the learned field: marching cubes over observed space."""
