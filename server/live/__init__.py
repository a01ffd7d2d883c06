"""The web process's side of running sessions: the manager that starts workers and holds
their channels, the hub that fans their events out to viewers, and the participant's
advising (runs/worker/ is the worker process's side)."""
