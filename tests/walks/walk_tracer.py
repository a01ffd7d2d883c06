"""A profiler hook that writes, per process, every entry into a function of the project's
source files, and where the walks' values are in each (tests/test_walks.py says exactly what
is counted and how the lines are read).

One line per event, tab-separated: monotonic ns; the event (`call CALLER`, CALLER as
`_caller` says; `return -`; `answer N`: `WorkerLink._recv` returned the `AdviceAnswer` for
advice N); the thread's name; the asyncio task (on the main thread: the task's id; on
another thread: the id of the task whose context its thread-pool call copied, else 0: a
request and the thread-pool calls it makes share one); the file, relative to the root; the
function; then the frame's number in this process (`seq`) and its caller's (`parent`: the
innermost project frame below it on the stack, 0: none; `N~`: it called through third-party
code; `N^`: on a thread-pool thread, the coroutine that awaits it through the pool), and the
value fields:

- `call`: the values among its arguments (`FORMS`), and which of those arguments the
  function's code reads (`READS`);
- `return` (written only where there is a value to report): the values it returns, the
  values in its arguments and locals, the values its arguments' objects hold after it that
  they did not hold before (`FORMS` each: what it stored), and which of its arguments and
  locals holding a value its code reads (`READS`);
- `leave FUNCTION` (SEQ: the project frame that calls the third-party FUNCTION itself with a
  value among its arguments; the file and function are that frame's): the values (`FORMS`);
- `answer`: the project frames on the stack (`FILE:FUNCTION:SEQ;...`, outermost first).

`FORMS` is `;`-joined `kind,type,id,where`: `where` names the argument or local (`spec`),
or the part of one that holds the value (`session.run`, `values[run]`, `self.spec`); `id` is
the object's identity (`int=N` for an int: small ints have none of their own).
Not counted: module and class bodies and all they call (import time), a suspended generator
or coroutine resuming (it was entered when it began), frames outside the project's
packages (third-party code is transparent), tests.
"""

from __future__ import annotations

import asyncio
import contextvars
import dataclasses
import dis
import os
import sys
import threading
import time
from types import CodeType
from typing import Any

PACKAGES = ("sim", "learner", "study", "runs", "server", "analysis", "cli")
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CO_NEWLOCALS = 0x2  # a function's code (not a module's or a class body's)
CO_VARARGS, CO_VARKEYWORDS = 0x4, 0x8
CO_GENERATOR_LIKE = 0x20 | 0x80 | 0x200  # generator, coroutine, async generator
MAKERS = {"__init__", "__new__", "__call__"}
READERS = {"getattr", "hasattr", "vars", "len", "dict", "list", "tuple", "set", "sorted", "iter"}
"""Builtins that read what they are given (its attributes, items or length)."""
PARTS = 64
"""At most this many parts of a container are looked at for a value."""

_walk: contextvars.ContextVar[int] = contextvars.ContextVar("walk")
_pool: contextvars.ContextVar[Any] = contextvars.ContextVar("pool")
"""The project frame that is calling a thread pool (`POOLS`) itself, while it does."""
POOLS = {"run_in_threadpool", "run_sync", "to_thread"}
"""The coroutines that run a function in a thread pool (starlette, anyio, asyncio)."""
_files: dict[str, str | None] = {}


def project_file(filename: str) -> str | None:
    """`server/routes/sessions.py` for a project source file, else None (cached)."""
    known = _files.get(filename, "")
    if known != "":
        return known
    found = None
    path = os.path.abspath(filename)
    if path.startswith(ROOT + os.sep) and path.endswith(".py"):
        relative = os.path.relpath(path, ROOT)
        if relative.split(os.sep)[0] in PACKAGES:
            found = relative.replace(os.sep, "/")
    _files[filename] = found
    return found


# The values followed ------------------------------------------------------------------

_action: list[int] = []
"""The action of the last advice seen in this process (an int is the advice's action only
once a form carrying it has been seen)."""


def _fields(t: type) -> set[str] | None:
    """The field names of a record-like class (pydantic model, dataclass, NamedTuple, ORM
    row), None for anything else."""
    model_fields = getattr(t, "model_fields", None)
    if isinstance(model_fields, dict):
        return set(model_fields)
    if isinstance(getattr(t, "__dataclass_fields__", None), dict):
        return set(t.__dataclass_fields__)  # type: ignore[attr-defined]
    if issubclass(t, tuple) and isinstance(getattr(t, "_fields", None), tuple):
        return set(t._fields)  # type: ignore[attr-defined]
    table = getattr(t, "__table__", None)
    if table is not None and hasattr(table, "columns"):
        return {c.key for c in table.columns}
    return None


