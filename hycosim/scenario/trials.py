"""The paper's trials (Table 2), rerun: ``hycosim trials --angles 30 40 50 60 --trials 20``.

Per trial: the full distributed co-simulation (server and every node as processes over
Zenoh on loopback: the rod twin and the robot scene, as FMUs by default (the shipped ``hycosim/scenario/configs/grasp-paper.json``)
or as Python nodes, the policy, and, with correction on, the camera watching the emulated
physical rod), then the robot's path exported as
EthernetKRL files and streamed over TCP to the emulated controller, which executes it
against the physical rod. The physical rod differs from the twin per trial (length ±3 %,
release angle ±2°, damping ±30 %, seeded), as a real rod differs from its model.
Measured: grasp distance error (TCP to the rod's grasp point when the jaws close, mm),
execution time (program start to grasp, s) and success (the jaws closed on the rod).
"""

from __future__ import annotations

import csv
import json
import math
import threading
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from hycosim.scenario.krl.controller import EmulatedController, parse_ack, stream_program
from hycosim.scenario.krl.eki import EkiConfig
from hycosim.scenario.krl.export import export
from hycosim.scenario.rod.model import RodParams
from hycosim.core import signals
from hycosim.core.config import parse_project
from hycosim.core.folders import make_folder

PAPER = {30: (3.2, 14.8, 95), 40: (3.8, 15.6, 95), 50: (5.0, 15.4, 90), 60: (5.8, 16.6, 80)}


def paper_figures(angle: float) -> tuple[float, float, int] | None:
    """The paper's Table 2 row for a release angle (error mm, time s, success %), or None for an
    angle it did not try (30.5° is not 30°)."""
    return PAPER.get(int(angle)) if float(angle).is_integer() else None


def figure_text(value: float, spec: str) -> str:
    """A table's figure, or "–" where there is none (no grasp to measure, no paper row)."""
    return "–" if math.isnan(value) else format(value, spec)
# The scenario's project files ship in the package (package data), so an installed wheel runs the trials.
CONFIGS = Path(__file__).resolve().parent / "configs"
# Where the rod and robot-scene FMUs are built when no other folder is given (beside the run, as
# `hycosim scene fmus` builds them): never inside the installed package.
FMU_DIR = Path("build") / "fmus"


@dataclass
class TrialResult:
    """One trial (see the module's text): the release angle, whether the camera corrected the twin,
    whether and how precisely and quickly the controller grasped the physical rod, whether the
    simulation grasped, the run's folder, the physical rod's draw, and why the trial could not run where
    it could not."""

    angle: float
    trial: int
    correction: bool
    success: bool
    grasp_error_mm: float | None
    execution_time_s: float | None
    simulated_grasp: bool
    run_dir: str
    physical_length: float
    physical_angle_deg: float
    physical_damping: float
    nodes: str = "fmu"  # how the rod and the robot scene ran: as FMUs or as Python nodes
    error: str = ""  # why the trial could not be carried out (it counts as not grasped)


def physical_rod(angle: float, seed: int) -> RodParams:
    """The physical rod of a trial: the twin's, drawn from ``seed`` to differ (length ±3 %, release
    angle ±2° about ``angle``, damping ±30 %)."""
    rng = np.random.default_rng(seed)
    return RodParams(length=0.6 * (1 + rng.uniform(-0.03, 0.03)),
                     initial_angle=math.radians(angle + rng.uniform(-2.0, 2.0)),
                     damping=0.002 * rng.uniform(0.7, 1.3))


def trial_seed(angle: float, trial: int, seed_base: int = 1000) -> int:
    """The seed of one trial: its physical rod and its camera noise."""
    return seed_base + int(angle) * 100 + trial


