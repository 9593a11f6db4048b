"""The validation report: one self-contained HTML file (figures embedded as PNG data URIs).

`write_report(root, out)` looks under `root` (depth ≤ 2) for datasets (``metadata.json`` + ``manifest.json``),
calibrations (``summary.json`` + ``samples.parquet`` from `uwlab fit`) and EMVA 1288 characterisations
(``emva.json``), and reports: the set-up, measured against predicted response per camera and lens with 68 % /
95 % bands and residuals, the posterior table beside the simulated truth, corner plot and traces, the
cross-configuration table, the spectra at the target and the camera, the EMVA summary, and the provenance of
every dataset.
"""
from __future__ import annotations

import base64
import html
import io
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from uwlab.errors import UwlabError  # noqa: E402
from uwlab.experiments.dataset_store import MANIFEST_FILE  # noqa: E402
from uwlab.outputs import output_file  # noqa: E402

CSS = """body{font-family:sans-serif;max-width:1200px;margin:2em auto;color:#222}table{border-collapse:collapse;margin:1em 0}
td,th{border:1px solid #ccc;padding:3px 8px;font-size:13px;text-align:right}th{background:#eee}td.l,th.l{text-align:left}
img{max-width:100%}.warn{color:#a40}.note{color:#555;font-size:13px}h2{border-bottom:1px solid #ccc}"""


def _find(root: Path, marker: str, also: str | None = None) -> list[Path]:
    found = [p.parent for p in sorted(root.glob(marker)) + sorted(root.glob(f"*/{marker}")) + sorted(root.glob(f"*/*/{marker}"))]
    return [p for p in dict.fromkeys(found) if also is None or (p / also).exists()]


def _img(path: Path) -> str:
    data = base64.b64encode(path.read_bytes()).decode()
    return f'<img src="data:image/png;base64,{data}" alt="{html.escape(path.name)}">'


def _fig(fig) -> str:
    buffer = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buffer, format="png", dpi=80)
    plt.close(fig)
    return f'<img src="data:image/png;base64,{base64.b64encode(buffer.getvalue()).decode()}">'


def _fmt(value) -> str:
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4g}"
    return html.escape(str(value))


def _table(rows: list[dict], columns: list[str], left: int = 1) -> str:
    head = "".join(f'<th class="{"l" if i < left else ""}">{html.escape(c)}</th>' for i, c in enumerate(columns))
    body = "".join("<tr>" + "".join(f'<td class="{"l" if i < left else ""}">{_fmt(r.get(c))}</td>'
                                    for i, c in enumerate(columns)) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _setup(metadata: dict) -> str:
    rows = []
    for sweep_id, rig in (metadata.get("rigs") or {}).items():
        light, lens, water = rig.get("light", {}), rig.get("lens", {}), rig.get("water", {})
        rows.append({"sweep": sweep_id, "sensor": rig.get("sensor", {}).get("profile"),
                     "light [lm]": light.get("luminous_flux_lm"), "beam half-angle [°]": light.get("beam_half_angle_deg"),
                     "light→target [m]": light.get("distance_m"), "target→camera [m]": rig.get("operation", {}).get("altitude_m"),
                     "water": water.get("type"), "focal length [mm]": lens.get("focal_length_mm"),
                     "f-number": lens.get("f_number"), "port": rig.get("housing", {}).get("port"),
                     "reflectance": rig.get("target", {}).get("reflectance")})
    return _table(rows, list(rows[0]) if rows else ["sweep"], left=3) + \
        '<p class="note">A "no lens" sweep is a bare sensor in the board\'s radiance field (recorded as f-number 0.5).</p>'


def _provenance(path: Path, metadata: dict) -> str:
    devices = metadata.get("devices") or {}
    rows = [{"sweep": s, "camera": f"{d.get('camera', {}).get('vendor', '')} {d.get('camera', {}).get('model', '')}",
             "serial": d.get("camera", {}).get("serial"), "firmware": d.get("camera", {}).get("firmware"),
             "light": d.get("light"), "spectrometer": d.get("spectrometer")} for s, d in devices.items()]
    software = ", ".join(f"{k} {v}" for k, v in (metadata.get("software") or {}).items())
    return (f"<p><b>{html.escape(str(path))}</b>: plan sha256 <code>{_fmt(metadata.get('plan_sha256'))}</code>, uwlab "
            f"{_fmt(metadata.get('uwlab_version'))}, host {_fmt(metadata.get('host'))}, "
            f"{_fmt(metadata.get('started_utc'))} → {_fmt(metadata.get('finished_utc'))}, "
            f"{'simulated rig' if metadata.get('sim') else 'tank'}</p>"
            + _table(rows, ["sweep", "camera", "serial", "firmware", "light", "spectrometer"], left=6)
            + f'<p class="note">software: {html.escape(software)}</p>')


def _posterior(summary: dict) -> str:
    rows = [{"parameter": n, "truth": p.get("truth"), "median": p["median"], "2.5 %": p["p2_5"], "16 %": p["p16"],
             "84 %": p["p84"], "97.5 %": p["p97_5"], "τ [steps]": p["tau"], "R-hat": p["rhat"]}
            for n, p in summary["parameters"].items()]
    notes = "".join(f'<p class="warn">warning: {html.escape(w)}</p>' for w in summary.get("warnings", []))
    pairs = "".join(f'<p class="warn">not separable by these data: {html.escape(p["a"])} and {html.escape(p["b"])} '
                    f'(posterior correlation {p["rho"]:+.2f})</p>' for p in summary.get("not_separable", []))
    return (_table(rows, list(rows[0])) + f'<p class="note">converged: {_fmt(summary["converged"])} — {summary["steps"]} '
            f'steps × {summary["walkers"]} walkers, {summary["tau_multiple"]:.0f} autocorrelation times, acceptance '
            f'{summary["acceptance_fraction"]:.2f}, {summary["points_used"]} points (saturated points excluded)</p>'
            + notes + pairs)


def _spectra_figure(path: Path) -> str:
    frame = pd.read_parquet(path)
    sweeps = list(dict.fromkeys(frame["sweep_id"]))[:6]
    fig, axes = plt.subplots(2, len(sweeps), figsize=(3 * len(sweeps), 5), squeeze=False, sharex=True)
    for j, sweep_id in enumerate(sweeps):
        for i, position in enumerate(("target", "camera")):
            sel = frame[(frame["sweep_id"] == sweep_id) & (frame["position"] == position)]
            ax = axes[i, j]
            ax.plot(sel["wavelength_nm"], sel["predicted_w_m2_nm"], label="predicted")
            if sel["irradiance_w_m2_nm"].notna().any():
                ax.plot(sel["wavelength_nm"], sel["irradiance_w_m2_nm"], ".", markersize=2, label="measured")
            ax.set_title(f"{sweep_id}: {position}", fontsize=8)
            ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7)
    axes[0, 0].set_ylabel("W/m²/nm at the target", fontsize=8)
    axes[1, 0].set_ylabel("W/m²/nm at the camera", fontsize=8)
    return _fig(fig)