_kinds: dict[type, str | None] = {}


def _kind_of_class(t: type) -> str | None:
    """What a class's instances are, from the class alone (cached): `run`, `batch`,
    `action`, None; `dict`, `Namespace`: ask the instance."""
    if t in _kinds:
        return _kinds[t]
    names = {c.__name__ for c in t.__mro__}
    kind = None
    if t is dict or t.__name__ == "Namespace":
        kind = t.__name__
    elif "RunSpec" in names:
        kind = "run"
    elif "BatchSpec" in names:
        kind = "batch"
    else:
        try:
            fields = _fields(t)
        except Exception:
            fields = None
        if fields and "method" in fields and "config" in fields:
            kind = "run"
        elif fields and "action" in fields and "advice_index" in fields:
            kind = "action"
    _kinds[t] = kind
    return kind


def form(obj: Any) -> str | None:
    """The walk value `obj` is a form of (`run`, `batch`, `action`), or None.

    - run: a `RunSpec`; a record with the fields `method` and `config` (the run's document:
      the request's dict, its pydantic model, the stored JSON); JSON text of one.
    - batch: a `BatchSpec`; the parsed command line of `ideeprl batch` (a Namespace with
      `methods`).
    - action: a record with the fields `action` and `advice_index` (the request's body, the
      advice row and messages); an int equal to the last such record's action."""
    t = type(obj)
    if t is int:
        return "action" if _action and obj == _action[-1] else None
    if t in (bool, float, bytes, type(None)):
        return None
    if t is str:
        if obj[:1] == "{" and '"method"' in obj and '"config"' in obj:
            return "run"
        return None
    kind = _kind_of_class(t)
    if kind == "dict":
        if "method" in obj and "config" in obj:
            return "run"
        if "action" in obj and "advice_index" in obj:
            kind = "action"
        else:
            return None
    elif kind == "Namespace":
        return "batch" if "methods" in getattr(obj, "__dict__", {}) else None
    if kind == "action":
        action = obj["action"] if t is dict else getattr(obj, "action", None)
        if type(action) is int:
            _action.append(action)
            del _action[:-1]
    return kind


def _parts(obj: Any) -> list[tuple[str, Any]]:
    """The parts of a container, one level down: (`.attr` or `[key]`, part)."""
    t = type(obj)
    if t in (int, float, bool, str, bytes, type(None)):
        return []
    try:
        if t is dict:
            return [(f"[{k}]", v) for k, v in list(obj.items())[:PARTS]]
        if t in (list, tuple, set, frozenset):
            return [(f"[{i}]", v) for i, v in enumerate(list(obj)[:PARTS])]
        found: list[tuple[str, Any]] = []
        d = getattr(obj, "__dict__", None)
        if isinstance(d, dict):
            found += [(f".{k}", v) for k, v in list(d.items())[:PARTS] if not k.startswith("_sa_")]
        if dataclasses.is_dataclass(obj) and not isinstance(d, dict):
            found += [(f".{f.name}", getattr(obj, f.name, None)) for f in dataclasses.fields(obj)]
        elif isinstance(obj, tuple):
            names = getattr(t, "_fields", ())
            found += [(f".{n}", v) for n, v in zip(names, obj, strict=False)]
        return found
    except Exception:
        return []


def _ident(obj: Any) -> str:
    return f"int={obj}" if type(obj) is int else str(id(obj))


def forms_in(
    named: list[tuple[str, Any]], reached: frozenset[str] | None = frozenset()
) -> list[str]:
    """The values among `named` objects: each one that is a form, and each form one level
    inside one that is not (inside `self`, only the attributes in `reached`; None: all)."""
    found = []
    for name, obj in named:
        kind = form(obj)
        if kind is not None:
            found.append(f"{kind},{type(obj).__name__},{_ident(obj)},{name}")
            continue
        for where, part in _parts(obj):
            if type(part) is int:
                continue  # an int is the action only as a value of its own
            if name == "self" and reached is not None and where[1:] not in reached:
                continue
            kind = form(part)
            if kind is not None:
                found.append(f"{kind},{type(part).__name__},{_ident(part)},{name}{where}")
    return found


