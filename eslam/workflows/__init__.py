"""Workflows that combine the SLAM run with meshing, culling, metrics and plots.

The top library layer (only the CLI sits above it): ``evaluate_run`` behind
``eslam eval``, ``run_demo`` behind ``eslam demo``.
"""
