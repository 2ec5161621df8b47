"""SLAM: the run loop and its components.

``slam/session.py`` wires a run (config, input, run folder, observers, components);
``slam/loop.py`` sequences its frames through the tracking front end
(``slam/tracking/frontend.py``: view filters, tracker, judgement, motion model) and
the mapping back end (``slam/mapping/backend.py``: keyframes, bound growth, window,
mapper); ``slam/run/`` is the run's plumbing (observers, writer, log, progress).
Each component is chosen by name from a registry (:class:`eslam.registry.Registry`)
and keeps its state in the run's :class:`~eslam.slam.state.SLAMState`.
"""
