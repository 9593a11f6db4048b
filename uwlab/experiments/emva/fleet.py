"""Characterising a fleet of cameras in one call: every uwlab dataset (a directory with ``metadata.json``) and every
EMVA 1288 descriptor file (``EMVA1288*.txt``) found under a folder, one table row per camera.

A camera whose data are refused (a one-line `UwlabError`) gets a row with the reason and the fleet goes on; with an
output directory each camera's files (`uwlab.experiments.emva.output`) go to a sub-directory of its own, and the
table to ``fleet.csv`` and ``fleet.json``. A colour camera's raw Bayer dataset gives a row per colour channel (EMVA 1288
Release 4.0 Linear §1.2: each channel is a sensor of its own), its files in ``<camera>/<channel>``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from uwlab.errors import ConfigError, UwlabError
from uwlab.jsonable import dumps
from uwlab.outputs import output_dir

DESCRIPTOR_GLOB = "EMVA1288*.txt"
COLUMNS = (
    ("K_dn_per_e", "K [DN/e-]", ".4g"),
    ("quantum_efficiency", "η", ".3f"),
    ("dark_noise_e", "σ_d [e-]", ".3g"),
    ("dark_noise_p", "σ_d [p]", ".3g"),
    ("saturation_e", "μ_e.sat [e-]", ".5g"),
    ("saturation_photons", "μ_p.sat [p]", ".5g"),
    ("dynamic_range_db", "DR [dB]", ".1f"),
    ("snr_max_db", "SNR_max [dB]", ".1f"),
    ("linearity_error_percent", "LE [%]", ".3g"),
    ("dsnu_e", "DSNU [e-]", ".3g"),
    ("prnu_percent", "PRNU [%]", ".3g"),
    ("dark_current_e_per_s", "I_dark [e-/s]", ".3g"),
)


@dataclass(frozen=True)
class FleetInput:
    """One camera's data: a dataset directory or a descriptor file."""

    path: Path
    kind: str

    @property
    def label(self) -> str:
        return self.path.parent.name if self.kind == "descriptor" else self.path.name


