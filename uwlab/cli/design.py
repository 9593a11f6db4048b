"""`uwlab design`: the design calculator (one design, or a grid of designs)."""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

from uwlab.errors import ConfigError
from uwlab.jsonable import to_jsonable
from uwlab.model.config import apply_override, load_raw, parse_value


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "design", help="predict FOV, exposure, framerate, DoF, response and SNR of a design; grids; inverse design",
        description="Evaluate an underwater camera design (TOML) with the image-formation model: one design, a grid "
                    "of designs (--grid), or the inverse problem `uwlab design solve CONFIG --free ... --require ...`.")
    p.add_argument("config", help="design TOML (see configs/design/example.toml), or `solve` followed by the TOML")
    p.add_argument("solve_config", nargs="?", metavar="CONFIG", help="with `solve`: the design TOML")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="override one value")
    p.add_argument("--out", metavar="FILE", help="results to FILE: .parquet (a directory of parts) or .csv; without "
                   "--grid the single design's row; with solve and two objectives the Pareto front")
    p.add_argument("--plot", metavar="DIR", help="write the design figures (PNG) to DIR (solve: the Pareto front)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    grid = p.add_argument_group("grids")
    grid.add_argument("--grid", action="append", default=[], metavar="SECTION.KEY=START:STOP:STEP|V1,V2,...",
                      help="evaluate the Cartesian grid of these values (repeatable)")
    grid.add_argument("--columns", metavar="OUT1,OUT2,...", help="grid outputs to keep (default: all)")
    grid.add_argument("--dask", metavar="local|tcp://HOST:PORT",
                      help="evaluate the grid on a Dask cluster (a LocalCluster, or a scheduler address) into --out")
    p.set_defaults(func=run)


def _assignment(text: str, option: str) -> tuple[str, str]:
    key, eq, value = text.partition("=")
    if not eq or not key:
        raise ConfigError(option, text, "expected SECTION.KEY=VALUE")
    return key.strip(), value.strip()


def parse_grid_values(key: str, text: str) -> list:
    """`start:stop:step` (inclusive of stop) or a comma list of TOML values / bare words."""
    if text.count(":") == 2:
        try:
            start, stop, step = (float(x) for x in text.split(":"))
        except ValueError:
            raise ConfigError(key, text, "grid range must be START:STOP:STEP numbers") from None
        if not all(math.isfinite(x) for x in (start, stop, step)):
            raise ConfigError(key, text, "grid range must be finite START:STOP:STEP numbers")
        if step <= 0 or stop < start:
            raise ConfigError(key, text, "grid range needs step > 0 and stop >= start")
        count = int(math.floor((stop - start) / step + 1e-9)) + 1
        if count > 10_000_000:
            raise ConfigError(key, text, f"{count} values in one axis is too many")
        return list(start + step * np.arange(count))
    values = [parse_value(v.strip()) for v in text.split(",") if v.strip()]
    if not values:
        raise ConfigError(key, text, "no grid values")
    return values


JSON_POINTS = 10_000


_TABLE = (
    ("effective_focal_length_mm", "effective focal length", "mm", "{:.2f}"),
    ("fov_deg", "field of view (x, y)", "deg", "{:.2f}"),
    ("fov_m", "footprint at altitude (x, y)", "m", "{:.3f}"),
    ("max_exposure_s", "max exposure for blur", "s", "{:.4g}"),
    ("exposure_s", "exposure", "s", "{:.4g}"),
    ("min_framerate_hz", "min framerate", "Hz", "{:.3g}"),
    ("dof_m", "depth of field (near, far)", "m", "{:.3f}"),
    ("min_f_number_for_dof", "min f-number for DoF", "", "{:.2f}"),
    ("dome_virtual_image_m", "dome virtual image", "m", "{:.4f}"),
    ("target_irradiance_w_m2", "target irradiance", "W/m²", "{:.4g}"),
    ("sensor_irradiance_w_m2", "sensor irradiance", "W/m²", "{:.4g}"),
    ("mean_electrons", "mean signal (on axis)", "e-", "{:.1f}"),
    ("mean_dn", "mean response (on axis)", "DN", "{:.1f}"),
    ("mean_fraction", "fraction of full scale", "", "{:.3f}"),
    ("saturated", "saturated", "", "{}"),
    ("snr", "SNR", "", "{:.1f}"),
    ("snr_db", "SNR", "dB", "{:.1f}"),
    ("image_average", "image average (e-, DN, SNR)", "", "{:.1f}"),
)


def _format(value, fmt: str) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, dict):
        return ", ".join(_format(v, fmt) for v in value.values())
    if isinstance(value, bool):
        return str(value).lower()
    return "inf" if value is None or (isinstance(value, float) and math.isinf(value)) else fmt.format(value)


