"""The robots' URDF models: data, read through importlib.resources (asibot.robots)."""
