"""Real depth cameras on the bus: the same depth, RGB and CameraInfo messages as the sim's."""