def find_inputs(folder: str | Path) -> list[FleetInput]:
    """Datasets and descriptor files under ``folder`` (recursively), in path order."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ConfigError("folder", str(folder), "not a directory")
    found = [FleetInput(p.parent, "dataset") for p in folder.rglob("metadata.json")]
    found += [FleetInput(p, "descriptor") for p in folder.rglob("*") if p.is_file() and p.match(DESCRIPTOR_GLOB)]
    if not found:
        raise ConfigError(
            "folder", str(folder), f"no datasets (metadata.json) or descriptors ({DESCRIPTOR_GLOB}) in it"
        )
    return sorted(found, key=lambda f: str(f.path))


@dataclass(frozen=True)
class FleetRow:
    """One camera's result (``values``: the characterisation's JSON document) or the reason it was refused."""

    camera: str
    source: str
    values: dict | None
    error: str | None = None

    def document(self) -> dict:
        row: dict[str, Any] = {
            "camera": self.camera,
            "source": self.source,
            "status": "ok" if self.error is None else "refused",
            "error": self.error,
        }
        values = self.values or {}
        row |= {key: values.get(key) for key, _, _ in COLUMNS}
        row |= {"model": values.get("model"), "notes": values.get("notes", [])}
        if values:
            from uwlab.experiments.emva.datasheet import missing_figures

            row["missing"] = missing_figures(values)
        return row


def characterize_input(
    item: FleetInput, *, model: str, pixel_size_um: float | None, out: Path | None
) -> list[FleetRow]:
    """Load, characterise and (with ``out``) write one camera: one row, or one per colour channel."""
    from uwlab.experiments.emva.analysis import characterize
    from uwlab.experiments.emva.output import output_paths, profile_name, result_document, write_characterization

    if item.kind == "dataset":
        from uwlab.experiments.emva.from_dataset import load_dataset_inputs

        loaded = load_dataset_inputs(item.path, pixel_size_um=pixel_size_um)
        jobs = {channel: (one.transfer, one.profile, one.camera, one.info) for channel, one in loaded.items()}
    else:
        from uwlab.experiments.emva.descriptor import parse_descriptor, photon_transfer_from_descriptor, sheet_info

        pt = photon_transfer_from_descriptor(item.path, pixel_size_um)
        info = sheet_info(parse_descriptor(item.path))
        jobs = {None: (pt, None, info.model if info.model != "—" else item.label, info)}
    results = {channel: characterize(job[0], model) for channel, job in jobs.items()}
    if out is None:
        return [FleetRow(jobs[c][2], str(item.path), result_document(r)) for c, r in results.items()]
    targets = {}
    for channel, (_, base, camera, _) in jobs.items():
        name = profile_name(f"measured-{camera}")
        folder = out / profile_name(item.label)
        if channel is not None:
            folder.mkdir(exist_ok=True)
            folder = folder / channel
        targets[channel] = (name, output_paths(folder, results[channel], name, bool(pixel_size_um or base)))
    rows = []
    for channel, (pt, base, camera, info) in jobs.items():
        name, paths = targets[channel]
        document = write_characterization(
            results[channel], pt, paths, name=name, base=base, pixel_size_um=pixel_size_um, info=info
        )
        rows.append(FleetRow(camera, str(item.path), document))
    return rows


def characterize_fleet(
    inputs: list[FleetInput],
    *,
    model: str = "linear",
    pixel_size_um: float | None = None,
    out: Path | None = None,
    progress: Callable[[FleetRow], None] | None = None,
    dask: str | None = None,
) -> list[FleetRow]:
    """One `FleetRow` per input, in input order; ``progress`` is called after each camera (in the order they
    finish). ``dask``: the cameras in parallel on a Dask cluster (``local`` or ``tcp://HOST:PORT``,
    `uwlab.experiments.cluster`), each on one worker (the workers write their cameras' sub-directories: on a
    multi-machine cluster ``out`` must be on a file system they share); otherwise one after another, each camera's
    blocks spread over this machine's threads."""
    from uwlab.experiments.emva.output import profile_name

    if out is not None:
        out = output_dir(out, "--out")
        labels = [profile_name(i.label) for i in inputs]
        twice = sorted({label for label in labels if labels.count(label) > 1})
        if twice:
            raise ConfigError("folder", twice[0], "two cameras would share this output sub-directory")
        for name in ("fleet.csv", "fleet.json"):
            if (out / name).exists():
                raise ConfigError("--out", str(out / name), "exists; refusing to overwrite")
        out.mkdir(exist_ok=True)
    options = {"model": model, "pixel_size_um": pixel_size_um, "out": out}
    if dask is None:
        rows = []
        for item in inputs:
            rows += _rows(item, options)
            if progress is not None:
                progress(rows[-1])
    else:
        rows = _rows_on_dask(inputs, options, dask, progress)
    if out is not None:
        write_fleet_table(rows, out)
    return rows


def _rows(item: FleetInput, options: dict) -> list[FleetRow]:
    """`characterize_input`, a refusal kept as the camera's row."""
    try:
        return characterize_input(item, **options)
    except UwlabError as exc:
        return [FleetRow(item.label, str(item.path), None, str(exc))]


def _rows_on_dask(
    inputs: list[FleetInput], options: dict, address: str, progress: Callable[[FleetRow], None] | None
) -> list[FleetRow]:
    from distributed import as_completed

    from uwlab.experiments.cluster import dask_client

    with dask_client(address) as client:
        futures = [client.submit(_rows, item, options, pure=False) for item in inputs]
        index = {future.key: number for number, future in enumerate(futures)}
        rows: list[list[FleetRow]] = [[] for _ in inputs]
        for future in as_completed(futures):
            found = future.result()
            rows[index[future.key]] = found
            if progress is not None:
                progress(found[-1])
    return [row for found in rows for row in found]


def write_fleet_table(rows: list[FleetRow], out: Path) -> None:
    """``fleet.json`` (every row's document) and ``fleet.csv`` (the table's columns) in ``out``."""
    import pandas as pd

    documents = [r.document() for r in rows]
    (out / "fleet.json").write_text(dumps(documents, indent=2) + "\n")
    frame = pd.DataFrame([{k: v for k, v in d.items() if k != "notes"} for d in documents])
    frame.to_csv(out / "fleet.csv", index=False)
