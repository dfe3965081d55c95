"""Error against run time, stability on stiff and extreme cases, synthetic head motions and the
offline demo (``hair_sim_eval``, ``hair_sim_demo``)."""
