"""Guide (target) strands: PBD, XPBD and Follow-The-Leader solvers, their constraints and the head
collider.  Imports :mod:`hair_tracking.core` only."""
