"""A session's pinned numerics when it (re)starts: honoured, refused, or overridden and
recorded.

A run is pinned when its session is created (`RunSpec.pinned`: device, convolution
precision, the compiled convolutions' variant and the layers it computes, torch threads).
A resume on a machine that cannot take the same steps (a run pinned to bfloat16 on a CPU
without AVX-512 BF16 or AMX, to CUDA without a GPU, to a kernel variant this CPU or build
lacks, or to a set of compiled layers this code does not compute) is refused with the
reason, unless the caller overrides: then the run is pinned anew on this machine and the
change is appended to the session's `numerics_overrides` (when, at which step, from what,
to what, why), which the export carries. A session stored before numerics
were pinned (`auto`) is pinned at its next start, without an override: it never had any.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import Session

from learner import machine
from learner.run import RunSpec
from study.db.models import StudySession, utcnow
from study.services.errors import Conflict

FIELDS = ("device", "precision", "conv_kernel", "torch_threads")


class NumericsRefused(Conflict):
    """The session's pinned numerics cannot be honoured here."""


def refusal(session: StudySession, spec: RunSpec) -> str | None:
    """Why this machine may not resume the session (whose run is `spec`) as pinned, or
    None."""
    problem = spec.numerics_problem()
    if problem is None:
        return None
    return (
        f"session {session.id} cannot resume here: {problem}. Its records so far were "
        "computed as pinned; resuming with other numerics mixes two computations (pass "
        "override_numerics to do it anyway; the override is recorded in the session)"
    )


def _numbers(spec: RunSpec) -> dict[str, Any]:
    return {name: getattr(spec.config, name) for name in FIELDS}


def settle(
    db: Session,
    session: StudySession,
    spec: RunSpec,
    override: bool = False,
) -> RunSpec:
    """The run (`spec`, the session's) as this machine will compute it: pinned as stored,
    pinned now (stored before pinning), or re-pinned by an override (recorded); raises
    `NumericsRefused` otherwise."""
    problem = refusal(session, spec)
    if problem is not None and not override:
        raise NumericsRefused(problem)
    if problem is not None:
        repinned = spec.repinned()
        session.numerics_overrides = [
            *session.numerics_overrides,
            {
                "at": utcnow().isoformat(),
                "checkpoint_step": session.checkpoint_step,
                "from": _numbers(spec),
                "to": _numbers(repinned),
                "why": spec.numerics_problem(),
                "machine": machine.cpu_kind(),
            },
        ]
        spec = repinned
    elif spec.pinned() != spec:  # stored before runs were pinned: pinned at this start
        spec = spec.pinned()
    else:
        return spec
    session.run = spec.to_json()
    db.commit()
    return spec
