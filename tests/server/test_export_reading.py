"""An export reads back as its `datapackage.json` declares, by the README's recipe
(`analysis.declared.read_table`): every column of every table of its declared type, CSV or
Parquet, a column empty in the export included; `ideeprl validate` accepts both packages,
and refuses one whose file differs from its descriptor. Runs on PostgreSQL too."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import httpx
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from analysis.declared import DTYPES, read_table, resources
from cli.main import main

pytestmark = pytest.mark.slow


def _export(api: httpx.Client, study: int, fmt: str, folder: Path) -> Path:
    response = api.get(f"/api/studies/{study}/export", params={"format": fmt})
    assert response.status_code == 200, response.text
    with zipfile.ZipFile(io.BytesIO(response.content)) as archive:
        archive.extractall(folder)
    return folder


def _declared(kind: str) -> str:
    return "datetime64[*, UTC]" if kind == "datetime" else DTYPES[kind]


def test_every_column_reads_back_with_its_declared_type_in_both_formats(
    api: httpx.Client, tmp_path: Path
) -> None:
    study = api.post("/api/studies", json={"name": f"reading {tmp_path.name}"}).json()["id"]
    for run in (
        {"method": "human", "config": {"advice_budget": 5}},
        {"method": "oracle", "strategy": "alternating", "config": {"advice_budget": 5},
         "strategy_options": {"interval": 3}},
        {"method": "autonomous"},
    ):  # fmt: skip
        made = api.post(f"/api/studies/{study}/sessions", params={"pretrain": "false"},
                        json={"run": run})  # fmt: skip
        assert made.status_code == 201, made.text
    empty_columns = 0
    for fmt in ("csv", "parquet"):
        folder = _export(api, study, fmt, tmp_path / fmt)
        for resource in resources(folder):
            table = read_table(folder, resource["name"])
            for field in resource["schema"]["fields"]:
                column = table[field["name"]]
                empty_columns += int(column.isna().all())
                found, wanted = str(column.dtype), _declared(field["type"])
                where = f"{fmt} {resource['name']}.{field['name']}"
                if field["type"] == "datetime":
                    assert found.startswith("datetime64[") and "UTC" in found, (where, found)
                else:
                    assert found == wanted, (where, found, wanted)
        assert main(["validate", str(folder)]) == 0
    assert empty_columns > 20, "the export has empty columns (tables without rows too)"
    sessions = read_table(tmp_path / "csv", "sessions")
    assert sessions["strategy_interval"].dropna().tolist() == [3]
    assert sessions["consented_at"].isna().all(), "nobody consented: empty, still datetimes"


def test_validate_refuses_a_parquet_column_of_another_type(
    tmp_path: Path, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": f"tampered {tmp_path.name}"}).json()["id"]
    made = api.post(f"/api/studies/{study}/sessions", json={"run": {"method": "oracle"}})
    assert made.status_code == 201, made.text
    folder = _export(api, study, "parquet", tmp_path / "parquet")
    path = folder / "sessions.parquet"
    table = pq.read_table(path)
    index = table.schema.get_field_index("seed")
    table = table.set_column(index, "seed", table.column("seed").cast(pa.float64()))
    pq.write_table(table, path)
    assert main(["validate", str(folder)]) == 1
    assert main(["validate", str(tmp_path / "nothing")]) == 2
