"""The dashboard's web app: the page, its static files, and a WebSocket feed of snapshots.

The page opens ``/ws`` and says which ports it plots (``{"select": ["node.port", ...]}``);
the feed answers a name that is no port with the closest ones, and pushes a snapshot of the
run as soon as the source has a newer one (a live run's: five times a second, whatever its
step rate), so that the page is no later than the source. Static files are served from the
package's ``static/`` folder alone (Starlette's StaticFiles refuses ``..``, absolute paths
and links out of it); nothing else on the disk is reachable from the page. Pages of other
sites cannot read the run through the user's browser (dashboard.origin).
"""

from __future__ import annotations

import asyncio
import difflib
import json
import math
import socket
import time
from pathlib import Path
from typing import Any, Protocol

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse
from starlette.middleware import Middleware
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket, WebSocketDisconnect

from hycosim.core import json_text
from hycosim.core.endpoints import listen_family
from hycosim.dashboard.changes import Watchers
from hycosim.dashboard.origin import OwnOriginOnly, is_loopback

STATIC = Path(__file__).resolve().parent / "static"
MIN_PUSH_S = 0.02  # the least time between two pushes to a page (a finished run's reader changes in bursts)
HEARTBEAT_S = 1.0  # a view is pushed at least this often (the page shows it is alive)
MAX_SELECT = 16  # ports plotted at once


class Source(Protocol):
    """What a dashboard page shows: a live run's feed or a finished run's files."""

    version: int  # changes whenever there is more to show
    watchers: Watchers  # notified at each change

    def ports(self) -> list[str]:
        """The ports the source can plot, as ``node.port``."""

    def snapshot(self, select: list[str], held: dict[str, tuple[int, int]] | None = None) -> dict[str, Any]:
        """The page's view: the source's state and each selected port's series, as what
        ``held`` (per port: the version and length of the series the page has) lacks."""


def closest(name: str, ports: list[str]) -> list[str]:
    """The port names nearest to ``name``, for a message that names no port."""
    return difflib.get_close_matches(name, ports, n=5, cutoff=0.3) or ports[:5]


def check_selection(raw: Any, ports: list[str]) -> tuple[list[str], list[dict[str, Any]]]:
    """The ports a message selects, and a problem for each entry that is none (with the closest)."""
    if type(raw) is not list:
        return [], [{"error": "a selection is a list of port names (node.port)", "closest": []}]
    chosen, problems = [], []
    for item in raw[:MAX_SELECT]:
        if type(item) is str and item in ports:
            chosen.append(item)
        else:
            name = item[:80] if type(item) is str else repr(item)[:80]
            problems.append({"error": f"no port {name!r}", "closest": closest(name, ports) if type(item) is str else []})
    if len(raw) > MAX_SELECT:
        problems.append({"error": f"at most {MAX_SELECT} ports at once", "closest": []})
    return list(dict.fromkeys(chosen)), problems


def finite(value: Any) -> Any:
    """``value`` with every NaN or infinity as None: JSON has neither, and the page parses JSON."""
    if type(value) is float:
        return value if math.isfinite(value) else None
    if type(value) is dict:
        return {str(k): finite(v) for k, v in value.items()}
    if type(value) in (list, tuple):
        return [finite(v) for v in value]
    return value


