"""ChefBot vision: book chapter 7 (OpenCV with ROS), depth -> point clouds."""
