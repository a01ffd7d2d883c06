"""One router per resource; `main.create_app` includes them all."""

from server.routes import exports, health, participant, sessions, studies

ROUTERS = [health.router, studies.router, sessions.router, exports.router, participant.router]
