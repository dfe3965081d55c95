"""rosbag2 files and recorded head motion: bag I/O, head-motion readers (BVH, pose tables), offline
runs, live play and record, rendering, and the ``hair_sim_bag`` command."""
