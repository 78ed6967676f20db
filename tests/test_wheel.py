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
    assert not any(n.startswith(("hycosim/build/", "hycosim/scenario/build/", "tests/", "benchmarks/")) for n in names)
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
                    "starlette": "starlette", "uvicorn": "uvicorn", "websockets": "websockets", "pyarrow": "pyarrow"}
    extras = _pyproject()["project"]["optional-dependencies"]
    for extra, modules in EXTRAS.items():
        dists = [re.split(r"[<>=!\[ ]", req, maxsplit=1)[0] for req in extras[extra]]
        assert sorted(import_names[d] for d in dists) == sorted(modules), extra


def test_the_core_install_runs_fmus_from_the_docs_and_names_a_missing_extra(installed, tmp_path):
    version = _pyproject()["project"]["version"]
    res = installed.hycosim("--version")
    assert res.returncode == 0 and res.stdout.strip() == f"hycosim {version}", res.stdout + res.stderr
    # The installed package, not this checkout, and none of the extras' packages.
    res = installed.python("import sys, hycosim, hycosim.core.config, hycosim.master.relay, hycosim.node.runtime, "
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
                        (["dashboard", str(run)], "dashboard"), (["plot", str(run)], "plot"),
                        (["run", "two.json", "--record", "parquet", "--runs-dir", "pq-runs"], "parquet")):
        res = installed.hycosim(*args)
        assert res.returncode == 2, (args, res.stdout, res.stderr)
        assert f"[{extra}] extra" in res.stderr and f"pip install 'hycosim[{extra}]'" in res.stderr, res.stderr
        assert "Traceback" not in res.stderr, res.stderr
    assert not (installed.work / "pq-runs").exists()  # refused before a run directory is made
    # A project whose node is one of the scenario's Python models names the extra too, and
    # `run` says so at once, before it makes a run directory or starts a process.
    shipped_grasp = next(installed.venv.glob("lib/python*/site-packages/hycosim/scenario/configs")) / "grasp.json"
    res = installed.hycosim("validate", str(shipped_grasp))
    assert res.returncode == 2 and "[scenario] extra" in res.stderr and "Traceback" not in res.stderr, res.stderr
    started = time.monotonic()
    res = installed.hycosim("run", str(shipped_grasp), "--runs-dir", "grasp-runs")
    took = time.monotonic() - started
    assert res.returncode == 2 and "pip install 'hycosim[scenario]'" in res.stderr, res.stdout + res.stderr
    assert not (installed.work / "grasp-runs").exists() and took < 5, took


def test_the_core_install_writes_and_runs_an_example_from_anywhere(installed):
    res = installed.hycosim("examples")
    assert res.returncode == 0, res.stderr
    listed = {line.split()[0] for line in res.stdout.splitlines() if line.strip()}
    assert {"default", "grasp", "grasp-fmu", "grasp-paper", "grasp-policy"} <= listed, res.stdout
    assert "[scenario]" in res.stdout  # what the grasp examples need, as written (no markup eaten)
    res = installed.hycosim("examples", "default", "-o", "d")
    assert res.returncode == 0 and (installed.work / "d" / "default.json").is_file(), res.stdout + res.stderr
    assert (installed.work / "d" / "project.schema.json").is_file()
    res = installed.hycosim("validate", "d/default.json")
    assert res.returncode == 0 and res.stdout.startswith("OK d/default.json"), res.stdout + res.stderr
    res = installed.hycosim("run", "d/default.json", "--no-progress", "--runs-dir", "d/runs")
    assert res.returncode == 0, res.stdout + res.stderr
    run = next((installed.work / "d" / "runs").glob("pendulum-catch-*"))
    assert json.loads((run / "meta.json").read_text())["status"] == "completed"
    # An example whose FMUs get built needs the extra that builds them, and says so.
    res = installed.hycosim("examples", "grasp-fmu", "-o", "g")
    assert res.returncode == 2 and "[scenario] extra" in res.stderr and "Traceback" not in res.stderr, res.stderr
    res = installed.hycosim("examples", "nope")
    assert res.returncode == 2 and "no example named 'nope'" in res.stderr, res.stderr


