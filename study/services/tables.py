"""The export's tables as typed columns: one declaration gives the CSV cells, the Parquet
schema and the Frictionless `datapackage.json`, so the three never disagree.

Cell conventions (what R's `read.csv`, readr, pandas and pyarrow all read without
options): booleans `true`/`false`; missing values empty; timestamps ISO 8601 in UTC
with a `Z` (`2026-12-01T20:35:41.668Z`, milliseconds); numbers as Python prints them,
integers without a decimal point. A missing value is missing in both formats (empty in the
CSV, null in Parquet; an integer column stays int64 with nulls): never a sentinel, never
NaN.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

TYPES = ("integer", "number", "boolean", "string", "datetime")
"""Frictionless Table Schema field types the export uses."""
BATCH = 5000
"""Rows per Parquet row group written at once."""


@dataclass(frozen=True)
class Column:
    name: str
    type: str
    """One of `TYPES`."""
    description: str
    unit: str | None = None
    """Unit of a quantity (s, count, ...); None for labels and ids."""

    def field(self) -> dict[str, Any]:
        """The Table Schema field: name, type, description, unit and formats."""
        field: dict[str, Any] = {"name": self.name, "type": self.type}
        field["description"] = self.description
        if self.unit:
            field["unit"] = self.unit
        if self.type == "boolean":
            field |= {"trueValues": ["true"], "falseValues": ["false"]}
        if self.type == "datetime":
            field["format"] = "%Y-%m-%dT%H:%M:%S.%fZ"
        return field


_UNIT = re.compile(r"\s*\[([^\]]+)\]\.?\s*$")


def column(name: str, type_: str, description: str, unit: str | None = None) -> Column:
    """A column; a trailing "[unit]" in the description becomes its unit."""
    assert type_ in TYPES, type_
    found = _UNIT.search(description)
    if found and unit is None:
        unit = found.group(1)
        description = description[: found.start()].rstrip() + "."
        description = description.replace("..", ".")
    return Column(name, type_, description, unit)


def iso_z(value: datetime | None) -> str:
    """ISO 8601 UTC with a Z and milliseconds; '' for None. Naive values are UTC."""
    if value is None:
        return ""
    if value.tzinfo is None:
        value = value.replace(tzinfo=UTC)
    return value.astimezone(UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def typed(column: Column, value: Any) -> Any:
    """A value as its column's declared type, None when missing: an integer stays an
    integer (a float such as 8.0, from JSON, becomes 8) and a number's NaN is missing, so
    the CSV and the Parquet file hold the same cells and a reader needs no sentinel."""
    if value is None or (isinstance(value, str) and value == ""):  # "" is missing (CSV)
        return None
    if column.type == "integer":
        if isinstance(value, float):
            if math.isnan(value):
                return None
            assert value.is_integer(), f"{column.name}: {value} is not an integer"
        assert not isinstance(value, bool), f"{column.name}: a boolean is not an integer"
        return int(value)
    if column.type == "number":
        value = float(value)
        return None if math.isnan(value) else value
    return value


def cell(value: Any) -> Any:
    """A value as the CSV cell the module docstring promises."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, datetime):
        return iso_z(value)
    return value


def write_csv(path: Path, columns: list[Column], rows: Iterable[dict[str, Any]]) -> int:
    """The rows as CSV; text cells a spreadsheet would run as a formula are neutralised
    (`analysis.csvsafe`), numbers are written as they are."""
    from analysis.csvsafe import safe_cell

    count = 0
    with path.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow([c.name for c in columns])
        for row in rows:
            writer.writerow(
                [
                    safe_cell(cell(typed(c, row.get(c.name))))
                    if c.type == "string"
                    else cell(typed(c, row.get(c.name)))
                    for c in columns
                ]
            )
            count += 1
    return count


def arrow_schema(columns: list[Column]) -> Any:
    import pyarrow as pa

    kinds = {
        "integer": pa.int64(),
        "number": pa.float64(),
        "boolean": pa.bool_(),
        "string": pa.string(),
        "datetime": pa.timestamp("ms", tz="UTC"),
    }
    return pa.schema([pa.field(c.name, kinds[c.type]) for c in columns])


def _batches(rows: Iterable[dict[str, Any]]) -> Iterator[list[dict[str, Any]]]:
    batch: list[dict[str, Any]] = []
    for row in rows:
        batch.append(row)
        if len(batch) == BATCH:
            yield batch
            batch = []
    if batch:
        yield batch


def write_parquet(path: Path, columns: list[Column], rows: Iterable[dict[str, Any]]) -> int:
    """The same table as Parquet, typed by `columns`, written in row groups."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = arrow_schema(columns)
    count = 0
    with pq.ParquetWriter(path, schema) as writer:
        for batch in _batches(rows):
            data = {c.name: [typed(c, r.get(c.name)) for r in batch] for c in columns}
            writer.write_table(pa.Table.from_pydict(data, schema=schema))
            count += len(batch)
        if count == 0:
            writer.write_table(schema.empty_table())
    return count


def resource(name: str, path: str, columns: list[Column], keys: dict[str, Any]) -> dict[str, Any]:
    """A Tabular Data Resource for one written table (`keys`: primaryKey, foreignKeys)."""
    fmt = "parquet" if path.endswith(".parquet") else "csv"
    described: dict[str, Any] = {
        "name": name,
        "path": path,
        "profile": "tabular-data-resource",
        "format": fmt,
        "mediatype": "application/vnd.apache.parquet" if fmt == "parquet" else "text/csv",
        "schema": {"fields": [c.field() for c in columns], "missingValues": [""], **keys},
    }
    if fmt == "csv":
        described["encoding"] = "utf-8"
    return described
