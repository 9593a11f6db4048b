"""The rig console's web application (docs/console.md): the page, its static files and the JSON API over
`uwlab.explore.console_rig`, behind the explorer's guard (`uwlab.explore.security.Guard`: Host allow-list, token
beyond the loopback, JSON bodies, Origin and XSRF checks on every POST).

**Sessions**: every client gets a session cookie (``uwlab_console``, HttpOnly, SameSite=Strict). One session at a
time controls the rig: the first to load the page or send a POST while nobody controls it; it keeps control while it
is active (a request or an open event stream within `CONTROL_IDLE_S`) or until it sends ``POST /api/control``
``{"release": true}``. Every other session watches: its POSTs are refused with 403 (it may take control with
``POST /api/control`` once control is free).

Bad input (`UwlabError`) answers 422 ``{"error": "<one line>", "key": ...}``; an unknown run 404.
"""

from __future__ import annotations

import asyncio
import contextlib
import secrets
import time
from http.cookies import SimpleCookie
from typing import Any

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import FileResponse, Response, StreamingResponse
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles
from starlette.templating import Jinja2Templates

from uwlab import __version__
from uwlab.errors import ConfigError, UwlabError
from uwlab.explore.app import HERE, JSON, PLOTLY_JS, _body, error_response
from uwlab.explore.console_rig import Live, Runs
from uwlab.explore.security import Access, Guard, Message, Receive, Scope, Send
from uwlab.jsonable import dumps

SESSION_COOKIE = "uwlab_console"
CONTROL_IDLE_S = 30.0
STREAM_GRACE_S = 5.0  # a page's stream may reconnect within this long and keep control
STREAM_IDLE_S = 0.5  # an event stream with nothing to tell looks this often whether its page has gone


class Control:
    """Which session controls the rig (module docstring)."""

    def __init__(self) -> None:
        self.holder: str | None = None
        self.seen: dict[str, float] = {}  # a session's last request
        self.streams: dict[str, int] = {}  # its open event streams
        self.left: dict[str, float] = {}  # when its last event stream closed

    def touch(self, session: str) -> None:
        self.seen[session] = time.monotonic()

    def _free(self) -> bool:
        if self.holder is None:
            return True
        if self.streams.get(self.holder, 0) > 0:
            return False
        now, seen = time.monotonic(), self.seen.get(self.holder, 0.0)
        left = self.left.get(self.holder)
        return now - seen > CONTROL_IDLE_S or (left is not None and now - max(seen, left) > STREAM_GRACE_S)

    def claim(self, session: str) -> bool:
        """Take control when it is free; True when ``session`` controls the rig."""
        if self.holder != session and self._free():
            self.holder = session
        return self.holder == session

    def release(self, session: str) -> None:
        if self.holder == session:
            self.holder = None

    def status(self, session: str) -> dict[str, Any]:
        return {"controlling": self.holder == session, "free": self._free() or self.holder == session}


class Sessions:
    """ASGI middleware: a session id for every client (a new cookie when it has none), in ``scope["session_id"]``."""

    def __init__(self, app, control: Control):
        self.app, self.control = app, control

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        cookie = _session_cookie(scope)
        fresh = cookie is None or not 16 <= len(cookie) <= 64 or not cookie.replace("-", "").replace("_", "").isalnum()
        session = secrets.token_urlsafe(24) if fresh or cookie is None else cookie
        scope["session_id"] = session
        self.control.touch(session)

        async def send_with_cookie(message: Message) -> None:
            if fresh and message["type"] == "http.response.start":
                cookie = f"{SESSION_COOKIE}={session}; Path=/; SameSite=Strict; HttpOnly".encode("latin-1")
                message["headers"] = [*message.get("headers", []), (b"set-cookie", cookie)]
            await send(message)

        await self.app(scope, receive, send_with_cookie)