def _reached(found: str, reached: frozenset[str]) -> bool:
    """Whether a form found in the arguments is one the function is given: not one in an
    attribute of `self` that its code never loads."""
    where = found.split(",", 3)[3]
    return not where.startswith("self.") or where[5:] in reached


_Uses = tuple[dict[str, set[str]], set[tuple[str, str]], frozenset[str], bool]
_uses: dict[CodeType, _Uses] = {}

_LOADS = {"LOAD_FAST", "LOAD_DEREF", "LOAD_FAST_CHECK", "LOAD_CLOSURE"}
_ACCESS = {"LOAD_ATTR", "LOAD_METHOD", "BINARY_SUBSCR", "CONTAINS_OP", "DELETE_SUBSCR"}


def uses(code: CodeType) -> _Uses:
    """What a function's code (nested functions' code included) takes of each name it loads:
    the attributes and methods (`[]`: an item, `in`: asked whether it holds something,
    `getattr()`: given first to a builtin that reads it, `READERS`); the
    (name, attribute) pairs whose attribute is then read further; the attributes of `self`
    it loads; whether it takes an attribute or item named `action` anywhere (cached)."""
    known = _uses.get(code)
    if known is not None:
        return known
    taken: dict[str, set[str]] = {}
    deep: set[tuple[str, str]] = set()
    reached: set[str] = set()
    action = False
    codes = [code]
    while codes:
        c = codes.pop()
        codes += [k for k in c.co_consts if isinstance(k, CodeType)]
        ins = [i for i in dis.get_instructions(c) if i.opname not in ("CACHE", "EXTENDED_ARG")]
        for n, i in enumerate(ins):
            nxt = ins[n + 1].opname if n + 1 < len(ins) else ""
            if i.argval == "action" and (
                i.opname in ("LOAD_ATTR", "LOAD_METHOD")
                or (i.opname == "LOAD_CONST" and nxt == "BINARY_SUBSCR")
            ):
                action = True
            if i.opname not in _LOADS or not isinstance(i.argval, str):
                continue
            name = i.argval
            mine = taken.setdefault(name, set())
            if n and ins[n - 1].opname == "LOAD_GLOBAL" and ins[n - 1].argval in READERS:
                mine.add(ins[n - 1].argval + "()")
            after = ins[n + 1 : n + 4]
            if not after:
                continue
            first = after[0]
            if first.opname in ("LOAD_ATTR", "LOAD_METHOD"):
                mine.add(first.argval)
                if name == "self":
                    reached.add(first.argval)
                rest = [a.opname for a in after[1:]]
                if rest and (rest[0] in _ACCESS or rest[:2] in (["LOAD_CONST", "BINARY_SUBSCR"],)):
                    deep.add((name, first.argval))
            elif first.opname in ("BINARY_SUBSCR", "DELETE_SUBSCR"):
                mine.add("[]")
            elif first.opname == "CONTAINS_OP":
                mine.add("in")
            elif (
                first.opname in ("LOAD_CONST", "LOAD_FAST")
                and len(after) > 1
                and after[1].opname in ("BINARY_SUBSCR", "DELETE_SUBSCR")
            ):
                mine.add("[]")
    known = (taken, deep, frozenset(reached), action)
    _uses[code] = known
    return known


REACH = {"[]", "get", "pop"}
"""What takes a value out of a dict or list that holds it (not a read of the container)."""


def reads(code: CodeType, forms: list[str]) -> list[str]:
    """Which of `forms`' names the code reads: a form it holds itself, when an attribute,
    method or item of it is taken or `in` asks it; a form inside an argument (`session.run`,
    `values[run]`), when it is read further than that or the argument's other attributes
    are read (inside `self`: only when it is read further); `@action` where the code takes
    an attribute or item named `action`."""
    taken, deep, _, action = uses(code)
    found = ["@action"] if action else []
    for f in forms:
        where = f.split(",", 3)[3]
        for sep in (".", "["):
            if sep in where:
                name, _, rest = where.partition(sep)
                attr = rest.rstrip("]")
                other = taken.get(name, set()) - {attr} - REACH
                if (name, attr) in deep or (name != "self" and other):
                    found.append(where)
                break
        else:
            if taken.get(where):
                found.append(where)
    return found


