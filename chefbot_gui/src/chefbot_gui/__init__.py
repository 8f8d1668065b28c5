"""PyQt5 table-delivery GUI, an action client of move_base."""
