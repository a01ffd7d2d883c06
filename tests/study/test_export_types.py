"""An export reads back with the types its `datapackage.json` declares: the CSV package
validates with Frictionless, the Parquet files carry the declared Arrow types, and an
integer column with missing values stays integers with the gaps missing (no sentinel, no
NaN), read with the pandas recipe of docs/architecture.md (`dtype_backend="numpy_nullable"`).
"""

from __future__ import annotations

import io
import json
import math
import zipfile
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import httpx
import pandas as pd
import pyarrow.parquet as pq
import pytest

from study.services.tables import column, resource, write_csv, write_parquet

ARROW_TYPES = {
    "integer": "int64",
    "number": "double",
    "boolean": "bool",
    "string": "string",
    "datetime": "timestamp[ms, tz=UTC]",
}
NULLABLE = {"integer": "Int64", "number": "Float64", "boolean": "boolean", "string": "string"}
COLUMNS = [
    column("id", "integer", "Row."),
    column("advised_action", "integer", "Advised action, when advised."),
    column("batch_size", "integer", "A config value, from JSON [count]."),
    column("loss", "number", "A number, NaN when not computed."),
    column("advised", "boolean", "Advised."),
    column("logged_at", "datetime", "When."),
    column("label", "string", "Label."),
]
ROWS: list[dict[str, Any]] = [
    {"id": 1, "advised_action": None, "batch_size": 8.0, "loss": math.nan, "advised": False,
     "logged_at": datetime(2026, 12, 1, 20, 35, 41, 668000, UTC), "label": "a"},
    {"id": 2, "advised_action": 3, "batch_size": 16, "loss": 0.25, "advised": True,
     "logged_at": None, "label": None},
    {"id": 3, "advised_action": None, "batch_size": 2**40, "loss": None, "advised": None,
     "logged_at": datetime(2026, 12, 1, tzinfo=UTC), "label": ""},
]  # fmt: skip


