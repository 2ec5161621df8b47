"""SLAM: keyframes and window selection, tracking, mapping, run state and the run loop.

``slam/loop.py`` alone orchestrates; the other modules are called from it and know
nothing of each other's internals.
"""