NODE_KINDS = ("fmu", "python")
# The twin's observer rate with the camera on (1/s). Measured offline on 100 physical rods per
# angle apart from the trials' (seed base 9000), the twin replayed on the camera pipeline's own
# measurements: at the grasp, 16/s left the twin 0.51/0.55/0.64/0.89 mm rms from the physical
# grasp point at 30/40/50/60° (12/s: 0.56/0.63/0.82/1.03; 20/s: 0.52/0.58/0.59/0.88). Slower
# rates lag the rod's own dynamics, which differ from the twin's; faster ones follow the noise.
OBSERVER_GAIN = 16.0
# The shipped project each trial starts from, by node kind and driver: the rod and the robot
# scene as FMUs (the paper's design) or as Python nodes; the policy or the scripted controller.
_BASES = {("fmu", "policy"): "grasp-paper.json", ("fmu", "reference"): "grasp-fmu.json",
          ("python", "policy"): "grasp-policy.json", ("python", "reference"): "grasp.json"}
_CAMERA_LINK = {"from": "camera", "to": "rod", "pairs": [["meas_angle", "meas_angle"], ["meas_t", "meas_t"],
                                                         ["meas_valid", "meas_valid"]]}


def _port_name(port) -> str:
    return port if isinstance(port, str) else port["name"]


class ScenarioMissing(RuntimeError):
    """A shipped scenario file that is not there (a damaged install); names the file."""


def scenario_file(nodes: str, driver: str) -> Path:
    """The shipped project file of that node kind and driver; ScenarioMissing if it is gone."""
    path = CONFIGS / _BASES[nodes, driver]
    if not path.is_file():
        raise ScenarioMissing(f"{path}: the scenario's project file is missing from the installed package "
                              "(reinstall hycosim)")
    return path


def trial_project(angle: float, physical: RodParams, correction: bool, driver: str, seed: int,
                  nodes: str = "fmu", fmu_dir: Path = FMU_DIR) -> dict:
    """The project JSON of one trial: the shipped scenario of that node kind and driver, released
    at ``angle``, with the camera on the trial's physical rod (with correction) or without it;
    the scene FMUs (``nodes='fmu'``) are taken from ``fmu_dir``."""
    base = json.loads(scenario_file(nodes, driver).read_text())
    base["projectName"] = f"trial-{angle:g}-{seed}"
    camera = {"source": "emulated", "noise_sigma": 25, "seed": seed,
              "physical": {"length": physical.length, "damping": physical.damping,
                           "initial_angle_deg": math.degrees(physical.initial_angle)}}
    for node in base["nodeLists"]:
        if "fmu" in node:  # the trial's file lies elsewhere than the shipped one: the FMUs by absolute path
            node["fmu"] = str((fmu_dir / Path(node["fmu"]).name).resolve())
        params = node.get("parameters")
        if node["nodeName"] == "camera":
            node["parameters"] = dict(params, **camera)
        elif "fmu" in node and "initial_angle" in params:  # the rod FMU: radians, as FMI variables are
            node["parameters"] = dict(params, initial_angle=math.radians(angle))
        elif params is not None and "fmu" not in node:
            node["parameters"] = dict(params, initial_angle_deg=angle)
    rod = base["nodeLists"][0]
    rod["parameters"]["observer_gain"] = OBSERVER_GAIN if correction else 0.0
    if "meas_t" not in map(_port_name, rod["input"]):
        rod["input"].append("meas_t")
    has_camera = any(n["nodeName"] == "camera" for n in base["nodeLists"])
    if correction and not has_camera:
        base["nodeLists"].append({
            "nodeName": "camera", "UID": 9, "model": "camera", "async": True, "rate": 60, "parameters": camera,
            "output": ["meas_angle", "meas_omega", "meas_t", "meas_conf", {"name": "meas_valid", "type": "Boolean"},
                       "latency", "true_angle"]})
        base["linkLists"].append(dict(_CAMERA_LINK))
    elif not correction and has_camera:
        base["nodeLists"] = [n for n in base["nodeLists"] if n["nodeName"] != "camera"]
        base["linkLists"] = [link for link in base["linkLists"] if not str(link["from"]).startswith("camera")]
    base["nodeNum"], base["linkNum"] = len(base["nodeLists"]), len(base["linkLists"])
    # Paced at real time: the camera lives on the wall clock, and rendering 60 frames per
    # second already takes a third of a core here (at twice real time it fell behind on
    # 2 cores, and late measurements cost the twin up to 2° at the grasp).
    base["coSimulation"] = {"stepSize": 0.01, "stopTime": 2.6, "realTime": 1.0, "stepTimeout": 20.0,
                            "attachTimeout": 60.0}
    return base


