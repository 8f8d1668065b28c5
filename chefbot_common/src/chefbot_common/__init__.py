"""What every ChefBot package shares: params, planar geometry, grids and map files, tables, rostest helpers.

Pure Python; nothing here imports another chefbot package.
"""
