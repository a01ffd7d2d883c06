"""`python -m learner train ...`, the same command as `ideeprl train`."""

from learner.cli import main

raise SystemExit(main())