def run_trial(angle: float, trial: int, out: Path, correction: bool = True, driver: str = "policy",
              seed_base: int = 1000, nodes: str = "fmu", fmu_dir: Path = FMU_DIR) -> TrialResult:
    """Run one trial into ``out`` (co-simulation, export, the emulated controller) and return its
    result; RuntimeError naming the trial where the co-simulation failed."""
    from hycosim.embedded import run_embedded

    seed = trial_seed(angle, trial, seed_base)
    physical = physical_rod(angle, seed)
    doc = trial_project(angle, physical, correction, driver, seed, nodes, fmu_dir)
    folder = out / f"{angle:g}deg-{trial:02d}"
    folder.mkdir(parents=True, exist_ok=True)
    cfg = folder / "project.json"
    cfg.write_text(json.dumps(doc, indent=1))
    loaded = parse_project(doc, str(cfg), cfg.resolve())
    result = run_embedded(loaded, cfg, runs_dir=folder / "runs", show_progress=False)
    if result.code == 130:
        raise KeyboardInterrupt  # the launcher stopped its processes; the trials stop too
    if result.code:
        raise RuntimeError(f"trial {angle:g}° #{trial}: co-simulation failed: {result.message}")
    files = export(result.run_dir, folder / "krl")
    controller = EmulatedController(EkiConfig(), physical, port=0)
    thread = threading.Thread(target=controller.serve_forever, daemon=True)
    thread.start()
    try:
        answer = parse_ack(stream_program("127.0.0.1", controller.address[1], files["frames"].read_text()))
    finally:
        controller.stop()
        thread.join(timeout=5)
    events = (result.run_dir / "events.jsonl").read_text()
    return TrialResult(angle, trial, correction, answer["grasped"], answer["grasp_error_mm"],
                       answer["grasp_time_s"], '"to": "grasp"' in events, str(result.run_dir),
                       physical.length, math.degrees(physical.initial_angle), physical.damping, nodes)


def summarise(results: list[TrialResult]) -> dict[float, dict[str, float]]:
    """Per release angle: the trials, the share that grasped (%), and the mean grasp error (mm) and
    execution time (s) of those that did."""
    table = {}
    for angle in sorted({r.angle for r in results}):
        rs = [r for r in results if r.angle == angle]
        ok = [r for r in rs if r.success]
        table[angle] = {
            "trials": len(rs), "success_pct": 100 * len(ok) / len(rs),
            "error_mm": float(np.mean([r.grasp_error_mm for r in ok])) if ok else float("nan"),
            "time_s": float(np.mean([r.execution_time_s for r in ok])) if ok else float("nan"),
        }
    return table


def write_csv(results: list[TrialResult], out: Path) -> Path:
    """Write the results as ``trials.csv`` in ``out`` (through a temporary file); returns its path."""
    csv_path = out / "trials.csv"
    tmp = csv_path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(asdict(results[0]).keys()))
        w.writeheader()
        for r in results:
            w.writerow(asdict(r))
    tmp.replace(csv_path)
    return csv_path


def write_outputs(results: list[TrialResult], out: Path) -> tuple[Path, Path]:
    """Write ``trials.csv`` and the ``trials.png`` figure in ``out``; returns both paths."""
    return write_csv(results, out), plot(results, out / "trials.png")