def _package(folder: Path, fmt: str, columns: list[Any], rows: list[dict[str, Any]]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    write = write_parquet if fmt == "parquet" else write_csv
    write(folder / f"t.{fmt}", columns, rows)
    package = {
        "profile": "tabular-data-package",
        "name": "t",
        "resources": [resource("t", f"t.{fmt}", columns, {"primaryKey": ["id"]})],
    }
    (folder / "datapackage.json").write_text(json.dumps(package))
    return folder


def read_declared(folder: Path) -> dict[str, pd.DataFrame]:
    """Every table of an export, read with pandas as docs/architecture.md says: nullable
    dtypes, so an integer column with gaps stays Int64."""
    package = json.loads((folder / "datapackage.json").read_text())
    tables = {}
    for described in package["resources"]:
        path = folder / described["path"]
        fields = described["schema"]["fields"]
        if described["format"] == "parquet":
            frame = pd.read_parquet(path, dtype_backend="numpy_nullable")
        else:
            dates = [f["name"] for f in fields if f["type"] == "datetime"]
            frame = pd.read_csv(path, dtype_backend="numpy_nullable", keep_default_na=False,
                                na_values=[""], dtype={f["name"]: "string" for f in fields
                                                       if f["type"] == "string"})  # fmt: skip
            for name in dates:
                frame[name] = pd.to_datetime(frame[name], format="ISO8601", utc=True)
        for field in fields:
            if field["type"] == "datetime":  # milliseconds, as declared
                frame[field["name"]] = frame[field["name"]].astype("datetime64[ms, UTC]")
            found = str(frame[field["name"]].dtype)
            if field["type"] == "datetime":
                assert found.startswith("datetime64") and "UTC" in found, (path, field)
            elif len(frame) and frame[field["name"]].notna().any():
                assert found == NULLABLE[field["type"]], (path.name, field["name"], found)
        tables[described["name"]] = frame
    return tables


def check_arrow_types(folder: Path) -> None:
    """Each Parquet file's Arrow schema is exactly what its descriptor declares."""
    package = json.loads((folder / "datapackage.json").read_text())
    for described in package["resources"]:
        schema = pq.read_schema(folder / described["path"])
        declared = {f["name"]: ARROW_TYPES[f["type"]] for f in described["schema"]["fields"]}
        assert {f.name: str(f.type) for f in schema} == declared, described["name"]


def check_frictionless(folder: Path) -> None:
    frictionless = pytest.importorskip("frictionless")
    report = frictionless.validate(folder / "datapackage.json")
    assert report.valid, report.flatten(["rowNumber", "fieldName", "type", "note"])[:10]


def test_integer_columns_keep_integers_and_gaps_in_both_formats(tmp_path: Path) -> None:
    csv_folder = _package(tmp_path / "csv", "csv", COLUMNS, ROWS)
    parquet_folder = _package(tmp_path / "parquet", "parquet", COLUMNS, ROWS)
    check_frictionless(csv_folder)
    check_arrow_types(parquet_folder)
    raw = (csv_folder / "t.csv").read_text()
    assert "8.0" not in raw and "nan" not in raw.lower(), raw
    table = pq.read_table(parquet_folder / "t.parquet")
    assert table.column("advised_action").to_pylist() == [None, 3, None]
    assert table.column("batch_size").to_pylist() == [8, 16, 2**40]
    assert table.column("loss").to_pylist() == [None, 0.25, None]  # NaN is missing too
    from_csv = read_declared(csv_folder)["t"]
    from_parquet = read_declared(parquet_folder)["t"]
    for frame in (from_csv, from_parquet):
        assert str(frame["advised_action"].dtype) == "Int64"
        assert frame["advised_action"].isna().tolist() == [True, False, True]
        assert frame["advised_action"][1] == 3 and frame["batch_size"].tolist() == [8, 16, 2**40]
        assert frame["loss"].isna().tolist() == [True, False, True]
    pd.testing.assert_frame_equal(from_csv, from_parquet, check_dtype=False)


def _zip(api: httpx.Client, study: int, fmt: str, folder: Path) -> Path:
    response = api.get(f"/api/studies/{study}/export", params={"format": fmt})
    assert response.status_code == 200, response.text
    with zipfile.ZipFile(io.BytesIO(response.content)) as archive:
        archive.extractall(folder)
    return folder


def test_a_real_export_reads_back_with_its_declared_types(
    api: httpx.Client, tmp_path: Path
) -> None:
    """Sessions that never ran have gaps in integer columns (`texts_version`,
    `strategy_interval`): the export still validates and reads as integers."""
    study = api.post("/api/studies", json={"name": f"types {tmp_path.name}"}).json()["id"]
    for run in (
        {"method": "human", "config": {"advice_budget": 5}},
        {"method": "oracle", "strategy": "alternating", "config": {"advice_budget": 5},
         "strategy_options": {"interval": 3}},
        {"method": "autonomous", "config": {"batch_size": 16}},
    ):  # fmt: skip
        body = {"run": run}
        created = api.post(f"/api/studies/{study}/sessions", json=body)
        assert created.status_code == 201, created.text
    csv_folder = _zip(api, study, "csv", tmp_path / "csv")
    parquet_folder = _zip(api, study, "parquet", tmp_path / "parquet")
    check_frictionless(csv_folder)
    check_arrow_types(parquet_folder)
    from_csv = read_declared(csv_folder)
    from_parquet = read_declared(parquet_folder)
    sessions = from_parquet["sessions"]
    for name in ("texts_version", "strategy_interval"):
        assert str(sessions[name].dtype) == "Int64" and sessions[name].isna().any(), name
    assert sessions["strategy_interval"].dropna().tolist() == [3]
    for name, frame in from_csv.items():
        pd.testing.assert_frame_equal(frame, from_parquet[name], check_dtype=False, obj=name)


def test_a_failed_export_leaves_no_scratch_folder(tmp_path: Path) -> None:
    from study.db.engine import make_engine, make_session_factory
    from study.db.migrate import upgrade
    from study.services.errors import NotFound
    from study.services.export import export_zip

    engine = make_engine(f"sqlite:///{tmp_path / 'db.sqlite3'}")
    upgrade(engine)
    scratch = tmp_path / "exports" / "tmp"
    with make_session_factory(engine)() as db:
        for _ in range(3):
            with pytest.raises(NotFound):
                export_zip(db, 424242, scratch)
    assert list(scratch.iterdir()) == []
