"""Installed in every process of a traced walk (tests/test_walks.py puts this folder first
on PYTHONPATH and names a folder in IDEEPRL_WALK_TRACE): `tracer.install()`."""

import os

if os.environ.get("IDEEPRL_WALK_TRACE"):
    import sys

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import walk_tracer

    walk_tracer.install(os.environ["IDEEPRL_WALK_TRACE"])
