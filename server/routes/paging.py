"""`limit` and `offset` for the list endpoints, so a client can page through long lists."""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated, TypeVar

from fastapi import Depends, Query

from study.schemas.types import MAX_ID

DEFAULT_LIMIT = 1000
"""Enough for a whole 300-episode learning curve in one call."""
MAX_LIMIT = 10_000

T = TypeVar("T")


@dataclass(frozen=True)
class Page:
    limit: int
    offset: int

    def of(self, items: Sequence[T]) -> list[T]:
        """The page's slice of `items` (in the list's own order)."""
        return list(items[self.offset : self.offset + self.limit])


def page(
    limit: int = Query(
        default=DEFAULT_LIMIT, ge=1, le=MAX_LIMIT, description="At most this many items."
    ),
    offset: int = Query(default=0, ge=0, le=MAX_ID, description="Skip this many items first."),
) -> Page:
    return Page(limit, offset)


PageDep = Annotated[Page, Depends(page)]
