"""A non-editable install works away from the checkout: the wheel holds every package the
programs import and the pages (`web/`), `ideeprl` starts, and the server it starts serves
pages from the installed copy.

The wheel is built from a copy of the files pyproject.toml names (so a package missing from
its list is missing here too) and installed, without its dependencies, into a fresh venv over
the base interpreter. The dependencies come from this interpreter's site-packages, named in a
`.pth` file: a directory named there is put on `sys.path`, but the `.pth` files inside it are
not run, so the editable install of this checkout (its finder is started by one) stays out.
"""

from __future__ import annotations

import os
import shutil
import signal
import site
import subprocess
import sys
import sysconfig
import time
import tomllib
from pathlib import Path

import httpx
import pytest

from tests.server.live import API_KEY, free_port
from tests.server.scale import session_body

ROOT = Path(__file__).absolute().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
MODULES = ("server.main", "runs.worker.worker", "analysis.report", "cli.main")

pytestmark = pytest.mark.slow  # a wheel, a venv, a server: about half a minute


def _top_level() -> list[str]:
    """The folders the wheel is built from: pyproject.toml's package list."""
    include = PYPROJECT["tool"]["setuptools"]["packages"]["find"]["include"]
    return sorted({name.split(".")[0] for name in include})


def _wheel(tmp: Path) -> Path:
    source = tmp / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, source / name)
    for name in _top_level():
        shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
    dist = tmp / "dist"
    build = ["wheel", "--no-deps", "--no-build-isolation", "--quiet", "--wheel-dir", str(dist)]
    subprocess.run([sys.executable, "-m", "pip", *build, str(source)], check=True, cwd=tmp)
    [wheel] = dist.glob("ideeprl-*.whl")
    return wheel


def _venv(tmp: Path, wheel: Path) -> Path:
    """A fresh venv holding the wheel, its dependencies reached through a `.pth`."""
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    purelib = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    ours = {sysconfig.get_path("purelib"), *site.getsitepackages()}
    Path(purelib, "dependencies.pth").write_text("\n".join(sorted(ours)) + "\n")
    install = ["--python", str(python), "install", "--quiet", "--no-deps", "--no-index"]
    subprocess.run([sys.executable, "-m", "pip", *install, str(wheel)], check=True, cwd=tmp)
    return venv


def _environment() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("IDEEPRL_", "PYTHON"))}
    env.pop("DATABASE_URL", None)
    return env


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("install")
    return _venv(tmp, _wheel(tmp))


def test_the_command_line_runs_from_the_install(installed: Path) -> None:
    done = subprocess.run(
        [str(installed / "bin" / "ideeprl"), "--help"],
        cwd=installed.parent,
        env=_environment(),
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "usage: ideeprl" in done.stdout and "serve" in done.stdout, done.stdout


def test_the_programs_import_from_the_install_not_the_checkout(installed: Path) -> None:
    code = (
        f"import importlib, sys\nfor name in {(*MODULES, 'sim', 'learner', 'study')!r}:\n"
        "    print(importlib.import_module(name).__file__)\n"
        "from server.routes.pages import WEB_DIR\nprint(WEB_DIR)\n"
    )
    done = subprocess.run(
        [str(installed / "bin" / "python"), "-c", code],
        cwd=installed.parent,
        env=_environment(),
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    *files, web = done.stdout.split()
    for file in files:
        assert Path(file).is_relative_to(installed), (file, installed)
    assert Path(web).is_relative_to(installed), web
    assert (Path(web) / "templates" / "base.html").is_file()
    assert (Path(web) / "texts" / "consent.txt").is_file()


def test_the_installed_server_serves_the_pages(installed: Path) -> None:
    tmp = installed.parent
    data = tmp / "data"
    data.mkdir()
    port = free_port()
    env = {
        **_environment(),
        "IDEEPRL_DATA_DIR": str(data),
        "IDEEPRL_DATABASE_URL": f"sqlite:///{data / 'study.sqlite3'}",
        "IDEEPRL_API_KEY": API_KEY,
        "IDEEPRL_POOL_LIMIT": "0",
    }
    log = tmp / "server.log"
    with log.open("wb") as out:
        process = subprocess.Popen(
            [str(installed / "bin" / "ideeprl"), "serve", "--port", str(port)],
            cwd=tmp,
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 90
        while True:
            assert process.poll() is None, log.read_text()
            assert time.monotonic() < deadline, log.read_text()
            try:
                if httpx.get(f"{url}/api/health", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.2)
        with httpx.Client(base_url=url, headers={"X-API-Key": API_KEY}, timeout=60) as api:
            css = api.get("/static/site.css")
            assert css.status_code == 200
            assert css.text == (ROOT / "web" / "static" / "site.css").read_text()
            login = api.get("/dashboard/login")
            assert login.status_code == 200 and "<form" in login.text, login.text
            study = api.post("/api/studies", json={"name": "installed"}).json()["id"]
            body = session_body("human", advice_budget=3)
            made = api.post(f"/api/studies/{study}/sessions", json=body)
            assert made.status_code == 201, made.text
            token = made.json()["participant_token"]
            consent = api.get(f"/p/{token}/consent")
            assert consent.status_code == 200, consent.text
            # the sorting robot's own consent text ships with the install (its task's folder)
            assert "You will watch a simulated robot arm" in consent.text, consent.text
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(60)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
