"""MuJoCo simulation of both robots (ASIBOT kitchen, Pioneer apartment) behind the driver contract.

Modules: scene (MJCF world + catalog URDF -> model), arm and base (driver rules), sensors,
cameras, simulation (the physics core, no bus), service (the core on the bus), make_map
(occupancy map from the MJCF), places (named places file), viewer (optional window).
"""
