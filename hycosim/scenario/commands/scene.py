"""The paper's scenario: ``hycosim scene`` (reach, FMUs), the camera alone, the trials."""

from __future__ import annotations

import math
import signal
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.table import Table
from rich.text import Text

from hycosim.cli.extras import require_extra
from hycosim.cli.options import finite
from hycosim.cli.output import err, fail, out
from hycosim.cli.projects import load
from hycosim.core import signals

app = typer.Typer()
scene_app = typer.Typer(no_args_is_help=True, help="The robot scene: reachability, FMUs.")


@scene_app.command("reach")
def scene_reach(
    file: Path,
    node: Annotated[str, typer.Option(help="the robot node whose parameters place base and rod")] = "robot",
    output: Annotated[Optional[Path], typer.Option("-o", "--output", help="PNG to write")] = None,
) -> None:
    """Which part of the rod's swing the robot can reach from its base placement: table and PNG."""
    require_extra("scenario", "hycosim scene reach")
    from hycosim.scenario.robot.node import scene_parameter_problems, scene_params
    from hycosim.scenario.robot.reach import analyse_reach, plot_reach

    loaded = load(file)
    try:
        spec = loaded.project.node(node)
    except KeyError:
        fail(f"{file}: no node named {node!r} (use --node)")
    wrong = scene_parameter_problems(spec.parameters)
    if wrong:
        fail(f"{file}: node {node!r}: {'; '.join(wrong)}")
    report = analyse_reach(scene_params(spec.parameters))
    table = Table(title=f"reach of {node!r} over the rod's swing")
    for col in ("rod angle (°)", "grasp point (m)", "reachable", "IK error (mm)", "A1…A6 (°)", "limit margin (°)"):
        table.add_column(col)
    for p in report.points:
        table.add_row(f"{p.angle_deg:+.1f}", "({:.3f}, {:.3f}, {:.3f})".format(*p.position),
                      "yes" if p.reachable else "[red]no[/red]", f"{p.position_error_mm:.2f}",
                      " ".join(f"{v:.0f}" for v in p.q_deg), f"{p.limit_margin_deg:.0f}")
    out.print(table)
    rng = report.reachable_range()
    out.print(("reachable from {:+.1f}° to {:+.1f}°".format(*rng) if rng else "no part of the swing is reachable")
              + "; share of the swing reachable: " + ", ".join(
                  f"±{a}°: {100 * report.fraction_of_swing(a):.0f} %" for a in (30, 40, 50, 60)), highlight=False)
    png = plot_reach(report, output or Path(f"reach-{loaded.name}.png"))
    out.print(f"wrote {png}", highlight=False)


@scene_app.command("fmus")
def scene_fmus(output: Annotated[Path, typer.Option("-o", "--output")] = Path("build/fmus")) -> None:
    """Build the rod and robot-scene FMUs (pythonfmu) into a folder."""
    require_extra("scenario", "hycosim scene fmus")
    from fmpy.validation import validate_fmu

    from hycosim.scenario.scene_fmus import build_scene_fmus

    try:
        built = build_scene_fmus(output)
    except OSError as exc:
        fail(f"{output}: cannot write the FMUs there ({exc.strerror or exc})")
    for name, path in built.items():
        problems = validate_fmu(str(path))
        out.print(f"{name}: {path} ({'valid' if not problems else 'INVALID: ' + '; '.join(problems)})", highlight=False)
        if problems:
            raise typer.Exit(4)


@app.command()
def camera(
    source: Annotated[str, typer.Option(help="'emulated', a video file, or a camera device index")] = "emulated",
    annotate: Annotated[Optional[Path], typer.Option(help="write the frames with the detected rod drawn, .mp4 or .avi")] = None,
    seconds: Annotated[float, typer.Option(min=0.0, callback=finite,
                                           help="how much to process (emulated: simulated seconds)")] = 3.0,
    calibration: Annotated[Optional[Path], typer.Option(help="calibration JSON (real sources)")] = None,
    initial_angle: Annotated[float, typer.Option(callback=finite,
                                                 help="emulated rod's release angle, degrees")] = 45.0,
    noise: Annotated[float, typer.Option(min=0.0, callback=finite,
                                         help="emulated image noise σ (grey levels)")] = 25.0,
    fps: Annotated[float, typer.Option(min=1.0, max=1000.0, callback=finite, help="emulated frame rate")] = 60.0,
) -> None:
    """Run the camera node alone: detect the rod in each frame and summarise (and annotate)."""
    require_extra("scenario", "hycosim camera")
    from hycosim.scenario.camera.calibration import Calibration, CalibrationError
    from hycosim.scenario.camera.emulated import CameraSetup, EmulatedRodCamera
    from hycosim.scenario.camera.sources import CameraError, DeviceSource, VideoFileSource, device_number
    from hycosim.scenario.camera.survey import AnnotatedVideo, VideoWriteError, survey
    from hycosim.scenario.rod.model import RodParams

    try:
        if source == "emulated":
            emu = EmulatedRodCamera(RodParams(initial_angle=math.radians(initial_angle)),
                                    CameraSetup(noise_sigma=noise, fps=fps))
            frames = emu.frames_until(seconds)
            cal = emu.calibration
        else:
            if calibration is None:
                fail("a real source needs --calibration FILE")
            cal = Calibration.load(calibration)
            device = device_number(source)
            src = DeviceSource(device) if device is not None else VideoFileSource(Path(source))
            frames = []
            for frame in src.frames():
                if frame.t > seconds:
                    break
                frames.append(frame)
            src.close()
    except (CameraError, CalibrationError) as exc:
        fail(str(exc), 3)
    video = AnnotatedVideo(annotate, fps if source == "emulated" else 30.0) if annotate is not None else None
    try:
        found = survey(frames, cal, video)
    except VideoWriteError as exc:
        fail(str(exc))
    out.print(f"{found.frames} frames ({found.dropped} dropped), {found.detected} confident detections, "
              f"detection {found.detection_frames_per_s:,.0f} frames/s", highlight=False)
    if found.errors_deg:
        out.print(f"angle error against the emulated rod: mean {sum(found.errors_deg) / len(found.errors_deg):.3f}°, "
                  f"max {max(found.errors_deg):.3f}°", highlight=False)
    if annotate is not None:
        out.print(f"wrote {annotate}", highlight=False)


