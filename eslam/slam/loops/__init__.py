"""Loop closure (global consistency): the pose graph over keyframes (:mod:`.pose_graph`)."""
