"""Workflows that combine the SLAM run with meshing, culling, metrics and plots.

The top library layer (only the CLI sits above it): ``evaluate_run`` behind
``eslam eval``, ``run_demo`` behind ``eslam demo``, ``run_sweep`` and ``write_table``
behind ``eslam sweep`` and ``eslam table`` (docs/sweeps.md), ``trajectory_errors``
behind ``eslam ate`` and ``mesh_errors`` behind ``eslam recon`` (docs/evaluation.md).
"""