def create_console(live: Live, runs: Runs, access: Access | None = None) -> Guard:
    """The console over ``live`` and ``runs`` behind the guard of ``access`` (default: loopback names, no token)."""
    templates = Jinja2Templates(directory=HERE / "templates")
    control = Control()

    def session(request: Request) -> str:
        return request.scope["session_id"]

    def controlled(request: Request) -> Response | None:
        """None when the request's session controls the rig (taking control when it is free), else a 403."""
        if control.claim(session(request)):
            return None
        return JSON({"error": "another session controls the rig: this one watches (read-only)"}, status_code=403)

    async def page(request: Request):
        control.claim(session(request))
        return templates.TemplateResponse(request, "console.html", {"version": __version__})

    async def plotly_js(request: Request):
        return FileResponse(PLOTLY_JS, media_type="text/javascript")

    async def rig(request: Request):
        return JSON({**await run_in_threadpool(live.rig), "control": control.status(session(request))})

    async def frame_png(request: Request):
        view = live.latest
        if view is None:
            return JSON({"error": "no frame yet"}, status_code=404)
        scale = _int_param(request, "scale", None, 1, 64)
        clip = _int_param(request, "clip", 1, 0, 1) == 1
        peaking = _int_param(request, "peaking", 0, 0, 1) == 1
        body = await run_in_threadpool(view.png, scale, clip, peaking)
        return Response(body, media_type="image/png", headers={"x-frame-id": str(view.frame.frame_id)})

    async def stats(request: Request):
        view = live.latest
        if view is None:
            return JSON({"error": "no frame yet" if live.error is None else live.error}, status_code=404)
        return JSON(view.stats)

    async def focus(request: Request):
        return JSON(await run_in_threadpool(live.focus))

    async def camera(request: Request):
        if (refused := controlled(request)) is not None:
            return refused
        body = await _object(request)
        return JSON(await run_in_threadpool(live.set_camera, body))

    async def view_roi(request: Request):
        if (refused := controlled(request)) is not None:
            return refused
        return JSON(await run_in_threadpool(live.set_view_roi, await _object(request)))

    async def focus_reset(request: Request):
        if (refused := controlled(request)) is not None:
            return refused
        await _object(request)
        live.reset_focus()
        return JSON({"reset": True})

    async def lights(request: Request):
        return JSON(await run_in_threadpool(live.lights))

    async def light(request: Request):
        if (refused := controlled(request)) is not None:
            return refused
        body = await _object(request)
        return JSON(await run_in_threadpool(live.set_light, request.path_params["name"], body))

    async def spectrometer(request: Request):
        return JSON(await run_in_threadpool(live.spectrum))

    async def control_post(request: Request):
        body = await _object(request)
        if body.get("release") is True:
            control.release(session(request))
        else:
            control.claim(session(request))
        return JSON(control.status(session(request)))

    async def runs_post(request: Request):
        if (refused := controlled(request)) is not None:
            return refused
        body = await _object(request)
        run = await run_in_threadpool(runs.start, body)
        return JSON({"id": run.id, "out": str(run.out)})

    async def runs_list(request: Request):
        return JSON({"runs": [{k: v for k, v in r.as_json().items() if k != "points"} for r in runs.runs.values()]})

    async def run_get(request: Request):
        run_id = request.path_params["id"]
        if run_id not in runs.runs:
            return JSON({"error": f"no run {run_id[:40]}"}, status_code=404)
        return JSON(runs.runs[run_id].as_json())

    async def run_prediction(request: Request):
        run_id = request.path_params["id"]
        if run_id not in runs.runs:
            return JSON({"error": f"no run {run_id[:40]}"}, status_code=404)
        return JSON(runs.runs[run_id].prediction)

    async def run_action(request: Request):
        if (refused := controlled(request)) is not None:
            return refused
        run_id, action = request.path_params["id"], request.path_params["action"]
        if run_id not in runs.runs:
            return JSON({"error": f"no run {run_id[:40]}"}, status_code=404)
        if action not in ("pause", "resume", "abort"):
            return JSON({"error": f"no action {action[:40]} (pause, resume, abort)"}, status_code=404)
        await _object(request)
        return JSON(runs.command(run_id, action).as_json())

    async def stream(request: Request):
        """Server-Sent Events: ``stats`` for every new frame, ``rig`` when a setting changes, ``run`` when a run
        changes (``?limit=N`` ends the stream after N events)."""
        limit = _int_param(request, "limit", 0, 0, 1_000_000)
        who = session(request)

        async def events():
            control.streams[who] = control.streams.get(who, 0) + 1
            sent, seen = 0, {"frame": -1, "rig": -1, "run": -1}
            loop, changed = asyncio.get_running_loop(), asyncio.Event()

            def wake() -> None:  # called by the thread that made the change
                with contextlib.suppress(RuntimeError):  # the server's loop closed (the console stopping)
                    loop.call_soon_threadsafe(changed.set)

            live.changes.subscribe(wake)
            try:
                yield "retry: 1000\n\n"
                while not await request.is_disconnected():
                    control.touch(who)
                    changed.clear()  # before reading: a change from now on wakes the wait below
                    out = []
                    view = live.latest
                    if view is not None and live.seq != seen["frame"]:
                        seen["frame"] = live.seq
                        out.append(("stats", view.stats))
                    if live.settings_seq != seen["rig"]:
                        seen["rig"] = live.settings_seq
                        out.append(("rig", {"held_by_run": live.released, "error": live.error}))
                    if runs.seq != seen["run"]:
                        seen["run"] = runs.seq
                        run = runs.active() or (list(runs.runs.values())[-1] if runs.runs else None)
                        if run is not None:
                            out.append(("run", run.as_json()))
                    for name, data in out:
                        yield f"event: {name}\ndata: {dumps(data)}\n\n"
                        sent += 1
                        if limit and sent >= limit:
                            return
                    with contextlib.suppress(TimeoutError):
                        await asyncio.wait_for(changed.wait(), STREAM_IDLE_S)
            finally:
                live.changes.unsubscribe(wake)
                control.streams[who] -= 1
                if control.streams[who] == 0:
                    control.left[who] = time.monotonic()

        return StreamingResponse(events(), media_type="text/event-stream", headers={"x-accel-buffering": "no"})

    routes = [
        Route("/", page),
        Route("/static/plotly.min.js", plotly_js),
        Mount("/static", StaticFiles(directory=HERE / "static"), name="static"),
        Route("/api/rig", rig),
        Route("/api/camera/frame.png", frame_png),
        Route("/api/camera/stats", stats),
        Route("/api/camera", camera, methods=["POST"]),
        Route("/api/view", view_roi, methods=["POST"]),
        Route("/api/focus", focus),
        Route("/api/focus/reset", focus_reset, methods=["POST"]),
        Route("/api/lights", lights),
        Route("/api/lights/{name}", light, methods=["POST"]),
        Route("/api/spectrometer", spectrometer),
        Route("/api/control", control_post, methods=["POST"]),
        Route("/api/runs", runs_post, methods=["POST"]),
        Route("/api/runs", runs_list),
        Route("/api/runs/{id}", run_get),
        Route("/api/runs/{id}/prediction", run_prediction),
        Route("/api/runs/{id}/{action}", run_action, methods=["POST"]),
        Route("/api/stream", stream),
    ]
    app = Starlette(routes=routes, exception_handlers={UwlabError: error_response})
    return Guard(Sessions(app, control), access or Access())


async def _object(request: Request) -> dict:
    body = await _body(request)
    if not isinstance(body, dict):
        raise ConfigError("request", "body", "must be a JSON object")
    return body


def _int_param(request: Request, name: str, default: int | None, low: int, high: int) -> int | None:
    text = request.query_params.get(name)
    if text is None or text == "":
        return default
    if not text.isdigit() or not low <= int(text) <= high:
        raise ConfigError(name, text[:40], f"must be an integer in [{low}, {high}]")
    return int(text)


def _session_cookie(scope: Scope) -> str | None:
    """The session cookie of a request (None when it has none or a malformed Cookie header)."""
    jar: SimpleCookie = SimpleCookie()
    for name, value in scope.get("headers", []):
        if name.lower() == b"cookie":
            try:
                jar.load(value.decode("latin-1"))
            except Exception:  # a malformed Cookie header is no cookie
                return None
    morsel = jar.get(SESSION_COOKIE)
    return None if morsel is None else morsel.value
