"""A trip to one of the person's places counts as a use of it, however it was sent: the page,
the voice, the AsTeRICS bridge, a program or the command line all reach nav, and nav says on
the bus which place its new goal is (NavStatus.place). Counted here, once per goal, so Home
offers the places this person goes to whoever asked for the trip.

The first status of a robot after the web starts is where counting begins, not a trip: a web
restarted by the launcher while the robot drives to the fridge sees that goal again, and it
was counted before the restart."""

from __future__ import annotations

import threading
from typing import Callable

from asibot import keys
from asibot.messages import NavStatus
from asibot.web.userdata.favourites import place_key


class TripCounter:
    """Calls `used(place_key)` once for each new goal to a named place of each robot."""

    def __init__(self, used: Callable[[str], None]) -> None:
        self.used = used
        self._lock = threading.Lock()
        self._goal: dict[str, int] = {}      # robot -> the goal last seen, counted or not

    def on_status(self, key: str, status: NavStatus) -> None:
        """A NavStatus as the bus delivers it, with its key (keys.nav_status of a robot)."""
        robot = keys.robot_of(key)
        if robot is None:
            return
        with self._lock:
            # != and not >: a restarted nav numbers its goals from 1 again.
            new = robot in self._goal and status.goal_id != self._goal[robot]
            self._goal[robot] = status.goal_id
        if new and status.place and status.state == "active":
            self.used(place_key(robot, status.place))
