"""A run's plumbing, apart from the algorithm: observers (log, progress, writer,
viewer), the run folder, stops and resources (ARCHITECTURE.md)."""
