"""SLAM core (pure, no rospy): log-odds grid, scan matcher, pose graph, mapper, frontiers."""