@app.command()
def trials(
    angles: Annotated[str, typer.Option(help="initial angles in degrees, each in (0, 90): --angles 30 40 50 60")] = "30,40,50,60",
    n: Annotated[int, typer.Option("--trials", min=1, help="trials per angle")] = 20,
    correction: Annotated[bool, typer.Option("--correction/--no-correction", help="camera correction of the twin")] = True,
    driver: Annotated[str, typer.Option(help="'policy' (pretrained DDPG) or 'reference' (scripted)")] = "policy",
    nodes: Annotated[str, typer.Option(help="the rod and the robot scene as 'fmu' (the FMUs `hycosim scene fmus` "
                                            "builds, built when missing) or as 'python' nodes")] = "fmu",
    output: Annotated[Path, typer.Option("-o", "--output")] = Path("runs/trials"),
    fmus: Annotated[Path, typer.Option(help="where the rod and robot-scene FMUs are, built there when missing "
                                            "or older than hycosim's sources")] = Path("build/fmus"),
    workers: Annotated[Optional[int], typer.Option(min=1, help="run the trials on a local Dask cluster of this "
                                                                "many worker processes (the ensemble extra)")] = None,
    scheduler: Annotated[Optional[str], typer.Option(help="run them on a running Dask scheduler's workers, "
                                                           "tcp://host:8786 (they must see the same files)")] = None,
) -> None:
    """Rerun the paper's trials: co-simulation, EthernetKRL export, emulated controller, Table 2."""
    require_extra("scenario", "hycosim trials")
    from hycosim.scenario.trials import (NODE_KINDS, ScenarioMissing, TrialsInterrupted, figure_text, paper_figures,
                                run_trials, summarise, write_outputs)

    from hycosim.ensemble.variants import SweepError

    if driver not in ("policy", "reference"):
        fail("--driver is 'policy' or 'reference'")
    if workers is not None and scheduler is not None:
        fail("--workers and --scheduler: a local cluster or one by address, not both")
    if nodes not in NODE_KINDS:
        fail(f"--nodes is {' or '.join(map(repr, NODE_KINDS))}")
    try:
        angle_list = [float(a) for a in angles.replace(",", " ").split()]
    except ValueError:
        fail(f"--angles {angles!r}: give numbers in degrees")
    outside = [a for a in angle_list if not 0.0 < a < 90.0]
    if not angle_list or outside:
        # The rod is released from rest on one side, below the horizontal (the paper: 30° to 60°).
        fail(f"--angles {angles!r}: "
             + (f"{', '.join(f'{a:g}°' for a in outside)} outside (0°, 90°)" if outside else "no angle given"))
    twice = sorted({a for a in angle_list if angle_list.count(a) > 1})
    if twice:  # a trial is its angle and number: its folder and its row would be the other's
        fail(f"--angles {angles!r}: {', '.join(f'{a:g}°' for a in twice)} given twice; give each angle once "
             "(--trials sets how many of each)")
    def progress(r) -> None:
        if r.error:
            err.print(Text.assemble(f"{r.angle:g}° #{r.trial}: ", ("not run", "red"), f": {r.error}"), highlight=False)
            return
        err.print(f"{r.angle:g}° #{r.trial}: {'grasped' if r.success else 'missed'}"
                  + (f", {r.grasp_error_mm:.1f} mm, {r.execution_time_s:.2f} s" if r.success else ""), highlight=False)

    interrupted = None
    try:
        results = run_trials(angle_list, n, output, correction, driver, progress, nodes, fmus, workers, scheduler)
    except (ScenarioMissing, SweepError) as exc:
        fail(str(exc))
    except TrialsInterrupted as exc:
        # Ctrl-C again must not cut short the table and files of the finished trials (a second or two).
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        interrupted, results = exc, exc.results
        if not results:
            fail(f"{exc}; nothing to tabulate", 130)
    csv_path, png = write_outputs(results, output)
    table = Table(title=f"grasping trials ({'with' if correction else 'without'} camera correction, {driver}, "
                        f"rod and robot as {'FMUs' if nodes == 'fmu' else 'Python nodes'}): "
                        "grasp distance error, execution time, success")
    for col in ("angle", "mm", "s", "success", "paper mm", "paper s", "paper %"):
        table.add_column(col, no_wrap=True)
    for angle, row in summarise(results).items():
        p = paper_figures(angle) or (float("nan"),) * 3
        table.add_row(f"{angle:g}°", figure_text(row["error_mm"], ".1f"), figure_text(row["time_s"], ".2f"),
                      f"{row['success_pct']:.0f} % of {row['trials']}",
                      *(figure_text(v, "g") for v in p))
    out.print(table)
    out.print(f"wrote {csv_path} and {png}", highlight=False)
    if interrupted is not None:
        err.print(f"[red]error:[/red] {interrupted} of {len(angle_list) * n}: the table holds those", highlight=False)
        raise typer.Exit(signals.exit_code(interrupted.stop))
    failed = [r for r in results if r.error]
    if failed:
        fail(f"{len(failed)} of {len(results)} trials could not be run (counted as missed): "
             + "; ".join(f"{r.angle:g}° #{r.trial}" for r in failed), 3)
