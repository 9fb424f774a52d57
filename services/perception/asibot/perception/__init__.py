"""Perception: depth images to laser scans, obstacle warnings, the red-object finder."""
