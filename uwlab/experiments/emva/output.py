"""Writing an EMVA 1288 characterisation to disk, as `uwlab.experiments.calibration.output` does for a fit.

Files in the output directory: ``emva.json`` (the parameters, their uncertainties, notes and the list of files),
the plots of `uwlab.experiments.emva.plots`, and — when the pixel size is known — a sensor profile
``<name>.toml`` with its flat QE curve ``<name>_qe.csv`` (`uwlab.experiments.emva.profile`) that `uwlab design`
reads. Nothing existing is overwritten: every target is checked before anything is written.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from uwlab.errors import ConfigError
from uwlab.experiments.emva.analysis import EmvaResult, PhotonTransfer
from uwlab.experiments.emva.plots import PLOT_NAMES, write_plots
from uwlab.experiments.emva.profile import profile_documents
from uwlab.jsonable import dumps, to_jsonable
from uwlab.model.sensor import SensorProfile
from uwlab.outputs import output_dir

RESULT_NAME = "emva.json"


def profile_name(text: str) -> str:
    """A file-name-safe profile name: lower case, runs of other characters as ``-``.

    >>> profile_name("measured-SimCam IMX250")
    'measured-simcam-imx250'
    """
    return "".join(ch if ch.isalnum() or ch in "-_" else "-" for ch in text.lower()).strip("-") or "camera"


@dataclass(frozen=True)
class OutputPaths:
    """Where a characterisation goes: the result and plots, and the profile's TOML and QE CSV (None: unknown
    pixel size, no profile)."""

    result: Path
    plots: tuple[Path, ...]
    profile: tuple[Path, Path] | None

    def all(self) -> list[Path]:
        return [self.result, *self.plots, *(self.profile or ())]


def output_paths(out: Path, name: str, with_profile: bool) -> OutputPaths:
    """The files a characterisation writes into ``out``; refuses (`ConfigError` on ``--out``) if any exists or
    ``out`` is not a place to write (`uwlab.outputs.output_dir`)."""
    out = output_dir(out, "--out")
    paths = OutputPaths(out / RESULT_NAME, tuple(out / n for n in PLOT_NAMES),
                        (out / f"{name}.toml", out / f"{name}_qe.csv") if with_profile else None)
    for path in paths.all():
        if path.exists():
            raise ConfigError("--out", str(path), "exists; refusing to overwrite")
    return paths


def result_document(result: EmvaResult) -> dict:
    """The JSON document of a characterisation (``emva.json``, ``uwlab emva characterize --json``)."""
    return to_jsonable(result.values)


def write_characterization(result: EmvaResult, pt: PhotonTransfer, paths: OutputPaths, *, name: str,
                           base: SensorProfile | None, pixel_size_um: float | None) -> dict:
    """Write the plots, the profile (when its paths are given) and ``emva.json``; returns the document written."""
    document = result_document(result)
    document["files"] = [str(p) for p in paths.all()]
    if paths.profile is None:
        document["notes"] = [*document["notes"], "no sensor profile written: pixel size unknown (--pixel-size-um)"]
    paths.result.parent.mkdir(exist_ok=True)
    write_plots(result, paths.result.parent)
    if paths.profile is not None:
        exposure_us = (float(pt.exposure_s.min() * 1e6), float(pt.exposure_s.max() * 1e6))
        toml_text, csv_text = profile_documents(result.values, name=name, width_px=pt.width_px,
                                                height_px=pt.height_px, exposure_range_us=exposure_us,
                                                pixel_size_um=pixel_size_um, base=base)
        paths.profile[0].write_text(toml_text)
        paths.profile[1].write_text(csv_text)
    paths.result.write_text(dumps(document, indent=2) + "\n")
    return document
