"""Guide (target) strands: the PBD, XPBD and Follow-The-Leader solvers behind one interface
(:func:`~hair_tracking.guides.solver.make_solver`), their constraints, the substep split rule
(:mod:`~hair_tracking.guides.split`) and the head collider.  Imports
:mod:`hair_tracking.core` only."""
