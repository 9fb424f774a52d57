"""Named places of a world (worlds/<world>_places.yaml), the file the nav service also reads."""

from __future__ import annotations

import yaml

from asibot.sim.scene import WORLDS_DIR


def load_places(world: str) -> dict[str, tuple[float, float, float]]:
    """name -> (x, y, theta) in the map frame; empty for a world without places."""
    path = WORLDS_DIR / f"{world}_places.yaml"
    if not path.exists():
        return {}
    doc = yaml.safe_load(path.read_text())
    return {name: (float(p["x"]), float(p["y"]), float(p["theta"])) for name, p in doc["places"].items()}
