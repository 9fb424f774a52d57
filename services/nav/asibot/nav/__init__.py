"""Navigation for the Pioneer: map, localisation (AMCL), costmap, planners, places, driving primitives.

Plain logic, no bus (docs/nav.md): mapfile, grid, costmap, planner, amcl, local, recovery,
navigator, places, primitives; robot (P3-AT footprint and limits), geometry, errors.
"""
