"""``hycosim krl``: KUKA EthernetKRL export of a run's path; an emulated controller."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Optional

import typer

from hycosim.cli.extras import require_extra
from hycosim.cli.options import finite
from hycosim.cli.output import err, fail, out
from hycosim.core.endpoints import Address

app = typer.Typer(no_args_is_help=True, help="KUKA EthernetKRL: export a run's path; an emulated controller.")


@app.command("export")
def krl_export(run_dir: Path, output: Annotated[Path, typer.Option("-o", "--output")] = Path("krl")) -> None:
    """Write the EKI configuration, the KRL program (Table 1) and the XML frame stream of a run."""
    from hycosim.scenario.krl.export import ExportError, export

    try:
        files = export(run_dir, output)
    except ExportError as exc:
        fail(str(exc))
    for kind, path in files.items():
        out.print(f"{kind}: {path}", highlight=False)


@app.command("controller")
def krl_controller(
    eki: Annotated[Path, typer.Option(help="the EKI configuration (port, RECEIVE elements)")],
    port: Annotated[Optional[int], typer.Option(min=1, max=65535, help="override the EKI file's port")] = None,
    host: Annotated[str, typer.Option(help="address to listen on")] = "127.0.0.1",
    length: Annotated[float, typer.Option(min=0.05, callback=finite, help="physical rod length (m)")] = 0.6,
    angle: Annotated[float, typer.Option(callback=finite, help="physical rod release angle (deg)")] = 40.0,
    programs: Annotated[int, typer.Option(min=0, help="stop after this many programs (0: run until stopped)")] = 0,
) -> None:
    """Listen as the robot's EKI endpoint and execute programs against the emulated physical rod."""
    require_extra("scenario", "hycosim krl controller")
    from hycosim.scenario.krl.controller import EmulatedController
    from hycosim.scenario.krl.eki import EkiConfig, EkiError
    from hycosim.scenario.rod.model import RodParams

    try:
        config = EkiConfig.parse(eki.read_bytes(), str(eki))
    except OSError as exc:
        fail(f"{eki}: cannot read ({exc.strerror or exc})")
    except EkiError as exc:
        fail(str(exc))
    try:
        controller = EmulatedController(config, RodParams(length=length, initial_angle=math.radians(angle)),
                                        host=host, port=port)
    except OSError as exc:
        fail(f"cannot listen on {Address(host, port or config.port)} ({exc.strerror or exc})", 3)
    out.print(f"emulated KUKA controller listening on {Address(host, controller.address[1])} ({eki.name})",
              highlight=False)
    try:
        while programs == 0 or len(controller.results) < programs:
            conn, peer = controller.listener.accept()
            with conn:
                result = controller.handle(conn, str(peer))
            if result is not None:
                out.print(f"program ended: {'grasped' if result.grasped else 'missed'}, error "
                          f"{result.grasp_error_mm if result.grasp_error_mm is not None else '-'} mm, "
                          f"{result.frames} frames, {len(result.rejected)} rejected", highlight=False)
            else:
                err.print(f"rejected: {controller.errors[-1]}", highlight=False)
    finally:  # Ctrl-C, SIGTERM or SIGHUP: main() ends with the signal's status
        controller.stop()
