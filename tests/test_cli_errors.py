"""Bad arguments to the tool commands: a message naming the file or option, exit 2, no traceback."""

from __future__ import annotations

import pytest

from tests.helpers import REPO, hycosim

GRASP = str(REPO / "configs" / "grasp.json")


@pytest.mark.parametrize("args, message", [
    (["camera", "--fps", "0"], "'--fps'"),
    (["camera", "--seconds", "-1"], "'--seconds'"),
    (["camera", "--seconds", "0.1", "--annotate", "{missing}/a.mp4"], "{missing}/a.mp4: cannot write a video there"),
    (["camera", "--seconds", "0.1", "--annotate", "{tmp}/a.gif"], "{tmp}/a.gif: cannot write a video there"),
    (["train", "--eval-every", "0", "-o", "{tmp}/train"], "'--eval-every'"),
    (["krl", "controller", "--eki", "{missing}/eki.xml"], "{missing}/eki.xml: cannot read"),
    (["scene", "fmus", "-o", "{file}/fmus"], "{file}/fmus: cannot write the FMUs there"),
    (["scene", "reach", GRASP, "-o", "{missing}/reach.png"], "{missing}/reach.png: No such file or directory"),
])
def test_bad_arguments_are_named(tmp_path, args, message):
    (tmp_path / "a-file").write_text("not a folder")
    where = {"tmp": tmp_path, "missing": tmp_path / "missing", "file": tmp_path / "a-file"}
    res = hycosim(*(a.format(**where) for a in args))
    assert res.returncode == 2, res.stderr
    assert message.format(**where) in res.stderr
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "train").exists() and not (tmp_path / "a.gif").exists()
