"""Running sessions beside the web process: workers, the channel to them, the event hub."""
