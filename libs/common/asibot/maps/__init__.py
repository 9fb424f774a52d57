"""The shipped occupancy maps (ROS map_server format), made from the sim's worlds by `python -m asibot.sim.make_map`; nav and the base emulator read them through importlib.resources."""
