"""Only a `LiveSession` writes its own state: the routes, the manager and every other part
of the web process read it and call its methods. Read from the source (no server runs), so
a write added anywhere in `server/` fails here at once."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OWNER = "LiveSession"
OWNER_FILE = ROOT / "server" / "live" / "session.py"
MUTATORS = frozenset(
    [
        "append",
        "appendleft",
        "extend",
        "clear",
        "pop",
        "popleft",
        "popitem",
        "update",
        "add",
        "remove",
        "discard",
        "insert",
        "setdefault",
        "sort",
        "reverse",
    ]
)


def owned_attributes() -> frozenset[str]:
    """The attributes a `LiveSession` gives itself (`self.x = ...` in its methods)."""
    tree = ast.parse(OWNER_FILE.read_text())
    owner = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == OWNER)
    names = set()
    for node in ast.walk(owner):
        for target in _targets(node):
            if isinstance(target, ast.Attribute) and _is_self(target.value):
                names.add(target.attr)
    assert {"request", "moving", "given", "history", "status"} <= names
    return frozenset(names)


def _targets(node: ast.AST) -> list[ast.expr]:
    if isinstance(node, ast.Assign):
        found = list(node.targets)
    elif isinstance(node, ast.AugAssign | ast.AnnAssign):
        found = [node.target]
    elif isinstance(node, ast.Delete):
        found = list(node.targets)
    else:
        return []
    flat: list[ast.expr] = []
    while found:
        target = found.pop()
        if isinstance(target, ast.Tuple | ast.List):
            found.extend(target.elts)
        elif isinstance(target, ast.Starred):
            found.append(target.value)
        else:
            flat.append(target)
    return flat


def _is_self(node: ast.expr) -> bool:
    return isinstance(node, ast.Name) and node.id in ("self", "cls")


def _written(node: ast.AST, names: frozenset[str]) -> list[ast.Attribute]:
    """The attributes of `names` this statement or call writes, as `x.name = ...`,
    `x.name[i] = ...`, `x.name.append(...)` or `setattr(x, "name", ...)`."""
    written: list[ast.Attribute] = []
    for target in _targets(node):
        while isinstance(target, ast.Subscript):
            target = target.value
        if isinstance(target, ast.Attribute) and target.attr in names:
            written.append(target)
    if isinstance(node, ast.Call):
        func = node.func
        if (
            isinstance(func, ast.Attribute)
            and func.attr in MUTATORS
            and isinstance(func.value, ast.Attribute)
            and func.value.attr in names
        ):
            written.append(func.value)
        if (
            isinstance(func, ast.Name)
            and func.id == "setattr"
            and len(node.args) >= 2
            and isinstance(node.args[1], ast.Constant)
            and node.args[1].value in names
        ):
            written.append(ast.Attribute(value=node.args[0], attr=str(node.args[1].value)))
    return written


def writes_outside_owner(source: str, names: frozenset[str]) -> list[str]:
    """Where `source` writes a live session's attribute outside `LiveSession`: its own
    `self.x` in another class is that class's attribute, and allowed."""
    found: list[str] = []

    def visit(node: ast.AST, owner: str | None) -> None:
        if isinstance(node, ast.ClassDef):
            owner = node.name
        if owner != OWNER:
            for attribute in _written(node, names):
                if owner is not None and _is_self(attribute.value):
                    continue
                found.append(f"line {node.lineno}: {ast.unparse(attribute)}")
        for child in ast.iter_child_nodes(node):
            visit(child, owner)

    visit(ast.parse(source), None)
    return found


def test_no_route_or_other_class_writes_a_live_session() -> None:
    names = owned_attributes()
    found = {
        str(path.relative_to(ROOT)): writes
        for path in sorted((ROOT / "server").rglob("*.py"))
        if (writes := writes_outside_owner(path.read_text(), names))
    }
    assert not found, (
        "a live session's state is written only by its own methods (server/live/session.py); "
        f"add a method there and call it instead: {found}"
    )


def test_the_check_finds_each_kind_of_write() -> None:
    names = owned_attributes()
    source = """
def route(manager, live, handle):
    live.moving = True
    handle.live.request, other = None, 1
    live.given[3] = 1
    live.history.append(entry)
    live.last_reward += 1.0
    setattr(live, "ready", True)
    live.take_advice(3, 1, 90)

class Other:
    def __init__(self, live):
        self.status = "mine"
        self.live = live
        self.live.status = "running"
"""
    found = writes_outside_owner(source, names)
    assert [entry.split(":")[0] for entry in found] == [
        "line 3",
        "line 4",
        "line 5",
        "line 6",
        "line 7",
        "line 8",
        "line 15",
    ], found
