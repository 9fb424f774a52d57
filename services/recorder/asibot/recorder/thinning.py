"""Camera images recorded at a lower rate than they are published.

The sim's cameras publish 10 frames a second; recorded whole, 16 minutes made 200 MB. A
recording is for seeing what happened, for which a few frames a second do, so the recorder
keeps at most `hz` images a second per camera stream (depth and rgb). Calibrations (`info`)
and everything else are kept whole: they are small and a replay needs them.
"""

from __future__ import annotations

import fnmatch

from asibot import keys

IMAGE_PATTERNS = (keys.every_robot(keys.camera_depth, "*"), keys.every_robot(keys.camera_rgb, "*"))

DEFAULT_CAMERA_HZ = 2.0


def is_camera_image(key: str) -> bool:
    return any(fnmatch.fnmatchcase(key, p) for p in IMAGE_PATTERNS)


class CameraThinner:
    """Decides, per camera image key, which frames to keep; `skipped` counts the others.

    Frames are kept on a fixed schedule (every 1/hz s from the first), not "at least 1/hz
    after the last kept", so a 10 Hz stream with jitter thinned to 2 Hz gives 2 Hz, not 1.7.
    """

    def __init__(self, hz: float = DEFAULT_CAMERA_HZ) -> None:
        if not hz >= 0:
            raise ValueError(f"the camera recording rate must be 0 (every frame) or more frames a second, not {hz}")
        self.period_ns = int(1e9 / hz) if hz > 0 else 0
        self.skipped = 0
        self._due: dict[str, int] = {}

    def thins(self, key: str) -> bool:
        """Whether frames of this key are thinned (`keep_frame`): a camera image, with a rate set;
        every sample of any other key is kept (the recorder asks once a key)."""
        return bool(self.period_ns) and is_camera_image(key)

    def keep_frame(self, key: str, t_ns: int) -> bool:
        """Whether to record this frame of a key that `thins`."""
        due = self._due.get(key)
        if due is not None and t_ns < due:
            self.skipped += 1
            return False
        # After a pause (or the first frame) the schedule restarts from this frame.
        self._due[key] = due + self.period_ns if due is not None and t_ns - due < self.period_ns \
            else t_ns + self.period_ns
        return True
