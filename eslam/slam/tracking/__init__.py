"""The tracking front end and its parts: trackers (render, sdf, hybrid) behind one
protocol and registry, view filters, the motion model (ARCHITECTURE.md)."""
