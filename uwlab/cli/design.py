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
    p = subparsers.add_parser("design", help="predict FOV, exposure, framerate, DoF, response and SNR of a design",
                              description="Evaluate an underwater camera design (TOML) with the image-formation model.")
    p.add_argument("config", help="design TOML (see configs/design/example.toml)")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="override one value")
    p.add_argument("--grid", action="append", default=[], metavar="SECTION.KEY=START:STOP:STEP|V1,V2,...",
                   help="evaluate the Cartesian grid of these values (repeatable)")
    p.add_argument("--out", metavar="FILE", help="grid results to FILE (.parquet or .csv)")
    p.add_argument("--plot", metavar="DIR", help="write the design figures (PNG) to DIR")
    p.add_argument("--json", action="store_true", help="print one JSON object")
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


def run(args) -> int:
    from uwlab.experiments.design.grid import evaluate_grid
    from uwlab.model.design import build_design, evaluate

    raw = load_raw(args.config)
    for item in args.set:
        key, value = _assignment(item, "--set")
        apply_override(raw, key, parse_value(value))
    base = Path(args.config).resolve().parent
    if args.grid:
        axes = {}
        for item in args.grid:
            key, value = _assignment(item, "--grid")
            axes[key] = parse_grid_values(key, value)
        if args.out and Path(args.out).suffix.lower() not in (".parquet", ".csv"):
            raise ConfigError("--out", args.out, "must end in .parquet or .csv")
        if args.out and Path(args.out).exists():
            raise ConfigError("--out", args.out, "exists; refusing to overwrite")
        frame = evaluate_grid(raw, axes, base)
        if args.out:
            Path(args.out).parent.mkdir(parents=True, exist_ok=True)
            (frame.to_parquet if args.out.lower().endswith(".parquet") else frame.to_csv)(args.out, index=False)
        if args.json:
            json.dump({"points": len(frame), "out": args.out, "columns": list(frame.columns)}, sys.stdout)
            sys.stdout.write("\n")
        else:
            print(f"{len(frame)} design points" + (f" written to {args.out}" if args.out else ""))
            if not args.out:
                print(frame.to_string(max_rows=40))
        return 0
    design = build_design(raw, base)
    result = to_jsonable(evaluate(design))
    if args.plot:
        from uwlab.experiments.design.plots import write_design_plots

        written = write_design_plots(design, Path(args.plot))
    if args.json:
        json.dump(result, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(_table(result))
        if args.plot:
            print(f"plots: {', '.join(str(p) for p in written)}")
    return 0
