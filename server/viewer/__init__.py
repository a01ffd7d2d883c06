"""The participant's live 3-D view of the robot, served by viser (see service.py)."""

from server.viewer.service import (
    ClientView,
    ParticipantViewer,
    ViewerConfig,
    viewer_from_settings,
)

__all__ = ["ClientView", "ParticipantViewer", "ViewerConfig", "viewer_from_settings"]
