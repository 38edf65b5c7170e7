"""Navigation: the stereo costmap, A* with replanning, and a differential-drive path follower.

The object-search paper's Sec. III-D (the costmap ``M_c`` and A*), as a data flow::

    points_W --fit_ground_plane--> GroundPlane --Costmap.integrate--> free / unknown / obstacle cells
      --Costmap.inflated(radius)--> CostGrid --astar / astar_to_region--> PathResult
      --simplify_path--> waypoints --PathFollower / drive_to--> robot.drive(v, omega)

Grid geometry and frames follow ``docs/conventions.md`` (world frame W, metres, radians).
"""
