"""The worker process: one session's run (environment, learner, advisors, its records
and checkpoints), and `messages`, the channel it and the web process (server/live/) speak."""
