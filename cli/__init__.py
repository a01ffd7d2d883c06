"""`ideeprl`, the command line (`cli.main`), and its sub-commands."""