def _table(result: dict) -> str:
    lines = []
    for key, label, unit, fmt in _TABLE:
        value = result[key]
        text = _format(value, fmt) if value is not None else "n/a"
        lines.append(f"{label:<32} {text} {unit}".rstrip())
    return "\n".join(lines)


def _raw_config(path: str, sets: list[str]) -> dict:
    raw = load_raw(path)
    for item in sets:
        key, value = _assignment(item, "--set")
        apply_override(raw, key, parse_value(value))
    return raw


def _grid_axes(items: list[str]) -> dict[str, list]:
    axes = {}
    for item in items:
        key, value = _assignment(item, "--grid")
        axes[key] = parse_grid_values(key, value)
    return axes


def _progress(total: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, unit="point", unit_scale=True, file=sys.stderr, leave=False,
                disable=not (enabled and sys.stderr.isatty()))


def _print_grid_summary(summary: dict, as_json: bool) -> None:
    if as_json:
        json.dump(summary, sys.stdout)
        sys.stdout.write("\n")
    else:
        where = f" on {summary['workers']} Dask workers" if "workers" in summary else ""
        print(f"{summary['points']} design points written to {summary['out']} ({summary['chunks']} chunks{where})")


def run_grid(args, raw: dict, base: Path) -> int:
    from uwlab.experiments.design.grid import DesignGrid, in_memory_frame

    outputs = tuple(c.strip() for c in args.columns.split(",") if c.strip()) if args.columns else None
    grid = DesignGrid(raw, _grid_axes(args.grid), base, outputs=outputs)
    if args.dask and not args.out:
        raise ConfigError("--dask", args.dask, "a grid on Dask streams to disk: give --out FILE.parquet")
    if args.out:
        if args.dask:
            from uwlab.experiments.design.distributed import write_grid_dask

            with _progress(grid.points, not args.json) as bar:
                summary = write_grid_dask(grid, args.out, args.dask, bar.update)
        else:
            from uwlab.experiments.design.grid import write_grid

            with _progress(grid.points, not args.json) as bar:
                summary = write_grid(grid, args.out, bar.update)
        _print_grid_summary(summary, args.json)
        return 0
    if args.json and grid.points > JSON_POINTS:
        raise ConfigError("--json", f"{grid.points} points", f"more than {JSON_POINTS} points are not printed; "
                          "write them with --out FILE.parquet")
    frame = in_memory_frame(grid)
    if args.json:
        rows = to_jsonable(frame.to_dict(orient="records"))
        json.dump({"points": len(frame), "columns": list(frame.columns), "rows": rows}, sys.stdout)
        sys.stdout.write("\n")
    else:
        print(f"{len(frame)} design points")
        print(frame.to_string(max_rows=40))
    return 0


def run(args) -> int:
    if args.config == "solve":
        return run_solve(args)
    if args.solve_config is not None:
        raise ConfigError("design", args.solve_config, "one config file expected (did you mean `uwlab design solve`?)")
    raw = _raw_config(args.config, args.set)
    base = Path(args.config).resolve().parent
    if args.plot:
        from uwlab.experiments.design.plots import prepare_plot_dir

        prepare_plot_dir(args.plot)
    if args.grid:
        return run_grid(args, raw, base)
    for option in ("columns", "dask"):
        if getattr(args, option):
            raise ConfigError(f"--{option}", getattr(args, option), "only applies to a grid (--grid)")
    from uwlab.model.design import build_design, evaluate

    design = build_design(raw, base)
    if args.out:
        from uwlab.experiments.design.grid import DesignGrid, write_grid

        written = write_grid(DesignGrid(raw, {}, base), args.out)
    result = to_jsonable(evaluate(design))
    if args.plot:
        from uwlab.experiments.design.plots import write_design_plots

        plots = write_design_plots(design, Path(args.plot))
    if args.json:
        json.dump(result, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(_table(result))
        if args.out:
            print(f"design row written to {written['out']}")
        if args.plot:
            print(f"plots: {', '.join(str(p) for p in plots)}")
    return 0


def run_solve(args) -> int:
    raise ConfigError("design solve", args.solve_config, "not implemented")
