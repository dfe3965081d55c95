"""Head motion: the head-pose stream type and its maths, and the readers of recorded motion
(BVH motion capture, pose tables); numpy only, below every layer that uses head motion."""
