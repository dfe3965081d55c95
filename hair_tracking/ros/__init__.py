"""The ROS 2 node (``hair_sim_node``), its load shedding and the live demo.  The only layer of
:mod:`hair_tracking` that is a ROS node."""
