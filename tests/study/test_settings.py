from pathlib import Path

import pytest

from study.settings import Settings


def test_plain_database_url_is_read_and_given_the_psycopg_driver(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv("IDEEPRL_DATABASE_URL", raising=False)
    monkeypatch.setenv("DATABASE_URL", "postgresql://u:p@localhost/db")
    assert Settings().db_url == "postgresql+psycopg://u:p@localhost/db"


def test_default_database_is_sqlite_in_the_data_dir(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.delenv("DATABASE_URL", raising=False)
    monkeypatch.delenv("IDEEPRL_DATABASE_URL", raising=False)
    assert Settings(data_dir=tmp_path).db_url == f"sqlite:///{tmp_path}/ideeprl.sqlite3"


def test_a_missing_key_is_generated_once_and_kept(tmp_path: Path) -> None:
    first, new = Settings(data_dir=tmp_path, api_key=None).ensure_api_key()
    again, new_again = Settings(data_dir=tmp_path, api_key=None).ensure_api_key()
    assert new and not new_again
    assert first == again and len(first) >= 24
    assert (tmp_path / "api_key").stat().st_mode & 0o077 == 0
