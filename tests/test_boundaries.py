"""Where the request and response models live, and what crosses between the packages.

Every pydantic model is in `study/schemas/` (a route imports its bodies, never defines
them), and a function that one top-level package calls in another takes and returns typed
values, not `dict[str, Any]`. Both read the packages' source (no import: milliseconds)."""

from __future__ import annotations

import ast
import re
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path

ROOT = Path(__file__).absolute().parents[1]
PACKAGES = ("sim", "tasks", "learner", "study", "runs", "server", "analysis", "cli")
SCHEMAS = "study.schemas."
PYDANTIC_BASES = {"pydantic.BaseModel", "pydantic.RootModel", "pydantic_settings.BaseSettings"}

MODELS_ELSEWHERE = {
    "study.settings.Settings": "pydantic-settings reads the environment into a BaseSettings "
    "(a BaseModel): the configuration, not a body",
}
"""pydantic models allowed outside `study/schemas/`, with why."""


def _module_path(name: str) -> Path | None:
    base = ROOT / name.replace(".", "/")
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


@cache
def _trees() -> dict[str, ast.Module]:
    """Every module of the packages, by dotted name (alembic's scripts left out)."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            if "migrations" in parts:
                continue
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            found[name] = ast.parse(path.read_text(), str(path))
    return found


def _base_name(node: ast.expr) -> str:
    while isinstance(node, ast.Subscript):  # RootModel[list[int]]
        node = node.value
    return node.attr if isinstance(node, ast.Attribute) else getattr(node, "id", "")


def _qualified(module: str, tree: ast.Module, base: ast.expr) -> str:
    """A base class's dotted name, through the module's imports (`BaseModel` after
    `from pydantic import BaseModel`: `pydantic.BaseModel`; a class of the module: its own)."""
    while isinstance(base, ast.Subscript):  # RootModel[list[int]]
        base = base.value
    head, _, rest = ast.unparse(base).partition(".")
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for alias in node.names:
                if (alias.asname or alias.name) == head:
                    head = f"{node.module}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname == head:
                    head = alias.name
        elif isinstance(node, ast.ClassDef) and node.name == head:
            head = f"{module}.{head}"
    return f"{head}.{rest}" if rest else head


def _with_subclasses(trees: dict[str, ast.Module], roots: set[str]) -> set[str]:
    """`roots` and `module.Class` of every class whose bases lead to one of them."""
    classes = {
        f"{module}.{node.name}": {_qualified(module, tree, b) for b in node.bases}
        for module, tree in trees.items()
        for node in tree.body
        if isinstance(node, ast.ClassDef)
    }
    found = set(roots)
    while more := {name for name, bases in classes.items() if bases & found} - found:
        found |= more
    return found


def defined_models(trees: dict[str, ast.Module]) -> set[str]:
    """`module.Class` of every class whose bases lead to a pydantic model."""
    return _with_subclasses(trees, PYDANTIC_BASES) - PYDANTIC_BASES


def test_every_pydantic_model_is_in_the_schemas_package() -> None:
    models = defined_models(_trees())
    assert "study.schemas.reports.ReportPublic" in models  # the walk finds models
    assert "study.schemas.sessions.SessionCreated" in models  # and their subclasses
    outside = {n for n in models if not n.startswith(SCHEMAS)} - set(MODELS_ELSEWHERE)
    assert not outside, f"move these to study/schemas/ (one module per topic): {sorted(outside)}"
    stale = set(MODELS_ELSEWHERE) - models
    assert not stale, f"gone: drop them from MODELS_ELSEWHERE: {sorted(stale)}"


def test_the_model_check_sees_a_model_in_a_route() -> None:
    route = ast.parse(
        "from pydantic import BaseModel\nfrom study.schemas.studies import StudyPublic\n"
        "from server.live.playbacks import Preview\n"  # a namesake of a model, not one
        "class Body(BaseModel): pass\nclass More(StudyPublic): pass\nclass Plain: pass\n"
        "class Namesake(Preview): pass\n"
    )
    schemas = ast.parse(
        "import pydantic as p\nclass StudyPublic(p.BaseModel): pass\n"
        "class Preview(p.BaseModel): pass\n"
    )
    found = defined_models({"server.routes.x": route, "study.schemas.studies": schemas})
    assert found == {
        "server.routes.x.Body",
        "server.routes.x.More",
        "study.schemas.studies.StudyPublic",
        "study.schemas.studies.Preview",
    }


# --- no record as a bare dict across a package boundary ----------------------------------
RECORD = re.compile(
    r"\b(dict|Dict|Mapping|MutableMapping)\[str, *(typing\.)?Any\]|^(dict|Mapping)$"
)
SERIALIZERS = {"to_json", "from_json", "to_dict", "from_dict", "state_dict", "load_state_dict"}
"""Methods whose job is turning their typed class into the JSON it is stored as, and back:
the typed side of the boundary is the class itself."""


@dataclass(frozen=True)
class Signature:
    where: str
    """`module.function` or `module.Class.method` (`.field` for a message's field)."""
    annotations: dict[str, str]


def _dataclass_like(node: ast.ClassDef) -> bool:
    decorators = {_base_name(d.func if isinstance(d, ast.Call) else d) for d in node.decorator_list}
    return "dataclass" in decorators or "NamedTuple" in {_base_name(b) for b in node.bases}


def _annotations(function: ast.FunctionDef | ast.AsyncFunctionDef) -> dict[str, str]:
    args = function.args
    found = {
        a.arg: ast.unparse(a.annotation)
        for a in [*args.posonlyargs, *args.args, *args.kwonlyargs, args.vararg, args.kwarg]
        if a is not None and a.annotation is not None
    }
    if function.returns is not None:
        found["return"] = ast.unparse(function.returns)
    return found


def _signatures(module: str, node: ast.stmt) -> Iterator[Signature]:
    if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
        yield Signature(f"{module}.{node.name}", _annotations(node))
    elif isinstance(node, ast.ClassDef):
        fields = {
            s.target.id: ast.unparse(s.annotation)
            for s in node.body
            if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)
        }
        if _dataclass_like(node) and fields:
            yield Signature(f"{module}.{node.name}.__init__", fields)
        for s in node.body:
            if not isinstance(s, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            if not s.name.startswith("_") or s.name == "__init__":
                yield Signature(f"{module}.{node.name}.{s.name}", _annotations(s))


def _definition(module: str, name: str, depth: int = 0) -> tuple[str, ast.stmt] | None:
    """Where `module.name` is defined, following re-exports (`from x import name`)."""
    tree = _trees().get(module)
    if tree is None or depth > 5:
        return None
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            if node.name == name:
                return module, node
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for alias in node.names:
                if (alias.asname or alias.name) == name:
                    return _definition(node.module, alias.name, depth + 1)
    return None


def crossings() -> dict[str, set[str]]:
    """`module.name` of what one top-level package takes from another, with who takes it:
    `from pkg.mod import f` and `mod.f` after `from pkg import mod` (or `import pkg.mod`)."""
    trees = _trees()
    found: dict[str, set[str]] = {}

    def other(importer: str, module: str) -> bool:
        top = module.split(".")[0]
        return top in PACKAGES and top != importer.split(".")[0]

    for importer, tree in trees.items():
        modules: dict[str, str] = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                if other(importer, node.module):
                    for alias in node.names:
                        sub = f"{node.module}.{alias.name}"
                        if sub in trees:
                            modules[alias.asname or alias.name] = sub
                        else:
                            found.setdefault(f"{node.module}.{alias.name}", set()).add(importer)
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if other(importer, alias.name):
                        modules[alias.asname or alias.name.split(".")[0]] = (
                            alias.name if alias.asname else alias.name.split(".")[0]
                        )
        for node in ast.walk(tree):
            if not isinstance(node, ast.Attribute):
                continue
            chain: list[str] = []
            value: ast.expr = node
            while isinstance(value, ast.Attribute):
                chain.insert(0, value.attr)
                value = value.value
            if not (chain and isinstance(value, ast.Name) and value.id in modules):
                continue
            module = modules[value.id]
            while chain and f"{module}.{chain[0]}" in trees:
                module = f"{module}.{chain.pop(0)}"
            if chain:
                found.setdefault(f"{module}.{chain[0]}", set()).add(importer)
    return found


def records_across(allowed: dict[str, str]) -> dict[str, list[str]]:
    """Signatures taken across a package boundary that pass a record as a bare dict."""
    bad: dict[str, list[str]] = {}
    for name in crossings():
        module, _, attr = name.rpartition(".")
        defined = _definition(module, attr)
        if defined is None:
            continue
        for signature in _signatures(*defined):
            if signature.where.rpartition(".")[2] in SERIALIZERS or signature.where in allowed:
                continue
            found = [f"{k}: {a}" for k, a in signature.annotations.items() if RECORD.search(a)]
            if found:
                bad[signature.where] = found
    return bad


def test_no_record_crosses_a_package_boundary_as_a_bare_dict() -> None:
    bad = records_across(RECORDS_ALLOWED)
    assert not bad, (
        "pass a typed value (a dataclass, a NamedTuple; a TypedDict for JSON stored as-is) "
        f"instead of dict[str, Any] across the packages: {bad}"
    )
    stale = set(RECORDS_ALLOWED) - set(records_across({}))
    assert not stale, f"typed now: drop them from RECORDS_ALLOWED: {sorted(stale)}"


GYM_INFO = "Gymnasium's `info` (its API types it dict[str, Any]): the env's state by name"
LEAF_VALUES = (
    "values by a declared dataclass's leaf name (`learner.fields`): that declaration, not a "
    "type here, says what each may be, and checks it"
)
RUN_JSON = "a run's JSON document (`RunSpec.to_json`'s form), stored as-is in `sessions.run`"
RECORDS_ALLOWED: dict[str, str] = {
    "sim.env.SortingEnv.reset": GYM_INFO,
    "sim.env.SortingEnv.step": GYM_INFO,
    "sim.rewards.step_outcome": GYM_INFO + " before and after a step",
    "sim.rules.oracle_action": GYM_INFO,
    "learner.advisors.Advisor.advise": GYM_INFO,
    "learner.advisors.RecordedAdvisor.advise": GYM_INFO,
    "learner.fitted.FittedAdvisor.advise": GYM_INFO,
    "learner.evaluators.RecordedEvaluator.judge": GYM_INFO + " before the judged step",
    "learner.fitted_ratings.FittedEvaluator.judge": GYM_INFO + " before the judged step",
    "learner.strategies.AdviceMoment.__init__": GYM_INFO + " where the advice is asked",
    "runs.worker.messages.AdviceRequest.__init__": GYM_INFO + " shown to the advisor",
    "learner.fields.given_arguments": LEAF_VALUES,
    "learner.fields.nest": LEAF_VALUES,
    "learner.run.RunSpec.values": LEAF_VALUES,
    "learner.run.RunSpec.with_values": LEAF_VALUES,
    "runs.batch.spec.BatchSpec.__init__": LEAF_VALUES + ", per method",
    "study.services.replays.replay_run": LEAF_VALUES,
    "study.schemas.runs.given": "a body's set values as JSON, read by `RunSpec.from_json`",
    "study.schemas.errors.valid_fields": "a JSON Schema document (pydantic's "
    "`model_json_schema()`), walked as JSON to name an object's fields",
    "learner.run.RunSpec.identity": RUN_JSON + ", normalized",
    "learner.run.RunSpec.is_run": RUN_JSON + ", normalized (`identity`)",
    "learner.run.RunSpec.sb3": "keyword arguments of Stable-Baselines3's DQN, passed on as-is",
    "learner.sb3_spec.describe": "Stable-Baselines3's hyperparameters and config, as SB3 names "
    "them",
    "learner.fitted_ratings.FittedEvaluatorModel.summary": "JSON served as-is "
    "(`FittedAdvisorPublic.summary`, a fitted evaluator's)",
    "learner.population.Population.save_checkpoint": "`metadata`: JSON the checkpoint keeps as-is",
    "learner.trainer.Trainer.save_checkpoint": "`metadata`: JSON the checkpoint keeps as-is",
    "learner.records.named_q": "a steps table's row as stored or written (its columns by name), "
    "of which only the Q-value columns are read",
    "analysis.exported.run_of": "a row of an exported CSV table, by column",
    "analysis.settings.where": "rows of an exported table, by column",
    "analysis.settings.settings_table": "`sessions.provenance` entries as read from an export",
}
"""Signatures that may pass `dict[str, Any]` across a package boundary, with why."""


def test_the_record_check_finds_what_crosses_and_what_is_a_bare_dict() -> None:
    taken = crossings()
    assert "server.routes.reports" in taken["study.services.reports.publish_report"]
    assert "cli.commands.replay" in taken["study.services.replays.compare"]  # `replays.compare`
    for bare in ("dict[str, Any]", "list[dict[str, Any]]", "Mapping[str, Any] | None", "dict"):
        assert RECORD.search(bare), bare
    for typed in ("dict[str, int]", "ReportDescription", "Any", "dict[int, list[str]]"):
        assert not RECORD.search(typed), typed


# --- a service takes domain values, never a REST body ------------------------------------
def request_bodies(trees: dict[str, ast.Module]) -> set[str]:
    """The models a route takes as its request body: a parameter of a route (a function
    under `@router.post(...)` and the like) annotated with a pydantic model, which FastAPI
    reads from the body."""
    models = defined_models(trees)
    found = set()
    for module, tree in trees.items():
        if not module.startswith("server.routes."):
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and _route(node):
                for arg in [*node.args.args, *node.args.kwonlyargs]:
                    if arg.annotation is not None:
                        name = _qualified(module, tree, arg.annotation)
                        if name in models:
                            found.add(name)
    return found


def _route(node: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    verbs = {"get", "post", "put", "patch", "delete"}
    return any(
        isinstance(d, ast.Call) and isinstance(d.func, ast.Attribute) and d.func.attr in verbs
        for d in node.decorator_list
    )


def bodies_taken(trees: dict[str, ast.Module], bodies: set[str], package: str) -> list[str]:
    """`module.function(parameter: Body)` for every function of `package` that takes one."""
    found = []
    for module, tree in trees.items():
        if not module.startswith(package):
            continue
        for node in ast.walk(tree):
            if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            for arg in [*node.args.posonlyargs, *node.args.args, *node.args.kwonlyargs]:
                names = ast.walk(arg.annotation) if arg.annotation is not None else ()
                for part in names:
                    named = isinstance(part, ast.Name | ast.Attribute)
                    if named and _qualified(module, tree, part) in bodies:
                        found.append(f"{module}.{node.name}({ast.unparse(arg)})")
    return sorted(set(found))


def test_no_service_takes_a_rest_body() -> None:
    """Issue 18: the core's services are plain functions over domain values; the routes,
    the dashboard and the command line each read their own body and call the same ones."""
    trees = _trees()
    bodies = request_bodies(trees)
    assert {"study.schemas.studies.StudyCreate", "study.schemas.participant.AdviceCreate"} <= bodies
    taken = bodies_taken(trees, bodies, "study.services.")
    assert not taken, f"take the body's values (keywords, a domain value), not the body: {taken}"


def test_the_body_check_sees_a_service_taking_a_body() -> None:
    route = ast.parse(
        "from study.schemas.studies import StudyCreate, Other\n"
        "@router.post('')\ndef create(db, body: StudyCreate) -> None: pass\n"
        "def helper(db, body: Other) -> None: pass\n"
    )
    schemas = ast.parse(
        "import pydantic as p\nclass StudyCreate(p.BaseModel): pass\n"
        "class Other(p.BaseModel): pass\n"
    )
    service = ast.parse(
        "from study.schemas import studies\n"
        "def make(db, body: studies.StudyCreate | None, name: str) -> None: pass\n"
        "def fine(db, name: str) -> None: pass\n"
    )
    trees = {
        "server.routes.x": route,
        "study.schemas.studies": schemas,
        "study.services.y": service,
    }
    bodies = request_bodies(trees)
    assert bodies == {"study.schemas.studies.StudyCreate"}
    assert bodies_taken(trees, bodies, "study.services.") == [
        "study.services.y.make(body: studies.StudyCreate | None)"
    ]


# --- a service returns domain values, never a REST response ------------------------------
def response_models(trees: dict[str, ast.Module]) -> set[str]:
    """The models a route answers with: a pydantic model named in the return annotation of
    a route (`-> StudyPublic`, `-> list[SessionPublic]`, `-> X | None`) or in its
    decorator's `response_model=`, which FastAPI serializes as the response body; and their
    subclasses (a `CheckResult` is a `CheckState`)."""
    models = defined_models(trees)
    found = set()
    for module, tree in trees.items():
        if not module.startswith("server.routes."):
            continue
        for node in ast.walk(tree):
            if not (isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and _route(node)):
                continue
            named = [node.returns] if node.returns is not None else []
            named += [
                k.value
                for d in node.decorator_list
                if isinstance(d, ast.Call)
                for k in d.keywords
                if k.arg == "response_model"
            ]
            for annotation in named:
                for part in ast.walk(annotation):
                    if isinstance(part, ast.Name | ast.Attribute):
                        name = _qualified(module, tree, part)
                        if name in models:
                            found.add(name)
    return _with_subclasses(trees, found)


def responses_built(trees: dict[str, ast.Module], responses: set[str], package: str) -> list[str]:
    """`module.function -> Annotation` for every function of `package` whose return
    annotation names one of `responses` (alone, in a list, a tuple, a union)."""
    found = []
    for module, tree in trees.items():
        if not module.startswith(package):
            continue
        for node in ast.walk(tree):
            if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            if node.returns is None:
                continue
            for part in ast.walk(node.returns):
                named = isinstance(part, ast.Name | ast.Attribute)
                if named and _qualified(module, tree, part) in responses:
                    found.append(f"{module}.{node.name} -> {ast.unparse(node.returns)}")
    return sorted(set(found))


RESPONSES_ALLOWED: dict[str, str] = {}
"""Service functions that may return a route's response model, with why."""


def test_no_service_returns_a_rest_response() -> None:
    """The services answer with domain values (ORM rows, dataclasses, the design's own
    models); the routes build the REST responses from them, as they read their own bodies.

    The rule: a service's return annotation names no REST response model, alone or inside
    a list, tuple or union. A REST response model is a pydantic model that a route returns
    (its return annotation or `response_model=`), or a subclass of one: what FastAPI writes
    as a response body and the OpenAPI document describes. It is read from the routes, not
    from a name's ending (`...Public`, `...State`), so a new response is covered whatever it
    is called, and a model that is only nested inside one (a study's `StudyDesign`, a
    questionnaire's `Section`) is not one: the design is stored, validated and read by the
    core. An exception needs an entry in RESPONSES_ALLOWED saying why."""
    trees = _trees()
    responses = response_models(trees)
    assert {
        "study.schemas.studies.StudyPublic",
        "study.schemas.sessions.SessionPublic",
    } <= responses
    built = responses_built(trees, responses, "study.services.")
    bad = [b for b in built if b.partition(" ")[0] not in RESPONSES_ALLOWED]
    assert not bad, f"return the rows or domain values; build the response on the web side: {bad}"
    stale = set(RESPONSES_ALLOWED) - {b.partition(" ")[0] for b in built}
    assert not stale, f"gone: drop them from RESPONSES_ALLOWED: {sorted(stale)}"


def test_the_response_check_sees_a_service_returning_a_response() -> None:
    route = ast.parse(
        "from study.schemas import studies as s\nfrom study.schemas.studies import Listed\n"
        "@router.get('')\ndef one(db) -> s.StudyPublic: pass\n"
        "@router.get('/all')\ndef every(db) -> list[Listed]: pass\n"
        "@router.get('/raw', response_model=s.Raw)\ndef raw(db) -> Response: pass\n"
        "def helper(db) -> s.Other: pass\n"
    )
    schemas = ast.parse(
        "import pydantic as p\nclass StudyPublic(p.BaseModel): pass\n"
        "class Listed(p.BaseModel): pass\nclass Raw(p.BaseModel): pass\n"
        "class Other(p.BaseModel): pass\nclass More(StudyPublic): pass\n"
    )
    service = ast.parse(
        "from study.schemas.studies import StudyPublic, Listed, Other, More\n"
        "def public(db) -> StudyPublic: pass\n"
        "def more(db) -> tuple[More, int]: pass\n"
        "def many(db) -> list[Listed] | None: pass\n"
        "def fine(db) -> Other: pass\n"
        "def plain(db) -> int: pass\n"
    )
    trees = {
        "server.routes.x": route,
        "study.schemas.studies": schemas,
        "study.services.y": service,
    }
    assert response_models(trees) == {
        "study.schemas.studies.StudyPublic",
        "study.schemas.studies.Listed",
        "study.schemas.studies.Raw",
        "study.schemas.studies.More",
    }
    assert responses_built(trees, response_models(trees), "study.services.") == [
        "study.services.y.many -> list[Listed] | None",
        "study.services.y.more -> tuple[More, int]",
        "study.services.y.public -> StudyPublic",
    ]
