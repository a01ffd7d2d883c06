"""The reach task's moves and the camera people see it from: what the web process reads of
the task, without PyBullet."""

from tasks import ViewCamera

MOVES = ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))
"""Action i's move in lattice points: forward (+x, away from the robot's base), back,
left (+y), right, up, down."""
MOVE_WORDS = ("forward", "back", "left", "right", "up", "down")
KEYS = ("ArrowUp", "ArrowDown", "ArrowLeft", "ArrowRight", "u", "d")
"""The advice page's keys, in action order."""
CAMERA = ViewCamera(eye=(-0.55, -1.0, 1.05), target=(0.45, 0.0, 0.3), fov=50.0)
"""What people see: above and behind the robot's right shoulder, its left the screen's
left, so "left" and "forward" read as the page's buttons say."""
