"""The data every layer shares: the scene, the model of the strands, the head track, transforms,
curves, metrics and the declarative parameter table.  numpy, numba and yaml only."""
