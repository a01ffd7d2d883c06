"""Path parameters shared by the routers (bounded, so no id can overflow a database int)."""

from typing import Annotated

from fastapi import Path

from study.schemas.types import MAX_ID

StudyId = Annotated[int, Path(ge=1, le=MAX_ID, description="Study id.")]
SessionId = Annotated[int, Path(ge=1, le=MAX_ID, description="Session id.")]
AdviceIndex = Annotated[int, Path(ge=0, le=MAX_ID, description="Advice index (0-based).")]
FittedId = Annotated[int, Path(ge=1, le=MAX_ID, description="Fitted advisor model id.")]