def arguments(frame: Any) -> list[tuple[str, Any]]:
    """A function's arguments, and the variables a closure was given (its free ones)."""
    code = frame.f_code
    count = code.co_argcount + code.co_kwonlyargcount
    count += bool(code.co_flags & CO_VARARGS) + bool(code.co_flags & CO_VARKEYWORDS)
    local = frame.f_locals
    names = [*code.co_varnames[:count], *code.co_freevars]
    return [(n, local[n]) for n in names if n in local]


# The trace ----------------------------------------------------------------------------


class _Out:
    """This process's trace file, line-buffered (a worker may be killed, or leave by
    os._exit); a forked child, such as a forkserver's worker, opens its own."""

    def __init__(self, folder: str) -> None:
        self.folder = folder
        self.open()
        os.register_at_fork(after_in_child=self.open)

    def open(self) -> None:
        self.lock = threading.Lock()
        name = os.path.join(self.folder, f"trace-{os.getpid()}.tsv")
        self.file = open(name, "a", buffering=1)  # noqa: SIM115

    def write(self, line: str) -> None:
        with self.lock:
            self.file.write(line)


def _caller(frame: Any, name: str) -> str:
    """`FILE` of the innermost project frame that called this one (`-`: none); `FILE!`
    when the call climbs back: the callee's file is further up the stack, under another
    file's frame (A -> B -> A)."""
    caller = None
    back = frame.f_back
    while back is not None:
        found = project_file(back.f_code.co_filename)
        if found is not None:
            if caller is None:
                caller = found
                if found == name:
                    return caller
            elif found == name:
                return caller + "!"
        back = back.f_back
    return caller or "-"


class _Frame:
    """A project frame's number and what is known of its values."""

    __slots__ = ("code", "entered", "holds", "inside", "parent", "seq")

    def __init__(self, code: CodeType, seq: int, parent: int) -> None:
        self.code = code
        self.seq = seq
        self.parent = parent
        self.holds = False
        """It was given a value or got one back from a callee."""
        self.entered: list[tuple[str, Any]] = []
        """Its arguments (for what they hold after it)."""
        self.inside: set[str] = set()
        """The values its arguments held when it began (`id,where`)."""


