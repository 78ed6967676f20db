"""hycosim as a user gets it: the sdist and wheel built from this tree, the wheel installed
with its core dependencies only into a fresh virtual environment outside the repository, and
used there with no checkout on the import path; then its [scenario] extra installed and one
grasp trial run from the installed package.

The environment is made once for the module (installing is most of the time); the tests run
in order on it: the core first, then the extra.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tarfile
import time
import zipfile
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hycosim.core.extras import EXTRAS
from tests.helpers import REPO

PIP_TIMEOUT = 900  # seconds for one pip install (torch is large)


def _pyproject() -> dict:
    import tomllib

    return tomllib.loads((REPO / "pyproject.toml").read_text())


def _user_env(venv: Path) -> dict[str, str]:
    """A user's shell with the venv active: nothing of the checkout on the import path."""
    base = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    return dict(base, PATH=f"{venv / 'bin'}{os.pathsep}{base['PATH']}", VIRTUAL_ENV=str(venv), PYTHONUNBUFFERED="1")


class Installed:
    """The fresh environment: run its ``hycosim`` and its ``python`` in a folder of the user's."""

    def __init__(self, root: Path, wheel: Path, sdist: Path):
        self.root, self.wheel, self.sdist = root, wheel, sdist
        self.venv, self.work = root / "venv", root / "work"
        self.timings: dict[str, float] = {}

    def run(self, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
        return subprocess.run(list(args), capture_output=True, text=True, cwd=self.work, env=_user_env(self.venv),
                              timeout=timeout)

    def hycosim(self, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
        return self.run(str(self.venv / "bin" / "hycosim"), *args, timeout=timeout)

    def python(self, code: str) -> subprocess.CompletedProcess:
        return self.run(str(self.venv / "bin" / "python"), "-c", code)

    def pip_install(self, requirement: str, label: str) -> None:
        # [scenario] pins torch==2.13.0, the CPU build that pip finds here (as the Makefile installs it).
        started = time.monotonic()
        res = self.run(str(self.venv / "bin" / "python"), "-m", "pip", "install", "--quiet", requirement,
                       timeout=PIP_TIMEOUT)
        self.timings[label] = time.monotonic() - started
        assert res.returncode == 0, res.stderr[-3000:]


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Installed:
    root = tmp_path_factory.mktemp("user")
    assert REPO not in root.parents
    dist = root / "dist"
    # --no-isolation: the build backend of this venv (setuptools, upgraded by the Makefile), so
    # the build needs no download; the wheel is built from the sdist, which proves the sdist whole.
    res = subprocess.run([sys.executable, "-m", "build", "--no-isolation", "--outdir", str(dist), str(REPO)],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-3000:]
    version = _pyproject()["project"]["version"]
    wheel, sdist = dist / f"hycosim-{version}-py3-none-any.whl", dist / f"hycosim-{version}.tar.gz"
    assert wheel.is_file() and sdist.is_file(), sorted(p.name for p in dist.iterdir())
    env = Installed(root, wheel, sdist)
    env.work.mkdir()
    res = subprocess.run([sys.executable, "-m", "venv", str(env.venv)], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    env.pip_install(str(wheel), "core")
    return env


def test_the_wheel_holds_only_the_hycosim_package_its_data_and_licence(installed):
    with zipfile.ZipFile(installed.wheel) as whl:
        names = whl.namelist()
        version = _pyproject()["project"]["version"]
        info = f"hycosim-{version}.dist-info"
        record = whl.read(f"{info}/RECORD").decode()
        metadata = whl.read(f"{info}/METADATA").decode()
        top_level = whl.read(f"{info}/top_level.txt").decode().split() if f"{info}/top_level.txt" in names else []
    tops = {line.split(",", 1)[0].split("/", 1)[0] for line in record.splitlines() if line}
    assert tops == {"hycosim", info}, tops
    assert top_level in ([], ["hycosim"]), top_level
    for data in ("hycosim/project.schema.json", "hycosim/scenario/configs/grasp-paper.json", "hycosim/configs/default.json",
                 "hycosim/scenario/policy/pretrained/ddpg_grasp.pt", "hycosim/dashboard/static/index.html",
                 "hycosim/bridge/templates/bridge_fmu.c", f"{info}/licenses/LICENSE"):
        assert data in names, data
    assert not any(n.startswith(("hycosim/build/", "tests/", "benchmarks/")) for n in names)
    assert "License-Expression: Apache-2.0" in metadata
    assert re.search(r"^Requires-Dist: torch.*extra == .scenario.", metadata, re.M), "torch is no core dependency"
    assert not re.search(r"^Requires-Dist: (torch|mujoco|opencv|starlette)[^;]*$", metadata, re.M)
    with tarfile.open(installed.sdist) as sdist:
        members = sdist.getnames()
    assert any(m.endswith("/LICENSE") for m in members) and any(m.endswith("/hycosim/scenario/configs/grasp.json")
                                                                for m in members)


def test_the_extras_table_matches_the_packaging_metadata():
    """hycosim.core.extras names the import names of each extra that a command checks for; every
    distribution of the extra is there (by its import name) and nothing else."""
    import_names = {"mujoco": "mujoco", "opencv-python-headless": "cv2", "torch": "torch", "gymnasium": "gymnasium",
                    "pythonfmu": "pythonfmu", "pythonfmu3": "pythonfmu3", "matplotlib": "matplotlib",
                    "starlette": "starlette", "uvicorn": "uvicorn", "websockets": "websockets"}
    extras = _pyproject()["project"]["optional-dependencies"]
    for extra, modules in EXTRAS.items():
        dists = [re.split(r"[<>=!\[ ]", req, maxsplit=1)[0] for req in extras[extra]]
        assert sorted(import_names[d] for d in dists) == sorted(modules), extra


def test_the_core_install_runs_fmus_from_the_docs_and_names_a_missing_extra(installed, tmp_path):
    version = _pyproject()["project"]["version"]
    res = installed.hycosim("--version")
    assert res.returncode == 0 and res.stdout.strip() == f"hycosim {version}", res.stdout + res.stderr
    # The installed package, not this checkout, and none of the extras' packages.
    res = installed.python("import sys, hycosim, hycosim.core.config, hycosim.server.relay, hycosim.node.runtime, "
                           "hycosim.fmi.fmu_open, hycosim.cli; print(hycosim.__file__); print(sorted(m for m in "
                           "('torch', 'mujoco', 'cv2', 'matplotlib', 'starlette', 'gymnasium') if m in sys.modules))")
    assert res.returncode == 0, res.stderr
    where, loaded = res.stdout.split("\n")[:2]
    assert Path(where).is_relative_to(installed.venv) and loaded == "[]", res.stdout
    res = installed.python("import importlib.util as u; print([m for m in ('torch', 'mujoco', 'cv2', 'starlette') "
                           "if u.find_spec(m)])")
    assert res.stdout.strip() == "[]", "the core install pulled an extra's package: " + res.stdout

    # The first page of the manual: a model FMU (built here with pythonfmu, which the core
    # install does not need to run it) coupled with itself, validated and run.
    page = (REPO / "docs" / "getting-started.md").read_text()
    blocks = dict(re.findall(r"<!-- file: ([\w.\-]+) -->\n```[a-z]*\n(.*?)```", page, re.S))
    for name in ("gain.py", "two.json"):
        (installed.work / name).write_text(blocks[name])
    from hycosim.bridge.model_fmu import build_model_fmu

    build_model_fmu(installed.work / "gain.py", installed.work)
    res = installed.hycosim("validate", "two.json")
    assert res.returncode == 0 and res.stdout.startswith("OK two.json"), res.stdout + res.stderr
    res = installed.hycosim("run", "two.json", "--no-progress")
    assert res.returncode == 0, res.stdout + res.stderr
    run = next((installed.work / "runs").glob("two-*"))
    rows = (run / "values.csv").read_text().splitlines()
    assert rows[0].startswith("step,t") and "amp.y" in rows[0] and len(rows) == 22, rows[:3]  # the header and steps 0 to 20
    assert json.loads((run / "meta.json").read_text())["versions"]["hycosim"] == version

    res = installed.hycosim("schema")
    shipped = installed.venv.glob("lib/python*/site-packages/hycosim/project.schema.json")
    assert res.returncode == 0 and json.loads(res.stdout) == json.loads(next(shipped).read_text())

    # What needs an extra says which, and how to install it.
    for args, extra in ((["trials", "--angles", "40", "--trials", "1"], "scenario"), (["camera"], "scenario"),
                        (["dashboard", str(run)], "dashboard"), (["plot", str(run)], "plot")):
        res = installed.hycosim(*args)
        assert res.returncode == 2, (args, res.stdout, res.stderr)
        assert f"[{extra}] extra" in res.stderr and f"pip install 'hycosim[{extra}]'" in res.stderr, res.stderr
        assert "Traceback" not in res.stderr, res.stderr
    # A project whose node is one of the scenario's Python models names the extra too.
    res = installed.hycosim("validate", str(next(installed.venv.glob("lib/python*/site-packages/hycosim/configs"))
                                           / "grasp.json"))
    assert res.returncode == 2 and "[scenario] extra" in res.stderr and "Traceback" not in res.stderr, res.stderr


def test_the_scenario_extra_runs_a_grasp_trial_from_the_installed_package(installed):
    installed.pip_install(f"{installed.wheel}[scenario]", "scenario")
    res = installed.hycosim("trials", "--angles", "40", "--trials", "1", "-o", "trials", timeout=600)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-3000:]
    assert "grasped" in res.stderr and (installed.work / "build" / "fmus" / "Rod.fmu").is_file(), res.stderr
    rows = (installed.work / "trials" / "trials.csv").read_text().splitlines()
    header, row = rows[0].split(","), rows[1].split(",")
    assert row[header.index("success")] == "True", rows
    # Built where the user is, not inside the installed package.
    assert not list(installed.venv.glob("lib/python*/site-packages/hycosim/build"))
    print(f"\ninstall times (s): {installed.timings}")


@given(st.one_of(st.none(), st.text(max_size=40), st.sampled_from(["cv2", "torch.nn", "clients", "clients.rod",
                                                                    "matplotlib.pyplot", "starlette"])),
       st.text(max_size=40))
def test_a_missing_modules_hint_is_total_and_names_an_extra_only_for_its_packages(missing, module_name):
    """The name an ImportError carries comes from whatever a user's model imports."""
    from hycosim.node.loader import _missing_module_hint
    from hycosim.core.extras import extra_providing

    extra = extra_providing(missing)
    assert extra is None or (missing or "").partition(".")[0] in EXTRAS[extra]
    hint = _missing_module_hint(missing, module_name)
    assert isinstance(hint, str)
    assert (f"[{extra}] extra" in hint) if extra else ("extra" not in hint)
