"""`uwlab design`: the design calculator (one design, or a grid of designs)."""

from __future__ import annotations

import json
import sys
from pathlib import Path


from uwlab.errors import ConfigError
from uwlab.experiments.design.readout import design_warnings, table_text
from uwlab.jsonable import to_jsonable
from uwlab.model.config import apply_override, load_raw, parse_grid_values, parse_value, split_assignment


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "design",
        description="Evaluate an underwater camera design (TOML) with the image-formation model: one design, a grid "
        "of designs (--grid), or the inverse problem `uwlab design solve CONFIG --free ... --require ...`.",
    )
    p.add_argument("config", help="design TOML (see configs/design/example.toml), or `solve` followed by the TOML")
    p.add_argument("solve_config", nargs="?", metavar="CONFIG", help="with `solve`: the design TOML")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="override one value")
    p.add_argument(
        "--out",
        metavar="FILE",
        help="results to FILE: .parquet (a directory of parts) or .csv; without "
        "--grid the single design's row; with solve and two objectives the Pareto front",
    )
    p.add_argument("--plot", metavar="DIR", help="write the design figures (PNG) to DIR (solve: the Pareto front)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--posterior",
        metavar="FIT_DIR",
        help="a `uwlab fit` output: carry its posterior into the "
        "design (credible band on response and SNR) or into solve (requirements met with probability)",
    )
    solve = p.add_argument_group("solve (uwlab design solve CONFIG ...)")
    solve.add_argument(
        "--free",
        action="append",
        default=[],
        metavar="SECTION.KEY=LO:HI",
        help="a key the solver may choose within [LO, HI] (repeatable)",
    )
    solve.add_argument(
        "--require",
        action="append",
        default=[],
        metavar='"OUTPUT OP VALUE"',
        help="a requirement on an output of `uwlab design --json`, OP >= or <= (repeatable), "
        'e.g. "snr_db >= 30", "dof_m.near <= 1.7"',
    )
    solve.add_argument(
        "--minimize",
        dest="objectives",
        action="append",
        default=[],
        metavar="SECTION.KEY",
        type=lambda key: ("minimize", key),
        help="a free key to make as small as possible",
    )
    solve.add_argument(
        "--maximize",
        dest="objectives",
        action="append",
        metavar="SECTION.KEY",
        type=lambda key: ("maximize", key),
        help="a free key to make as large as possible (with a second objective: the Pareto front)",
    )
    solve.add_argument(
        "--confidence",
        type=float,
        metavar="P",
        help="with --posterior: the probability the requirements must hold with (default 0.9)",
    )
    grid = p.add_argument_group("grids")
    grid.add_argument(
        "--grid",
        action="append",
        default=[],
        metavar="SECTION.KEY=START:STOP:STEP|V1,V2,...",
        help="evaluate the Cartesian grid of these values (repeatable)",
    )
    grid.add_argument("--columns", metavar="OUT1,OUT2,...", help="grid outputs to keep (default: all)")
    grid.add_argument(
        "--dask",
        metavar="local|tcp://HOST:PORT",
        help="evaluate the grid on a Dask cluster (a LocalCluster, or a scheduler address) into --out",
    )
    p.set_defaults(func=run)


JSON_POINTS = 10_000
SOLVE_SAMPLES = 500


_BAND = (
    ("mean_dn", "mean response (on axis)", "DN", "{:.1f}"),
    ("mean_fraction", "fraction of full scale", "", "{:.3f}"),
    ("snr_db", "SNR", "dB", "{:.1f}"),
    ("image_average_mean_dn", "image average response", "DN", "{:.1f}"),
)


def _band_text(band: dict) -> str:
    lines = [
        f"calibrated uncertainty ({band['samples']} posterior samples of {band['fit']}: "
        f"{', '.join(band['carried']) or 'nothing carried'})",
        f"  {'':<30} {'median':>9} {'68 % interval':>22} {'95 % interval':>22}",
    ]
    for key, label, unit, fmt in _BAND:
        q = band[key]
        inner = f"[{fmt.format(q['p16'])}, {fmt.format(q['p84'])}]"
        outer = f"[{fmt.format(q['p2_5'])}, {fmt.format(q['p97_5'])}]"
        lines.append(f"  {label:<30} {fmt.format(q['median']):>9} {inner:>22} {outer:>22} {unit}")
    lines.append(f"  saturated in {100 * band['saturated_fraction']:.1f} % of the samples")
    return "\n".join(lines)


def _raw_config(path: str, sets: list[str]) -> dict:
    raw = load_raw(path)
    for item in sets:
        key, value = split_assignment(item, "--set")
        apply_override(raw, key, parse_value(value))
    return raw


def _grid_axes(items: list[str]) -> dict[str, list]:
    axes = {}
    for item in items:
        key, value = split_assignment(item, "--grid")
        axes[key] = parse_grid_values(key, value)
    return axes


