"""What a new user meets first: the paper's own JSON, the manual's node example, `fmu inspect` on a pipe."""

from __future__ import annotations

import json
import re
import shutil

from hycosim.bridge.model_fmu import build_model_fmu
from tests.helpers import REPO, hycosim

# The paper's form: nodes with nodeName, UID, input and output only (each played by a bridge FMU
# in some tool), serverIP a bare IP, no coSimulation.
PAPER = {
    "serverIP": "192.168.1.10",
    "nodeNum": 2,
    "nodeLists": [
        {"nodeName": "adams", "UID": 1, "input": ["grip_x"], "output": ["angle"]},
        {"nodeName": "process_simulate", "UID": 2, "input": ["rod_angle"], "output": ["tcp_x"]},
    ],
    "linkNum": 2,
    "linkLists": [{"from": "adams.angle", "to": "process_simulate.rod_angle"},
                  {"from": "process_simulate.tcp_x", "to": "adams.grip_x"}],
}


def test_the_papers_json_validates_and_names_the_nodes_that_wait_for_bridge_fmus(tmp_path):
    (tmp_path / "paper.json").write_text(json.dumps(PAPER, indent=1))
    res = hycosim("validate", str(tmp_path / "paper.json"))
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith("OK ")
    assert "2 node(s) wait for a bridge FMU in some tool: adams, process_simulate" in res.stdout


def _doc_blocks(page: str) -> dict[str, str]:
    """The first python and json code blocks of a page of the manual (docs/)."""
    section = (REPO / "docs" / page).read_text()
    blocks = {}
    for lang, body in re.findall(r"```(\w+)\n(.*?)```", section, flags=re.S):
        blocks.setdefault(lang, body)
    return blocks


def test_the_manuals_node_example_runs_verbatim_from_a_fresh_folder(tmp_path):
    blocks = _doc_blocks("nodes.md")
    (tmp_path / "mypackage").mkdir()
    (tmp_path / "mypackage" / "heater.py").write_text(blocks["python"])
    (tmp_path / "heater.json").write_text(blocks["json"])
    for args in (("validate", "heater.json"), ("run", "heater.json", "--no-progress")):
        res = hycosim(*args, cwd=tmp_path)
        assert res.returncode == 0, res.stderr
    values = next((tmp_path / "runs").iterdir()) / "values.csv"
    last = values.read_text().splitlines()[-1].split(",")
    assert float(last[1]) == 10.0 and float(last[5]) > 15.0  # t, heater.T warmed by the supply's power


def test_a_model_file_beside_the_project_loads_by_path_and_a_broken_one_is_named(tmp_path):
    blocks = _doc_blocks("nodes.md")
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "heater.py").write_text(blocks["python"])
    doc = json.loads(blocks["json"])
    doc["nodeLists"][1]["model"] = "models/heater.py:Heater"
    (tmp_path / "p.json").write_text(json.dumps(doc))
    assert hycosim("validate", "p.json", cwd=tmp_path).returncode == 0
    doc["nodeLists"][1]["model"] = "models/missing.py:Heater"
    (tmp_path / "q.json").write_text(json.dumps(doc))
    res = hycosim("validate", "q.json", cwd=tmp_path)
    assert res.returncode == 2 and "cannot load model 'models/missing.py:Heater'" in res.stderr


_LONG = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class LongNames(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.Float64_fixed_parameter_with_a_rather_long_name = 1.0
        self.Float64_continuous_output_with_a_rather_long_name = 0.0
        self.register_variable(Real("Float64_fixed_parameter_with_a_rather_long_name",
                                    causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Real("Float64_continuous_output_with_a_rather_long_name",
                                    causality=Fmi2Causality.output))

    def do_step(self, t, h):
        return True
'''


def test_fmu_inspect_prints_whole_names_on_a_pipe(tmp_path):
    (tmp_path / "long_names.py").write_text(_LONG)
    fmu = build_model_fmu(tmp_path / "long_names.py", tmp_path / "out")
    res = hycosim("fmu", "inspect", str(fmu))  # stdout is a pipe here
    assert res.returncode == 0, res.stderr
    assert "Float64_fixed_parameter_with_a_rather_long_name" in res.stdout
    assert "Float64_continuous_output_with_a_rather_long_name" in res.stdout
    assert "…" not in res.stdout
    shutil.rmtree(tmp_path / "out")
