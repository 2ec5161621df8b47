"""The mapping back end and its parts: keyframes and windows, the mapper, the scene
bound, the first frame's warm start (ARCHITECTURE.md)."""
