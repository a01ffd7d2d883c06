"""Field docstrings of a dataclass, read from its source.

They document configs and records in one place: the code. Help texts, the server's API
docs and the export's column dictionary are built from them.
"""

from __future__ import annotations

import ast
import inspect
import itertools


def field_docstrings(cls: type) -> dict[str, str]:
    """Field name -> the string literal right under the field in the class body."""
    tree = ast.parse(inspect.getsource(cls))
    body = tree.body[0].body  # type: ignore[attr-defined]
    docs: dict[str, str] = {}
    for node, after in itertools.pairwise(body):
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and isinstance(after, ast.Expr)
            and isinstance(after.value, ast.Constant)
            and isinstance(after.value.value, str)
        ):
            docs[node.target.id] = " ".join(after.value.value.split())
    return docs