def _readme_commands() -> list[list[str]]:
    """The commands of README's table, each as the words that name it (``fmu build``)."""
    table = (REPO / "README.md").read_text().split("## Commands", 1)[1].split("\n## ", 1)[0]
    commands = []
    for cell in re.findall(r"`(hycosim [^`]+)`", table):
        words = []
        for word in cell.split()[1:]:
            if not re.fullmatch(r"[a-z][a-z-]*", word):
                break
            words.append(word)
        if words and words not in commands:
            commands.append(words)
    return commands


def test_every_command_of_the_readme_ends_in_a_core_install_with_0_or_2_and_no_traceback(installed):
    commands = _readme_commands()
    assert len(commands) >= 20 and ["krl", "controller"] in commands and ["examples"] in commands, commands
    # Each with no arguments, then with the least that gets past its usage check.
    minimal = {("krl", "controller"): ["--eki", "foo.xml"], ("krl", "export"): ["nothere"],
               ("validate",): ["x.json"], ("run",): ["x.json"], ("report",): ["nothere"],
               ("fmu", "inspect"): ["x.fmu"], ("fmu", "build"): ["x.json", "-o", "/no/such/dir"],
               ("scene", "reach"): ["x.json"], ("evaluate",): ["x.pt"], ("import",): ["x.ssp", "-o", "y.json"]}
    for words in commands:
        for extra_args in ([], minimal.get(tuple(words), [])):
            res = installed.hycosim(*words, *extra_args, timeout=120)
            said = res.stdout + res.stderr
            assert res.returncode in (0, 2), (words, extra_args, res.returncode, said[-1500:])
            assert "Traceback" not in said, (words, extra_args, said[-3000:])
    assert not (installed.work / "runs").exists() or not any((installed.work / "runs").glob("x-*"))


def test_the_models_extra_runs_getting_started_as_written(installed, tmp_path):
    """Every step of docs/getting-started.md, from pip install 'hycosim[models]' alone."""
    installed.pip_install(f"{installed.wheel}[models]", "models")
    folder = installed.work / "tour"
    folder.mkdir()
    page = (REPO / "docs" / "getting-started.md").read_text()
    assert "pip install 'hycosim[models]'" in page.split("## 1.", 1)[0]
    blocks = re.finditer(r"<!-- (?:file: (?P<name>[\w.\-]+)|shell) -->\n```[a-z]*\n(?P<body>.*?)```", page, re.S)
    ran = 0
    for block in blocks:
        if block["name"]:
            (folder / block["name"]).write_text(block["body"])
            continue
        script = "\n".join(line[2:] for line in block["body"].splitlines() if line.startswith("$ "))
        res = subprocess.run(["bash", "-e", "-c", script], capture_output=True, text=True, cwd=folder,
                             env=_user_env(installed.venv), timeout=300)
        assert res.returncode == 0, f"{script}\n--- exit {res.returncode}\n{res.stdout[-2000:]}\n{res.stderr[-3000:]}"
        ran += 1
    assert ran >= 5 and (folder / "Gain.fmu").is_file()


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


def test_the_scenario_extra_writes_the_fmu_example_and_runs_it_from_its_folder(installed):
    before = sorted(str(p) for p in installed.venv.glob("lib/python*/site-packages/hycosim/**/*"))
    res = installed.hycosim("examples", "grasp-fmu", "-o", "g", timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    g = installed.work / "g"
    assert (g / "fmus" / "Rod.fmu").is_file() and (g / "fmus" / "RobotScene6.fmu").is_file()
    doc = json.loads((g / "grasp-fmu.json").read_text())
    assert {n["fmu"] for n in doc["nodeLists"] if "fmu" in n} == {"fmus/Rod.fmu", "fmus/RobotScene6.fmu"}
    res = subprocess.run([str(installed.venv / "bin" / "hycosim"), "run", "grasp-fmu.json", "--no-progress"],
                         capture_output=True, text=True, cwd=g, env=_user_env(installed.venv), timeout=600)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-3000:]
    run = next((g / "runs").glob("grasp-fmu-*"))
    assert json.loads((run / "meta.json").read_text())["status"] == "completed"
    assert '"to": "grasp"' in (run / "events.jsonl").read_text()
    # Nothing was written into the installed package (no FMUs, no run, no cache).
    after = sorted(str(p) for p in installed.venv.glob("lib/python*/site-packages/hycosim/**/*"))
    assert [p for p in after if p not in before and "__pycache__" not in p] == []


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