def make_app(source: Source, *, loopback_only: bool = True, allow_origins: tuple[str, ...] = ()) -> Starlette:
    """The app serving ``source`` (a dashboard.live.LiveFeed or a dashboard.finished.FinishedRun)
    to its own page alone (dashboard.origin): ``loopback_only``, for a dashboard listening on a
    loopback address, answers requests addressed to this machine only; ``allow_origins`` are
    the other sites whose pages may open the feed."""

    async def index(request: Request) -> FileResponse:
        return FileResponse(STATIC / "index.html")

    async def ports(request: Request) -> JSONResponse:
        names = source.ports()
        q = request.query_params.get("q", "")[:80]
        if not q:
            return JSONResponse({"ports": names})
        hits = [p for p in names if q.lower() in p.lower()]
        return JSONResponse({"ports": hits, "closest": [] if hits else closest(q, names)})

    async def snapshot(request: Request) -> JSONResponse:
        chosen, problems = check_selection([p for p in request.query_params.get("ports", "").split(",") if p],
                                           source.ports())
        body = await run_in_threadpool(source.snapshot, chosen)
        return JSONResponse(finite({**body, "problems": problems}))

    async def feed(ws: WebSocket) -> None:
        await ws.accept()
        wanted: Any = []  # the page's selection, checked against the ports once they are known
        said: list[dict[str, Any]] = []
        held: dict[str, tuple[int, int]] = {}  # port → (version, points) the page has: only what it lacks is sent
        incoming = asyncio.ensure_future(ws.receive_text())
        changed = source.watchers.add()
        newer = asyncio.ensure_future(changed.wait())
        shown, pushed = None, 0.0
        try:
            while True:
                done, _ = await asyncio.wait({incoming, newer}, return_when=asyncio.FIRST_COMPLETED,
                                             timeout=max(0.0, pushed + HEARTBEAT_S - time.monotonic()))
                if newer in done:
                    changed.clear()  # a change after this sets it again; one before it shows in source.version
                    newer = asyncio.ensure_future(changed.wait())
                if incoming in done:
                    text = incoming.result()
                    incoming = asyncio.ensure_future(ws.receive_text())
                    try:
                        message = json_text.loads(text)
                    except ValueError:
                        message = None
                    if type(message) is dict and "select" in message:
                        wanted, said, held, shown = message["select"], [], {}, None
                    else:
                        await ws.send_text(json.dumps({"problems": [{"error": "not a message the feed knows "
                                                                              '(send {"select": [...]})', "closest": []}]}))
                ports = source.ports()  # a live run's come with the server's first answer
                chosen, problems = check_selection(wanted, ports) if ports else ([], [])
                if problems != said:
                    said = problems
                    await ws.send_text(json.dumps({"problems": problems}))
                now = time.monotonic()
                if shown == source.version and now - pushed < HEARTBEAT_S:
                    continue
                if now - pushed < MIN_PUSH_S:
                    await asyncio.sleep(MIN_PUSH_S - (now - pushed))
                shown, pushed = source.version, time.monotonic()
                body = await run_in_threadpool(source.snapshot, chosen, held)
                for port, part in body["series"].items():
                    held[port] = (part["version"], part["from"] + len(part["t"]))
                await ws.send_text(json.dumps(finite(body), allow_nan=False, default=str))
        except (WebSocketDisconnect, RuntimeError):
            pass  # the browser went: the run is not concerned
        finally:
            incoming.cancel()
            newer.cancel()
            source.watchers.remove(changed)

    return Starlette(routes=[Route("/", index), Route("/api/ports", ports), Route("/api/snapshot", snapshot),
                             WebSocketRoute("/ws", feed), Mount("/static", StaticFiles(directory=STATIC))],
                     middleware=[Middleware(OwnOriginOnly, loopback_only=loopback_only, allowed=allow_origins)])


def bind(host: str, port: int) -> socket.socket:
    """The listening socket (port 0: any free one); OSError if the address cannot be had."""
    sock = socket.socket(listen_family(host), socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError:
        sock.close()
        raise
    sock.listen(64)
    return sock


def serve(source: Source, sock: socket.socket, allow_origins: tuple[str, ...] = ()) -> None:
    """Serve the page on ``sock`` until Ctrl-C or SIGTERM (uvicorn's own handling); on a
    loopback address to requests addressed to this machine alone."""
    import uvicorn

    app = make_app(source, loopback_only=is_loopback(str(sock.getsockname()[0])), allow_origins=allow_origins)
    config = uvicorn.Config(app, log_level="warning", lifespan="off", ws="websockets-sansio")
    uvicorn.Server(config).run(sockets=[sock])
