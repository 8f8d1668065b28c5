"""ChefBot fleet: several robots in one restaurant (pure modules; the nodes are in ../../nodes)."""
