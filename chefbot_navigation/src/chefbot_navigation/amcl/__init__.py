"""AMCL-compatible Monte Carlo localization, pure numpy (no rospy, time in float s).

* :mod:`.motion`      sample motion model of a differential drive (odometry deltas)
* :mod:`.sensor`      likelihood-field measurement model (distance transform of the map)
* :mod:`.resample`    low-variance resampling, KLD bound, pose clusters
* :mod:`.filter`      the particle set: initialise, predict, weigh, resample, estimate
* :mod:`.localizer`   AMCL's update logic (update_min_d/a, recovery, map->odom, diagnostics)

Particles are an (N, 3) float array of (x m, y m, yaw rad) in the map frame.
"""