def plot(results: list[TrialResult], path: Path) -> Path:
    """Plot the trials' success, grasp error and execution time per angle beside the paper's (Table 2),
    and one grasping trial's run, into ``path``; returns ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hycosim.master.report import read_columns

    table = summarise(results)
    angles = list(table)
    fig, axes = plt.subplots(1, 4, figsize=(16, 4))
    x = np.arange(len(angles))
    for ax, key, label, paper_i in ((axes[0], "success_pct", "success (%)", 2), (axes[1], "error_mm", "grasp error (mm)", 0),
                                    (axes[2], "time_s", "execution time (s)", 1)):
        ax.bar(x - 0.2, [table[a][key] for a in angles], 0.4, label="hycosim")
        ax.bar(x + 0.2, [(paper_figures(a) or (np.nan,) * 3)[paper_i] for a in angles], 0.4,
               label="paper (real robot)")
        ax.set_xticks(x, [f"{a:g}°" for a in angles])
        ax.set_title(label)
        ax.legend(fontsize=7)
    example = next((r for r in results if r.success), next((r for r in results if not r.error), None))
    ax = axes[3]
    if example is None:  # no trial ran: nothing to draw
        ax.set_title("no trial ran")
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        plt.close(fig)
        return path
    data = read_columns(Path(example.run_dir), ["rod.angle", "robot.dist"])
    t = np.array(data["t"])
    ax.plot(t, np.degrees(data["rod.angle"]), label="rod twin angle (°)")
    from hycosim.scenario.rod.model import RodModel

    physical = RodModel(RodParams(length=example.physical_length, damping=example.physical_damping,
                                  initial_angle=math.radians(example.physical_angle_deg)))
    truth = []
    for k, tk in enumerate(t):
        if k:
            physical.advance(tk - t[k - 1])
        truth.append(math.degrees(physical.angle))
    ax.plot(t, truth, "--", label="physical rod, free (°)")
    ax2 = ax.twinx()
    ax2.plot(t, 1000 * np.array(data["robot.dist"]), color="tab:red", lw=0.8, label="TCP to grasp point (mm)")
    ax2.set_ylabel("mm")
    ax.set_xlabel("t (s)")
    ax.set_title(f"trial {example.angle:g}° #{example.trial}")
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


class TrialsInterrupted(Exception):
    """Ctrl-C (or SIGTERM, SIGHUP) during the trials: ``results`` holds the trials finished
    before it (in ``trials.csv``), ``stop`` the interruption."""

    def __init__(self, results: list[TrialResult], stop: KeyboardInterrupt):
        super().__init__(f"{signals.describe(stop)} after {len(results)} trial{'' if len(results) == 1 else 's'}")
        self.results = results
        self.stop = stop


def _trial_or_failure(angle: float, trial: int, out: Path, correction: bool, driver: str, nodes: str,
                      fmu_dir: Path) -> TrialResult:
    """One trial; one that fails to run is its result too: not grasped, with its error."""
    try:
        return run_trial(angle, trial, out, correction, driver, nodes=nodes, fmu_dir=fmu_dir)
    except (RuntimeError, OSError, ValueError) as exc:
        return _not_run(angle, trial, out, correction, nodes, str(exc))


def _not_run(angle: float, trial: int, out: Path, correction: bool, nodes: str, error: str) -> TrialResult:
    physical = physical_rod(angle, trial_seed(angle, trial))
    return TrialResult(angle, trial, correction, False, None, None, False, str(out / f"{angle:g}deg-{trial:02d}"),
                       physical.length, math.degrees(physical.initial_angle), physical.damping, nodes, error=error)


def _trial_on_worker(angle: float, trial: int, out: Path, correction: bool, driver: str, nodes: str,
                     fmu_dir: Path) -> TrialResult:
    """One trial as a Dask worker runs it: a trial stopped by Ctrl-C is a result too (a worker
    is not the place for KeyboardInterrupt). Its logs go where the serial trials' go."""
    from hycosim.core import logs

    logs.configure(out / "trials.log.jsonl")
    try:
        return _trial_or_failure(angle, trial, out, correction, driver, nodes, fmu_dir)
    except KeyboardInterrupt as stop:
        return _not_run(angle, trial, out, correction, nodes, signals.describe(stop))


# How long a worker's trial nodes have to end by their server's STOP before they are told too.
_NODES_FOLLOW_S = 3.0


def _stop_trials_here() -> int:
    """On a worker: Ctrl-C to the hycosim processes the worker started (a trial's server and
    nodes), as a serial trial takes it: the server writes its records and the nodes follow."""
    import os
    import signal

    import psutil

    servers, nodes = [], []
    for child in psutil.Process(os.getpid()).children():
        try:
            command = child.cmdline()
        except psutil.Error:  # ended meanwhile, or not ours to look at
            continue
        if "hycosim" in command:
            (servers if "server" in command else nodes).append(child)
    # The servers alone first; their nodes end on the STOP each server sends as it stops. A node
    # told too ends at once, and its launcher, in this worker, which was told nothing, takes a
    # node that ended by Ctrl-C before its server for a failed node and records the run failed.
    stopped = 0
    for child in servers:
        try:
            child.send_signal(signal.SIGINT)
            stopped += 1
        except psutil.Error:  # ended meanwhile, or not ours to signal
            pass
    _, left = psutil.wait_procs(nodes, timeout=_NODES_FOLLOW_S if servers else 0)
    for child in left:  # a node whose server had not started, or did not stop it
        try:
            child.send_signal(signal.SIGINT)
            stopped += 1
        except psutil.Error:
            pass
    return stopped


