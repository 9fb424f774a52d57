"""The web Task Creator: the ASIBOT's browser interface (jog, capture points, program, assign, launch)."""
