"""hair_tracking: real-time hair that follows a head pose.

Guide (target) strands are simulated with position-based dynamics; many ghost strands track them
(Park & Kim, "PBD-based Framework for Efficiently Controlling the Movement of Strands in Hair").
The core modules of this package import numpy, numba and yaml only.  Importing the package
changes nothing in the process: numba's cache folder and the other process-wide settings are
made by each executable's ``main()`` (:mod:`hair_tracking.executable`).
"""
