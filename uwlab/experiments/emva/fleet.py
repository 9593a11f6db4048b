"""Characterising a fleet of cameras in one call: every uwlab dataset (a directory with ``metadata.json``) and every
EMVA 1288 descriptor file (``EMVA1288*.txt``) found under a folder, one table row per camera.

A camera whose data are refused (a one-line `UwlabError`) gets a row with the reason and the fleet goes on; with an
output directory each camera's files (`uwlab.experiments.emva.output`) go to a sub-directory of its own, and the
table to ``fleet.csv`` and ``fleet.json``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

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
        row = {
            "camera": self.camera,
            "source": self.source,
            "status": "ok" if self.error is None else "refused",
            "error": self.error,
        }
        values = self.values or {}
        row |= {key: values.get(key) for key, _, _ in COLUMNS}
        row |= {"model": values.get("model"), "notes": values.get("notes", [])}
        return row


def characterize_input(item: FleetInput, *, model: str, pixel_size_um: float | None, out: Path | None) -> FleetRow:
    """Load, characterise and (with ``out``) write one camera."""
    from uwlab.experiments.emva.analysis import characterize
    from uwlab.experiments.emva.output import output_paths, profile_name, result_document, write_characterization

    if item.kind == "dataset":
        from uwlab.experiments.emva.from_dataset import load_dataset_input

        loaded = load_dataset_input(item.path, pixel_size_um=pixel_size_um)
        pt, base, camera, info = loaded.transfer, loaded.profile, loaded.camera, loaded.info
    else:
        from uwlab.experiments.emva.descriptor import parse_descriptor, photon_transfer_from_descriptor, sheet_info

        pt, base = photon_transfer_from_descriptor(item.path, pixel_size_um), None
        info = sheet_info(parse_descriptor(item.path))
        camera = info.model if info.model != "—" else item.label
    result = characterize(pt, model)
    if out is None:
        return FleetRow(camera, str(item.path), result_document(result))
    name = profile_name(f"measured-{camera}")
    paths = output_paths(out / profile_name(item.label), result, name, bool(pixel_size_um or base))
    document = write_characterization(result, pt, paths, name=name, base=base, pixel_size_um=pixel_size_um, info=info)
    return FleetRow(camera, str(item.path), document)


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
            rows.append(_row(item, options))
            if progress is not None:
                progress(rows[-1])
    else:
        rows = _rows_on_dask(inputs, options, dask, progress)
    if out is not None:
        write_fleet_table(rows, out)
    return rows


def _row(item: FleetInput, options: dict) -> FleetRow:
    """`characterize_input`, a refusal kept as the camera's row."""
    try:
        return characterize_input(item, **options)
    except UwlabError as exc:
        return FleetRow(item.label, str(item.path), None, str(exc))


def _rows_on_dask(
    inputs: list[FleetInput], options: dict, address: str, progress: Callable[[FleetRow], None] | None
) -> list[FleetRow]:
    from distributed import as_completed

    from uwlab.experiments.cluster import dask_client

    with dask_client(address) as client:
        futures = [client.submit(_row, item, options, pure=False) for item in inputs]
        index = {future.key: number for number, future in enumerate(futures)}
        rows: list[FleetRow | None] = [None] * len(inputs)
        for future in as_completed(futures):
            row = future.result()
            rows[index[future.key]] = row
            if progress is not None:
                progress(row)
    return [row for row in rows if row is not None]


def write_fleet_table(rows: list[FleetRow], out: Path) -> None:
    """``fleet.json`` (every row's document) and ``fleet.csv`` (the table's columns) in ``out``."""
    import pandas as pd

    documents = [r.document() for r in rows]
    (out / "fleet.json").write_text(dumps(documents, indent=2) + "\n")
    frame = pd.DataFrame([{k: v for k, v in d.items() if k != "notes"} for d in documents])
    frame.to_csv(out / "fleet.csv", index=False)
