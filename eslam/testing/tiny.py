"""Settings small enough for a whole run on 2 CPU cores in seconds (tests, drills).

Coarse planes (0.24 / 0.12 m cells), few rays, samples and iterations. The paper's
`render` tracker: on planes this coarse the learned TSDF is too rough near surfaces for
the SDF stage of `hybrid` (it tracks the tests' tiny sequence worse than `render`);
the trackers have their own tests. The first frame keeps the 60 plain rendering steps
the tiny runs were tuned with (the demo config's TSDF warm start is tested on its own,
tests/slam/test_first_frame.py).
"""

TINY_SETTINGS = (
    "tracking.method=render",
    "tracking.render.rays=200",
    "tracking.border=4",
    "tracking.render.iterations=8",
    "mapping.rays=400",
    "mapping.every=3",
    "mapping.window=4",
    "mapping.iterations=6",
    "mapping.first_iterations=60",
    "mapping.first_lr_factor=5.0",
    "mapping.first_warm_start=none",
    "render.samples_stratified=12",
    "render.samples_surface=6",
    "output.progress=false",
    "output.checkpoint_every=4",
    "output.mesh_resolution=0.1",
    "field.geometry_resolution=[0.24, 0.12]",
    "field.appearance_resolution=[0.24, 0.12]",
)
"""``key=value`` overrides for any config (later overrides win, e.g. a checkpoint_every)."""
