"""`ideeprl train`: to be written (issue 3)."""
