"""The explorer's web application (Starlette): the page, its static files, Plotly.js from the installed plotly
package, and the JSON API under ``/api/`` (docs/explorer.md).

Requests are parsed like the command line's arguments (`uwlab.explore.inputs`); the numbers come from
`uwlab.model` and `uwlab.experiments.design` only. Any `UwlabError` (bad input) answers 422 with
``{"error": "<the line uwlab design prints after 'uwlab design: error: '>", "key": "<the key>"}``.
"""

from __future__ import annotations

import datetime as _dt
import json
from pathlib import Path
from typing import Any

import plotly
from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import FileResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles
from starlette.templating import Jinja2Templates

from uwlab import __version__
from uwlab.errors import ConfigError, UwlabError
from uwlab.experiments.design.readout import BUDGET_KEY, budget_rows, design_warnings, output_leaves, rows
from uwlab.explore import figures
from uwlab.explore.catalog import SUGGESTIONS, Catalog
from uwlab.explore.forms import form_json, gridable_keys
from uwlab.explore.inputs import (
    OUTSIDE_ROOTS,
    Served,
    absolute_paths,
    build,
    check_files,
    design_raw,
    field_texts,
    read_toml_text,
    toml_text,
)
from uwlab.explore.security import Access, Guard
from uwlab.explore.studies import solve_answer, sweep_answer
from uwlab.jsonable import dumps, to_jsonable
from uwlab.model.build import build_design
from uwlab.model.data import resolve_path
from uwlab.model.evaluation import evaluate
from uwlab.model.sensor import available_profiles

HERE = Path(__file__).resolve().parent
PLOTLY_JS = Path(plotly.__file__).resolve().parent / "package_data" / "plotly.min.js"


class JSON(Response):
    """A JSON response written by `uwlab.jsonable` (numpy values, infinities as null)."""

    media_type = "application/json"

    def render(self, content) -> bytes:
        return dumps(content).encode()


def error_response(request: Request, exc: Exception) -> JSON:
    """A `UwlabError` (the only exception it is registered for) as a 422 JSON body naming the key."""
    body = {"error": str(exc)}
    if isinstance(exc, ConfigError):
        body["key"] = exc.key
    return JSON(body, status_code=422)


MAX_JSON_DEPTH = 32


async def _body(request: Request):
    """The request's JSON (the guard, `uwlab.explore.security`, has limited its size), nested at most
    `MAX_JSON_DEPTH` deep."""
    try:
        body = json.loads(await request.body())
    except RecursionError:
        raise ConfigError("request", "body", f"nested deeper than {MAX_JSON_DEPTH} levels") from None
    except ValueError:
        raise ConfigError("request", "body", "must be JSON") from None
    if _depth(body) > MAX_JSON_DEPTH:
        raise ConfigError("request", "body", f"nested deeper than {MAX_JSON_DEPTH} levels")
    return body


