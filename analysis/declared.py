"""An export's tables with the types its `datapackage.json` declares, and the check that
each file holds what the descriptor says.

pandas alone guesses a column's type from its cells: a column that is empty in an export
(`sessions.participant` in a study without people, `advice.same_observation` without
replays) reads as numbers, and an integer column with gaps as floats. Here every column gets
its declared type, CSV or Parquet alike: `integer` Int64, `number` Float64, `boolean`
boolean, `string` string, `datetime` UTC timestamps, a missing value `<NA>` (`NaT`).

The check is `ideeprl validate EXPORT`'s: Frictionless 5 validates the CSV package but
misreads Parquet (through pandas' default dtypes, an integer column with gaps becomes
floats, which it reports as type errors that are not in the file).
"""

from __future__ import annotations

import json
import tempfile
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pandas as pd

DTYPES = {"integer": "Int64", "number": "Float64", "boolean": "boolean", "string": "string"}
ARROW = {
    "integer": "int64",
    "number": "double",
    "boolean": "bool",
    "string": "string",
    "datetime": "timestamp[ms, tz=UTC]",
}
"""The Arrow type of each declared type in a Parquet export (`study.services.tables`)."""
BOOLEANS = {"true": True, "false": False}


class DeclaredTypeError(ValueError):
    """A cell that is not of its column's declared type."""


def resources(folder: Path) -> list[dict[str, Any]]:
    """The tables `datapackage.json` describes."""
    package = json.loads((folder / "datapackage.json").read_text(encoding="utf-8"))
    return list(package["resources"])


def read_table(export: str | Path, name: str) -> pd.DataFrame:
    """Table `name` (`sessions`, `steps`, ...) of an export folder, every column of its
    declared type."""
    folder = Path(export)
    for resource in resources(folder):
        if resource["name"] == name:
            return read_resource(folder, resource)
    names = ", ".join(r["name"] for r in resources(folder))
    raise KeyError(f"no table {name!r} in {folder} (it has {names})")


def read_resource(folder: Path, resource: dict[str, Any]) -> pd.DataFrame:
    fields = resource["schema"]["fields"]
    path = folder / resource["path"]
    if resource.get("format") == "parquet":
        frame = pd.read_parquet(path, dtype_backend="numpy_nullable")
    else:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False, na_values=[""])
    for field in fields:
        frame[field["name"]] = _typed(frame[field["name"]], field["type"], field["name"])
    return frame


def _typed(column: pd.Series, kind: str, name: str) -> pd.Series:
    try:
        if kind == "datetime":
            if isinstance(column.dtype, pd.DatetimeTZDtype):
                return column
            return pd.to_datetime(column.astype("string"), format="ISO8601", utc=True)
        if kind == "boolean" and not pd.api.types.is_bool_dtype(column.dtype):
            text = column.astype("string")
            if not text.dropna().isin(list(BOOLEANS)).all():
                raise ValueError("not true or false")
            return text.map(BOOLEANS, na_action="ignore").astype("boolean")
        if kind in ("integer", "number") and not pd.api.types.is_numeric_dtype(column.dtype):
            numbers = pd.to_numeric(column.astype("string"))
            if kind == "integer" and not (numbers.dropna() % 1 == 0).all():
                raise ValueError("not whole numbers")
            return numbers.astype(DTYPES[kind])
        return column.astype(DTYPES[kind])
    except (ValueError, TypeError) as error:
        raise DeclaredTypeError(f"column {name!r} is not all {kind}: {error}") from None


def problems(export: str | Path) -> list[str]:
    """What in an export (folder or zip) differs from its descriptor: a table missing, its
    columns other than declared, a cell not of its column's type, a Parquet column of
    another Arrow type, a primary key repeated or missing. Empty: the export is valid."""
    import pyarrow.parquet as pq

    found = []
    with _folder(Path(export)) as folder:
        if not (folder / "datapackage.json").is_file():
            return [f"{export}: no datapackage.json, so not an export"]
        for resource in resources(folder):
            name, path = resource["name"], folder / resource["path"]
            declared = [f["name"] for f in resource["schema"]["fields"]]
            if not path.is_file():
                found.append(f"{name}: {resource['path']} is missing")
                continue
            if resource.get("format") == "parquet":
                types = {f.name: str(f.type) for f in pq.read_schema(path)}
                for field in resource["schema"]["fields"]:
                    want = ARROW[field["type"]]
                    if types.get(field["name"], want) != want:
                        got = types[field["name"]]
                        found.append(f"{name}.{field['name']}: {got} where {want} is declared")
                header = list(types)
            else:
                header = list(pd.read_csv(path, dtype=str, nrows=0).columns)
            if header != declared:
                found.append(f"{name}: columns {header} where {declared} are declared")
                continue
            try:
                table = read_resource(folder, resource)
            except DeclaredTypeError as error:
                found.append(f"{name}: {error}")
                continue
            keys = resource["schema"].get("primaryKey") or []
            keys = [keys] if isinstance(keys, str) else keys
            if keys and (table[keys].isna().any(axis=None) or table.duplicated(keys).any()):
                found.append(f"{name}: its primary key {', '.join(keys)} is missing or repeated")
    return found


@contextmanager
def _folder(export: Path) -> Iterator[Path]:
    """The export's folder (a zip unpacked into a temporary one)."""
    if export.is_dir():
        yield export
        return
    with tempfile.TemporaryDirectory() as tmp, zipfile.ZipFile(export) as archive:
        archive.extractall(tmp)
        yield Path(tmp)
