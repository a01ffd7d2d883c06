"""The web process: the FastAPI app, its routes, the live sessions and the viewer relay
(`server.main:app`); the pages it serves are in web/."""
