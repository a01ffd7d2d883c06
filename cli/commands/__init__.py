"""Sub-commands of `ideeprl`: each module here defines `register(subparsers)`."""
