"""eslam: dense neural RGB-D SLAM (ESLAM, CVPR 2023) on CPU and GPU.

Nothing runs on import. The public API grows with the package; see README.md.
"""

__version__ = "0.1.0"
