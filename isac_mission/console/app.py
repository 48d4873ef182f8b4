"""The console's web application (Starlette): the page, its assets, the JSON API and the
WebSocket that pushes updates.

Routes: `GET /` the page; `GET /static/...` its assets (package data, nothing from the
internet); `GET /api/snapshot` the current picture; `GET /api/replay` the traces of `view`;
`POST /api/login` {"password"}; `POST /api/control` {"command", "uav"?, "params"?,
"track"?} with the header `X-Console-Token` when security is on; `WS /ws` a snapshot, then
batches of updates.
Every request is validated (`console.requests`); a bad one gets a 4xx JSON `{"error": text,
"field": name}` whose text names the field, and nothing is sent on the bus.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from pathlib import Path
from typing import Any, Final

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket, WebSocketDisconnect

from isac_mission.console.feed import ClientFeed, batch_text
from isac_mission.console.requests import (
    ControlRequest,
    LoginRequest,
    RequestError,
    parse_body,
)
from isac_mission.console.service import ConsoleService
from isac_mission.wire.strict_json import dumps_strict

log = logging.getLogger(__name__)

STATIC: Final = Path(__file__).parent / "static"
MIN_SEND_INTERVAL_S: Final = 0.025
"""A page gets at most one batch per 25 ms (a quarter of the telemetry period at 10 Hz); what
arrives meanwhile is coalesced."""
SEND_TIMEOUT_S: Final = 10.0
"""A page that takes longer than this to accept one batch is dropped."""


def _json(obj: Any, status: int = 200) -> Response:
    return Response(dumps_strict(obj), status_code=status, media_type="application/json")


def _refusal(err: RequestError) -> JSONResponse:
    return JSONResponse({"error": err.text, "field": err.field}, status_code=err.status)


async def _body(request: Request) -> bytes:
    if request.headers.get("content-type", "").split(";")[0].strip() != "application/json":
        raise RequestError(415, "content-type: expected application/json")
    return await request.body()


def build_app(service: ConsoleService, replay: dict[str, Any] | None = None) -> Starlette:
    """The Starlette app over `service` (live) or `replay` (`view`: traces, no bus)."""

    async def index(_: Request) -> Response:
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    async def snapshot(_: Request) -> Response:
        return _json(
            {"mode": "replay" if replay is not None else "live"}
            | service.view.snapshot()
            | {"console": service.console_state()}
        )

    async def replay_data(_: Request) -> Response:
        if replay is None:
            return JSONResponse({"error": "replay: this console is live"}, status_code=404)
        return _json(replay)

    async def login(request: Request) -> Response:
        try:
            req = parse_body(LoginRequest, await _body(request))
            token = await service.login(req.password)
        except RequestError as err:
            return _refusal(err)
        return JSONResponse({"token": token})

    async def control(request: Request) -> Response:
        try:
            req = parse_body(ControlRequest, await _body(request))
            entry = service.send_control(req, request.headers.get("x-console-token"))
        except RequestError as err:
            return _refusal(err)
        service.hub.broadcast("notice", {"sent": entry})
        return JSONResponse(entry, status_code=202)

    async def ws(websocket: WebSocket) -> None:
        await websocket.accept()
        feed = ClientFeed()
        service.hub.add(feed)
        try:
            first = {"mode": "replay" if replay is not None else "live"}
            first |= service.view.snapshot() | {"console": service.console_state()}
            await websocket.send_text(dumps_strict([{"topic": "snapshot", "data": first}]))
            receiver = asyncio.create_task(_drain(websocket))
            try:
                while not receiver.done():
                    waiter = asyncio.create_task(feed.wait())
                    await asyncio.wait({waiter, receiver}, return_when=asyncio.FIRST_COMPLETED)
                    waiter.cancel()
                    batch = feed.take()
                    if batch:
                        text = batch_text(batch)
                        async with asyncio.timeout(SEND_TIMEOUT_S):
                            await websocket.send_text(text)
                    await asyncio.sleep(MIN_SEND_INTERVAL_S)
            finally:
                receiver.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await receiver
        except (WebSocketDisconnect, TimeoutError, RuntimeError, OSError):
            pass
        finally:
            service.hub.remove(feed)
            with contextlib.suppress(Exception):
                await websocket.close()

    return Starlette(
        routes=[
            Route("/", index),
            Route("/favicon.ico", lambda _: Response(status_code=204)),
            Route("/api/snapshot", snapshot),
            Route("/api/replay", replay_data),
            Route("/api/login", login, methods=["POST"]),
            Route("/api/control", control, methods=["POST"]),
            WebSocketRoute("/ws", ws),
            Mount("/static", StaticFiles(directory=STATIC), name="static"),
        ]
    )


async def _drain(websocket: WebSocket) -> None:
    """Read (and ignore) what a page sends, until it goes away."""
    while True:
        msg = await websocket.receive()
        if msg["type"] == "websocket.disconnect":
            return
        if len(msg.get("text") or msg.get("bytes") or b"") > 4096:
            log.info("console: a page sent an oversized WebSocket message; ignored")
