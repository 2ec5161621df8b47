"""Place recognition over the keyframes: which keyframes see what a frame sees, and
where the frame's camera is if it sees the same place (relocalisation; loop closure)."""
