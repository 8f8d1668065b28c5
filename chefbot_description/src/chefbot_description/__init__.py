"""ChefBot robot model: URDF/xacro, simulation parameters, RViz configs and model launch files."""
