"""Ghost strands that follow the guides: correspondence (eq. 1), the weights (eq. 4-5), the
tracking kernels and their head contacts.  Imports :mod:`hair_tracking.core` and
:mod:`hair_tracking.guides` only."""