def _progress(total: int, enabled: bool):
    from uwlab.progress import bar

    return bar(total=total, desc="grid", unit="point", enabled=enabled)


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
        raise ConfigError(
            "--json",
            f"{grid.points} points",
            f"more than {JSON_POINTS} points are not printed; write them with --out FILE.parquet",
        )
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
    for option in SOLVE_ONLY:
        if getattr(args, option):
            raise ConfigError(f"--{option}", getattr(args, option), "only applies to `uwlab design solve`")
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
    from uwlab.model.build import build_design
    from uwlab.model.evaluation import evaluate

    design = build_design(raw, base)
    if args.out:
        from uwlab.experiments.design.grid import DesignGrid, write_grid

        written = write_grid(DesignGrid(raw, {}, base), args.out)
    result = to_jsonable(evaluate(design))
    if args.posterior:
        from uwlab.experiments.design.posterior import credible_band, load_posterior

        result["posterior"] = to_jsonable(credible_band(design, load_posterior(args.posterior, design)))
    if args.plot:
        from uwlab.experiments.design.plots import write_design_plots

        plots = write_design_plots(design, Path(args.plot))
    if args.json:
        json.dump(result, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(table_text(result, design_warnings(design, result)))
        if args.posterior:
            print(_band_text(result["posterior"]))
        if args.out:
            print(f"design row written to {written['out']}")
        if args.plot:
            print(f"plots: {', '.join(str(p) for p in plots)}")
    return 0


SOLVE_ONLY = ("free", "require", "objectives", "confidence")


def run_solve(args) -> int:
    from uwlab.experiments.design.solve import (
        Objective,
        Problem,
        front_frame,
        parse_free,
        parse_requirement,
        result_dict,
        solve,
    )

    if args.solve_config is None:
        raise ConfigError(
            "design solve", None, "give the design TOML: uwlab design solve CONFIG --free ... --require ..."
        )
    for option in ("grid", "columns", "dask"):
        if getattr(args, option):
            raise ConfigError(f"--{option}", getattr(args, option), "not an option of solve")
    if args.confidence is not None and not args.posterior:
        raise ConfigError("--confidence", args.confidence, "needs --posterior FIT_DIR")
    raw = _raw_config(args.solve_config, args.set)
    base = Path(args.solve_config).resolve().parent
    objectives = [Objective(key, sense) for sense, key in args.objectives]
    two = len(objectives) == 2
    out = None
    if args.out:
        from uwlab.experiments.design.grid import check_output_path

        if not two:
            raise ConfigError("--out", args.out, "solve writes the Pareto front of two objectives")
        out = check_output_path(args.out)
    if args.plot:
        from uwlab.experiments.design.plots import prepare_plot_dir

        if not two:
            raise ConfigError("--plot", args.plot, "solve plots the Pareto front of two objectives")
        prepare_plot_dir(args.plot)
    loader = None
    if args.posterior:
        from uwlab.experiments.design.posterior import load_posterior

        loader = lambda design: load_posterior(args.posterior, design, max_samples=SOLVE_SAMPLES)  # noqa: E731
    problem = Problem(
        raw,
        base,
        [parse_free(f) for f in args.free],
        [parse_requirement(r) for r in args.require],
        objectives,
        loader,
        0.9 if args.confidence is None and args.posterior else args.confidence or 1.0,
    )
    result = solve(problem)
    answer = result_dict(result, problem)
    if result.feasible and two:
        frame = front_frame(result, problem)
        if out is not None:
            out.parent.mkdir(parents=True, exist_ok=True)
            (frame.to_parquet if out.suffix.lower() == ".parquet" else frame.to_csv)(out, index=False)
            answer["out"] = str(out)
        if args.plot:
            from uwlab.experiments.design.plots import plot_front
            from uwlab.experiments.figures import save_figure

            y, x = (f for f in problem.free[:2])
            front = plot_front(
                frame, x.key, y.key, (objectives[1].sense, objectives[0].sense), answer["requirements"], x.log, y.log
            )
            answer["plot"] = str(save_figure(front, Path(args.plot) / "front.png"))
    if args.json:
        json.dump(to_jsonable(answer), sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(_solve_text(answer))
    return 0


def _solve_text(answer: dict) -> str:
    lines = ["requirements: " + ", ".join(answer["requirements"])]
    objectives = ", ".join(f"{o['sense']} {o['key']}" for o in answer["objectives"])
    lines.append(f"objectives: {objectives}")
    if "posterior" in answer:
        post = answer["posterior"]
        lines.append(
            f"posterior: {post['samples']} samples of {post['fit']} ({', '.join(post['carried'])}); "
            f"requirements must hold together with probability >= {answer['confidence']:g}"
        )
    if not answer["feasible"]:
        lines.append("infeasible within the bounds")
        for entry in answer["unmet"]:
            best = (
                f"best {entry['best']:.4g}" if "best" in entry else f"best probability {entry['best_probability']:.3f}"
            )
            where = ", ".join(f"{k} = {v:.4g}" for k, v in entry["at"].items())
            lines.append(f"  cannot be met even at the bounds: {entry['requirement']} ({best}, at {where})")
        for group in answer["conflicting"]:
            lines.append(f"  cannot be met together: {'; '.join(group)}")
        return "\n".join(lines)
    points = [answer] if "front" not in answer else answer["front"]
    if "front" in answer:
        lines.append(f"Pareto front: {len(points)} points")
    for point in points:
        values = ", ".join(f"{k} = {v:.6g}" for k, v in point["solution"].items())
        extra = f"; probability {point['probability']:.3f}" if "probability" in point else ""
        lines.append(
            f"  {values}   active: {'; '.join(point['active']) or 'none'}{extra}"
            + ("" if point["minimal"] else "   (not minimal)")
        )
    if "front" not in answer:
        verdict = "yes" if answer["minimal"] else "no"
        lines.append(f"minimal: {verdict} (1 % better objective breaks a requirement)")
        if answer["at_bounds"]:
            lines.append(f"at a bound: {', '.join(answer['at_bounds'])}")
        lines.append("design at the solution:")
        lines.append(table_text(answer["outputs"]))
    for key in ("out", "plot"):
        if key in answer:
            lines.append(f"{key}: {answer[key]}")
    return "\n".join(lines)
