"""A study's fitted advisor models as files: where each lies (`fitted` runs name it), the
file written again when gone, and what a run's `fitted_model` resolves to. Apart from the
fitting, which reads sessions, so that creating a session needs none of it."""

from __future__ import annotations

import json
from pathlib import Path

from sqlalchemy.orm import Session

from study.db.models import FittedAdvisorModel
from study.services.errors import Invalid


def fitted_model_path(data_dir: Path, study_id: int, model_id: int) -> Path:
    """A stored fitted advisor model's JSON file, which `fitted` runs name."""
    return data_dir / "fitted" / f"study-{study_id}-model-{model_id}.json"


def write_model_file(data_dir: Path, row: FittedAdvisorModel) -> Path:
    path = fitted_model_path(data_dir, row.study_id, row.id)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(row.model, indent=1))
    return path


def resolve(db: Session, name: str, data_dir: Path | None) -> str:
    """The model file a `fitted` run names: `fitted:ID` (a stored model; its file written
    again if gone), or a path, which through the API must lie under `data_dir`."""
    if name.startswith("fitted:"):
        number = name.removeprefix("fitted:")
        known = number.isdigit() and len(number) < 10
        row = db.get(FittedAdvisorModel, int(number)) if known else None
        if row is None or data_dir is None:
            raise Invalid(
                "run.fitted_model",
                "run.fitted_model names no stored model; GET /api/studies/ID/fitted lists "
                "them (fitted:ID), or give the path `ideeprl fit` printed",
            )
        path = fitted_model_path(data_dir, row.study_id, row.id)
        if not path.is_file():
            write_model_file(data_dir, row)
        return str(path.resolve())
    path = Path(name).resolve()
    if data_dir is not None and not path.is_relative_to(data_dir.resolve()):
        raise Invalid(
            "run.fitted_model",
            "run.fitted_model must be fitted:ID (a stored model) or a file under the "
            "server's data folder",
        )
    if not path.is_file():
        raise Invalid("run.fitted_model", "run.fitted_model: no such file")
    return str(path)