def run_trials(angles: list[float], trials: int, out: Path, correction: bool = True, driver: str = "policy",
               progress: Callable[[TrialResult], None] | None = None, nodes: str = "fmu",
               fmu_dir: Path = FMU_DIR, workers: int | None = None, scheduler: str | None = None) -> list[TrialResult]:
    """Every trial; one that fails to run is recorded as not grasped, with its error, and the
    others go on. In order, one after the other, or, with ``workers`` (a local Dask cluster of
    that many processes) or ``scheduler`` (a Dask scheduler's address, whose workers see the same
    files), as many at a time as there are workers, in the order they end. The scene FMUs
    (``nodes='fmu'``) are built into ``fmu_dir`` when missing or older than their sources;
    ScenarioMissing if the shipped scenario is not there; ValueError for an angle given twice;
    SweepError where Dask is missing or the scheduler cannot be reached. ``trials.csv`` is rewritten after each trial, in the trials'
    order. Ctrl-C stops them: TrialsInterrupted carries the finished ones (the interrupted
    trials are not counted)."""
    from hycosim.core import logs

    scenario_file(nodes, driver)  # a damaged install is named before anything runs
    if len(set(angles)) != len(angles):
        raise ValueError(f"angles {angles}: an angle given twice (a trial is its angle and number)")
    distributed = workers is not None or scheduler is not None
    if distributed:
        from hycosim.ensemble.cluster import require_ensemble

        require_ensemble("hycosim trials --workers")
    make_folder(out)
    logs.configure(out / "trials.log.jsonl")
    if nodes == "fmu":
        from hycosim.scenario.scene_fmus import ensure_scene_fmus

        ensure_scene_fmus(fmu_dir)
    order = {(angle, i): n for n, (angle, i) in enumerate((a, i) for a in angles for i in range(trials))}
    results: list[TrialResult] = []

    def finished(r: TrialResult) -> None:
        results.append(r)
        results.sort(key=lambda x: order[x.angle, x.trial])
        write_csv(results, out)
        if progress:
            progress(r)

    try:
        if distributed:
            _run_on_dask(list(order), out, correction, driver, nodes, fmu_dir, workers, scheduler, finished)
        else:
            for angle, i in order:
                finished(_trial_or_failure(angle, i, out, correction, driver, nodes, fmu_dir))
    except KeyboardInterrupt as stop:
        raise TrialsInterrupted(results, stop) from None
    return results


def _run_on_dask(todo: list[tuple[float, int]], out: Path, correction: bool, driver: str, nodes: str,
                 fmu_dir: Path, workers: int | None, scheduler: str | None,
                 finished: Callable[[TrialResult], None]) -> None:
    """Each trial a job on a Dask worker; a worker that dies is its trial's error. Ctrl-C on a
    local cluster stops the trials running on it as it stops a serial one."""
    from hycosim.ensemble.cluster import dask_client, each_ended

    out, fmu_dir = out.resolve(), fmu_dir.resolve()  # a worker's working folder need not be ours
    jobs = [((angle, i), (angle, i, out, correction, driver, nodes, fmu_dir)) for angle, i in todo]
    with dask_client(workers, scheduler) as client:
        try:
            for (angle, i), result, error in each_ended(client, _trial_on_worker, jobs):
                finished(result if error is None else
                         _not_run(angle, i, out, correction, nodes, f"{type(error).__name__}: {error}"))
        except KeyboardInterrupt:
            if scheduler is None:  # a shared cluster's workers run others' processes too: left alone
                try:
                    client.run(_stop_trials_here)
                except Exception:  # noqa: BLE001 - a worker that died meanwhile: nothing of its to stop
                    pass
            raise
