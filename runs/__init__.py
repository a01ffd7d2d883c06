"""What runs sessions: the session worker process and the batch runner."""