def _depth(value) -> int:
    """How deep lists and objects nest in a JSON value (iteratively: no recursion limit to hit)."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict | list):
            deepest = max(deepest, depth)
            stack.extend((child, depth + 1) for child in (item.values() if isinstance(item, dict) else item))
    return deepest


def design_result(design) -> dict:
    """The object `uwlab design CONFIG --json` prints for this design."""
    return to_jsonable(evaluate(design))


def create_app(served: Served, catalog: Catalog | None = None, access: Access | None = None) -> Guard:
    """The explorer for the served design, with the user profiles of `catalog`, behind the guard of `access`
    (default: loopback names only, no token; `uwlab.explore.security`)."""
    catalog = catalog or Catalog()
    templates = Jinja2Templates(directory=HERE / "templates")

    def presets() -> dict:
        return {
            section: [{"label": p.label, "text": field_texts(_nest(p.values)), "user": p.user} for p in found]
            for section, found in catalog.presets().items()
        }

    async def page(request: Request):
        return templates.TemplateResponse(
            request, "index.html", {"sections": form_json(), "served": str(served.path or ""), "version": __version__}
        )

    async def plotly_js(request: Request):
        return FileResponse(PLOTLY_JS, media_type="text/javascript")

    async def schema(request: Request):
        suggestions = {**{k: list(v) for k, v in SUGGESTIONS.items()}, "sensor.profile": available_profiles()}
        return JSON(
            {
                "sections": form_json(),
                "presets": presets(),
                "suggestions": suggestions,
                "grid_keys": gridable_keys(),
                "template": figures.template(),
            }
        )

    async def config(request: Request):
        return JSON({"path": str(served.path or ""), "text": field_texts(served.raw)})

    async def design(request: Request):
        body = await _body(request)
        return JSON(await run_in_threadpool(lambda: design_result(build(body, served))))

    def _view(body) -> dict:
        design = build(body, served)
        result = design_result(design)
        view: dict[str, Any] = {
            "result": result,
            "rows": [vars(r) for r in rows(result)],
            "warnings": [vars(w) for w in design_warnings(design, result)],
            "outputs": output_leaves(result),
            "figures": figures.design_figures(design, result, catalog.user_sensors()),
        }
        if result.get(BUDGET_KEY):
            stage_rows, worst, total = budget_rows(result[BUDGET_KEY])
            view["budget"] = {"rows": [vars(r) for r in stage_rows], "worst": worst, "total": total}
            view["figures"]["budget"] = figures.budget_figure(stage_rows, worst, result[BUDGET_KEY])
        return view

    async def view(request: Request):
        body = await _body(request)
        return JSON(await run_in_threadpool(_view, body))

    async def sweep(request: Request):
        body = await _body(request)
        return JSON(await run_in_threadpool(sweep_answer, body, served))

    async def solve(request: Request):
        body = await _body(request)
        return JSON(await run_in_threadpool(solve_answer, body, served))

    def _toml(body) -> str:
        raw = design_raw(body, served)
        build_design(raw, served.base_dir)
        header = (
            f"Design saved by uwlab explore {__version__} on {_dt.datetime.now().isoformat(timespec='seconds')}"
            + (f"\nstarting from {served.path}" if served.path else "")
        )
        return toml_text(absolute_paths(raw, served.base_dir), header)

    async def save(request: Request):
        body = await _body(request)
        text = await run_in_threadpool(_toml, body)
        return Response(
            text, media_type="application/toml", headers={"Content-Disposition": 'attachment; filename="design.toml"'}
        )

    def _load(body) -> dict:
        if not isinstance(body, dict):
            raise ConfigError("request", body, "must be a JSON object")
        raw = read_toml_text(body.get("toml"), str(body.get("name", "uploaded file")))
        check_files(raw, served)
        raw = absolute_paths(raw, served.base_dir)
        build_design(raw, served.base_dir)
        return {"text": field_texts(raw)}

    async def load(request: Request):
        body = await _body(request)
        return JSON(await run_in_threadpool(_load, body))

    async def profile(request: Request):
        body = await _body(request)
        if not isinstance(body, dict) or not isinstance(body.get("path"), str):
            raise ConfigError("path", body, 'give {"path": "/path/to/profile.toml"}')
        path = served.readable(resolve_path(body["path"], served.base_dir))
        if path is None:
            raise ConfigError("path", body["path"], OUTSIDE_ROOTS)
        section, preset = await run_in_threadpool(catalog.add_profile, path)
        return JSON(
            {"section": section, "label": preset.label, "text": field_texts(_nest(preset.values)), "presets": presets()}
        )

    routes = [
        Route("/", page),
        Route("/static/plotly.min.js", plotly_js),
        Mount("/static", StaticFiles(directory=HERE / "static"), name="static"),
        Route("/api/schema", schema),
        Route("/api/config", config),
        Route("/api/design", design, methods=["POST"]),
        Route("/api/view", view, methods=["POST"]),
        Route("/api/sweep", sweep, methods=["POST"]),
        Route("/api/solve", solve, methods=["POST"]),
        Route("/api/toml", save, methods=["POST"]),
        Route("/api/load", load, methods=["POST"]),
        Route("/api/profile", profile, methods=["POST"]),
    ]
    app = Starlette(routes=routes, exception_handlers={UwlabError: error_response})
    return Guard(app, access or Access())


def _nest(values: dict) -> dict:
    """{"section.key": value} → {section: {key: value}}."""
    out: dict = {}
    for dotted, value in values.items():
        section, _, key = dotted.partition(".")
        out.setdefault(section, {})[key] = value
    return out