def install(folder: str) -> None:
    os.makedirs(folder, exist_ok=True)
    out = _Out(folder)

    importing = threading.local()
    main = threading.main_thread()
    frames: dict[int, _Frame] = {}
    counter = iter(range(1, 1 << 62))

    def known(frame: Any) -> _Frame | None:
        found = frames.get(id(frame))
        return found if found is not None and found.code is frame.f_code else None

    def below(frame: Any) -> _Frame | None:
        back = frame.f_back
        while back is not None:
            if project_file(back.f_code.co_filename) is not None:
                return known(back)
            back = back.f_back
        return None

    def submitter() -> _Frame | None:
        """On a thread-pool thread, the project coroutine that awaits this call through the
        pool itself (`await run_in_threadpool(f, ...)`): the pool's call copied it with the
        context (`_pool`)."""
        if threading.current_thread() is main:
            return None
        return _pool.get(None)

    def direct(frame: Any) -> bool:
        """Called by a project frame itself, not through third-party code."""
        back = frame.f_back
        return back is not None and project_file(back.f_code.co_filename) is not None

    def emit(kind: str, code: CodeType, name: str, fields: str) -> None:
        walk = _walk.get(0)
        if threading.current_thread() is main:  # the asyncio task is the request
            loop = asyncio._get_running_loop()
            task = asyncio.current_task(loop) if loop is not None else None
            if task is not None and walk != id(task):
                walk = id(task)
                _walk.set(walk)  # a thread-pool call the task makes copies its context
        line = (
            f"{time.monotonic_ns()}\t{kind}\t{threading.current_thread().name}\t{walk}\t"
            f"{name}\t{code.co_qualname}\t{fields}\n"
        )
        out.write(line)

    def on_call(frame: Any, code: CodeType, name: str) -> None:
        resumed = code.co_flags & CO_GENERATOR_LIKE and code.co_code[frame.f_lasti + 1]
        if resumed:
            return  # resumed (at a RESUME whose argument is not 0), not entered
        parent = below(frame)
        pooled = None if parent is not None else submitter()
        parent = parent or pooled
        me = _Frame(code, next(counter), parent.seq if parent else 0)
        frames[id(frame)] = me
        named = arguments(frame)
        me.entered = named
        held = forms_in(named, None)
        me.inside = {f.split(",", 2)[2] for f in held}
        reached = uses(code)[2]
        found = [f for f in held if _reached(f, reached)]
        if found:
            me.holds = True
            if parent is not None:
                parent.holds = True
        read = reads(code, found)
        through = "^" if pooled is not None else "" if direct(frame) else "~"
        fields = f"{me.seq}\t{me.parent}{through}\t{';'.join(found)}\t{','.join(read)}"
        emit("call " + _caller(frame, name), code, name, fields)

    def on_leave(frame: Any, code: CodeType) -> None:
        """A third-party function a project frame that holds a value calls itself: the
        values among its arguments (or in a tuple, list or dict given as one) leave the
        project's code there (a pipe, the database, a serializer, a thread pool); a special
        method other than a constructor or `__call__` is not one (an attribute's
        descriptor, `isinstance`, a comparison: the caller looks at the value)."""
        back = frame.f_back
        if back is None:
            return
        caller = known(back)
        dunder = code.co_name.startswith("__") and code.co_name.endswith("__")
        if caller is None or not caller.holds or (dunder and code.co_name not in MAKERS):
            return
        found = [f for f in forms_in(arguments(frame)) if "." not in f.split(",", 3)[3]]
        if not found:
            return
        name = project_file(back.f_code.co_filename) or "-"
        fields = f"{caller.seq}\t0\t{';'.join(found)}\t"
        emit(f"leave {code.co_qualname}", back.f_code, name, fields)

    def on_return(frame: Any, code: CodeType, name: str, value: Any) -> None:
        me = known(frame)
        if me is None:
            return
        if not code.co_flags & CO_GENERATOR_LIKE:
            del frames[id(frame)]
        returned = forms_in([("return", value)])
        if returned:
            parent = below(frame)
            if parent is not None:
                parent.holds = True
        if not me.holds and not returned:
            return
        local = [(n, v) for n, v in frame.f_locals.items() if n not in dict(me.entered)]
        held = forms_in([*me.entered, *local], uses(code)[2])
        kept = [f for f in forms_in(me.entered, None) if f.split(",", 2)[2] not in me.inside]
        read = reads(code, held)
        fields = (
            f"{me.seq}\t{me.parent}\t{';'.join(returned)}\t{';'.join(held)}\t"
            f"{';'.join(kept)}\t{','.join(read)}"
        )
        emit("return -", code, name, fields)

    def hook(frame: Any, event: str, arg: Any) -> None:
        code = frame.f_code
        if code.co_name == "<module>" and frame.f_globals.get("__name__") != "__main__":
            # import time: nothing it runs is counted (a program's own __main__ is not an
            # import: `python -m cli`, `python -c ...spawn_main(...)`)
            if event == "call":
                importing.depth = getattr(importing, "depth", 0) + 1
            elif event == "return":  # (the hook starts inside sitecustomize's import)
                importing.depth = max(0, getattr(importing, "depth", 0) - 1)
            return
        if getattr(importing, "depth", 0):
            return
        if event == "call":
            if not code.co_flags & CO_NEWLOCALS:
                return  # a class body
            name = project_file(code.co_filename)
            if name is None:
                submitting = known(frame.f_back) if code.co_name in POOLS else None
                if submitting is not None:
                    _pool.set(submitting)  # the pool copies the context to the thread
                on_leave(frame, code)
                return
            on_call(frame, code, name)
        elif event == "return":
            name = project_file(code.co_filename)
            if name is None:
                if code.co_name in POOLS:
                    _pool.set(None)
                return
            if type(arg).__name__ == "AdviceAnswer" and code.co_name == "_recv":
                stack = []
                back = frame
                while back is not None:
                    there = project_file(back.f_code.co_filename)
                    mine = known(back)
                    if there is not None and mine is not None:
                        stack.append(f"{there}:{back.f_code.co_qualname}:{mine.seq}")
                    back = back.f_back
                fields = f"0\t0\t{';'.join(reversed(stack))}\t"
                emit(f"answer {arg.advice_index}", code, name, fields)
            on_return(frame, code, name, arg)

    threading.setprofile(hook)
    sys.setprofile(hook)
