"""Plots of a run's results (matplotlib, the [viz] extra)."""
