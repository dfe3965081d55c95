"""The ROS 2 node (``hair_sim_node``), its load shedding, the live demo and ``hair_sim_bag``'s
play and record.  The only layer of :mod:`hair_tracking` that joins a ROS graph."""
