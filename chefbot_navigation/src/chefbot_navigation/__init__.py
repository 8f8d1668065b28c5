"""Map server and saver, SLAM, localization and a move_base-compatible action server."""
