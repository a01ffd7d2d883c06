"""Where the server meets the learner: a session's run is a `learner.run.RunSpec`, stored whole
as its `run` document (`RunSpec.to_json()`), read back by the worker that runs it, the batch
that looks for it, the export and the report (docs/architecture.md)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from learner.fields import FieldError, leaves
from learner.run import RunSpec
from study.db.models import StudySession
from study.services.errors import Invalid


def checked(spec: RunSpec, threads: int | None = None) -> RunSpec:
    """The run validated and pinned on this machine (`threads`: torch threads for a run that
    leaves them open), as a session stores it; its errors as the API's (naming the field)."""
    try:
        return spec.validate().pinned(threads)
    except FieldError as error:
        raise Invalid(_where(error), str(error)) from None


def parse(data: Any, spec_class: type[RunSpec] = RunSpec) -> RunSpec:
    """A run from JSON, every value checked (`Invalid` names the field)."""
    try:
        return spec_class.from_json(data)
    except FieldError as error:
        raise Invalid(_where(error), str(error)) from None


def _where(error: FieldError) -> str:
    """The body's field of a run's error: `run.config.batch_size`."""
    return f"run.{error.field}" if error.field else "run"


def spec_of(session: StudySession, spec_class: type[RunSpec] = RunSpec) -> RunSpec:
    """The run a stored session describes, as the learner reads it back (fields added to
    `spec_class` since it was stored take their defaults)."""
    return spec_class.from_json(session.run)


NUMERICS = tuple(leaf.name for leaf in leaves(RunSpec) if leaf.role == "numerics")
"""The leaves a session pins when it is created (`RunSpec.pinned`)."""
OPEN = {"auto", 0}
"""A numerics value that leaves the choice to the machine."""


def identity(spec: RunSpec) -> dict[str, Any]:
    """What identifies a run among a study's sessions (the batch finds its runs by it): every
    field of the normalized run in its stored JSON form, the advisor's checkpoint as an
    absolute path, and numerics only where they were asked for (not left `auto`): a run's
    pinned numerics are checked when it resumes (`RunSpec.numerics_problem`)."""
    doc = spec.normalized().to_json()
    doc.pop("version")
    if doc["advisor_checkpoint"] is not None and not doc["advisor_checkpoint"].startswith(
        "session:"
    ):
        doc["advisor_checkpoint"] = str(Path(doc["advisor_checkpoint"]).resolve())
    if doc.get("fitted_model") and not doc["fitted_model"].startswith("fitted:"):
        doc["fitted_model"] = str(Path(doc["fitted_model"]).resolve())
    for name in NUMERICS:
        if doc["config"].get(name) in OPEN:
            doc["config"].pop(name)
    return json.loads(json.dumps(doc))


def same_run(wanted: dict[str, Any], session: StudySession, spec_class: type[RunSpec]) -> bool:
    """Whether the stored session is the run `wanted` (an `identity`): equal in everything,
    numerics wanted `auto` matching whatever the session pinned."""
    try:
        stored = identity(spec_of(session, spec_class))
    except (ValueError, TypeError):
        return False  # a run the learner can no longer read is never the same as a new one
    for name in NUMERICS:
        if name not in wanted["config"]:
            stored["config"].pop(name, None)
    return stored == wanted
