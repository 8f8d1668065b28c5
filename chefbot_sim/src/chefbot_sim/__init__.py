"""A pybullet world standing in for Gazebo, with plugin and firmware-in-the-loop drive modes."""