def _calibration(path: Path) -> str:
    summary = json.loads((path / "summary.json").read_text())
    parts = [f"<h2>Calibration: {html.escape(str(path))}</h2>", f"<p class=note>dataset: {_fmt(summary.get('dataset'))}</p>",
             "<h3>Measured against predicted response (68 % and 95 % bands) and residuals</h3>", _img(path / "response.png"),
             "<h3>Posterior</h3>", _posterior(summary), _img(path / "corner.png"), "<h3>Traces</h3>", _img(path / "traces.png")]
    cross = summary.get("cross_configuration") or []
    if cross:
        parts += [f"<h3>Cross-configuration prediction (fitted on {html.escape(', '.join(summary.get('training_sweeps', [])))})</h3>",
                  _table(cross, ["sweep_id", "role", "points", "median_abs_rel_error", "max_abs_rel_error", "inside_95"], 2),
                  '<p class="note">Relative error of the posterior median; "inside_95": fraction of measured points inside '
                  'the 95 % posterior predictive band of a new measurement.</p>']
    if (path / "spectra.parquet").exists():
        parts += ["<h3>Spectra: predicted (posterior median) and measured</h3>", _spectra_figure(path / "spectra.parquet")]
        if summary.get("spectra"):
            parts.append(_table(summary["spectra"], ["sweep_id", "position", "measured_over_predicted", "shape_rms_error"], 2))
    return "\n".join(parts)


def _emva(path: Path) -> str:
    doc = json.loads((path / "emva.json").read_text())
    keys = ("K_dn_per_e", "quantum_efficiency", "dark_noise_e", "saturation_e", "snr_max_db", "dynamic_range_db",
            "linearity_error_percent", "dark_current_e_per_s", "dsnu_e", "prnu_percent")
    rows = [{"quantity": k, "value": doc.get(k), "std": doc.get(f"{k}_std")} for k in keys]
    images = "".join(_img(path / n) for n in ("photon_transfer.png", "snr.png", "linearity.png", "dark_current.png")
                     if (path / n).exists())
    return f"<h2>EMVA 1288 characterisation: {html.escape(str(path))}</h2>" + _table(rows, ["quantity", "value", "std"]) + images


def write_report(root: str | Path, out: str | Path, *, replace: bool = False) -> Path:
    """Write the HTML report of everything found under `root` to `out` (an existing file only if `replace`; the
    directory must exist); returns `out`."""
    root = Path(root)
    if not root.is_dir():
        raise UwlabError(f"{root}: not a directory")
    out = output_file(out, "--out", replace=replace, replace_option="--force")
    datasets = _find(root, "metadata.json", MANIFEST_FILE)
    calibrations = _find(root, "summary.json", "samples.parquet")
    emva = _find(root, "emva.json")
    if not (datasets or calibrations or emva):
        raise UwlabError(f"{root}: no dataset, calibration or EMVA characterisation found")
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>uwlab validation report</title><style>{CSS}</style>"
             f"</head><body><h1>uwlab validation report</h1><p class=note>{html.escape(str(root.resolve()))}</p>"]
    metadata = [(d, json.loads((d / "metadata.json").read_text())) for d in datasets]
    if metadata:
        parts += ["<h2>Set-up</h2>", _setup(metadata[0][1])]
    parts += [_calibration(c) for c in calibrations]
    parts += [_emva(e) for e in emva]
    if metadata:
        parts += ["<h2>Provenance</h2>"] + [_provenance(d, m) for d, m in metadata]
    parts.append("</body></html>")
    out.write_text("\n".join(parts))
    return out
