"""Writing an EMVA 1288 characterisation to disk, as `uwlab.experiments.calibration.output` does for a fit.

Files in the output directory: ``emva.json`` (the parameters, their uncertainties, notes, the list of files and the
software and machine that computed them, `uwlab.provenance`, which the datasheet, the XML and the profile name too),
``datasheet.html`` (`uwlab.experiments.emva.datasheet`), ``emva1288.xml`` (`uwlab.experiments.emva.results_xml`), the
figures of `uwlab.experiments.emva.plots`, and — for the linear model when the pixel size is known — a sensor
profile ``<name>.toml`` with its flat QE curve ``<name>_qe.csv`` (`uwlab.experiments.emva.profile`) that
`uwlab design` reads. Nothing existing is overwritten: every target is checked before anything is written.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from uwlab.errors import ConfigError
from uwlab.experiments.emva.analysis import EmvaResult
from uwlab.experiments.emva.transfer import PhotonTransfer
from uwlab.jsonable import dumps, to_jsonable
from uwlab.outputs import output_dir
from uwlab.provenance import provenance

if TYPE_CHECKING:
    from uwlab.model.sensor import SensorProfile

RESULT_NAME = "emva.json"
DATASHEET_NAME = "datasheet.html"
XML_NAME = "emva1288.xml"


def profile_name(text: str) -> str:
    """A file-name-safe profile name: lower case, runs of other characters as ``-``.

    >>> profile_name("measured-SimCam IMX250")
    'measured-simcam-imx250'
    """
    return "".join(ch if ch.isalnum() or ch in "-_" else "-" for ch in text.lower()).strip("-") or "camera"


@dataclass(frozen=True)
class OutputPaths:
    """Where a characterisation goes: the result, datasheet, XML and figures, and the profile's TOML and QE CSV
    (None: no profile)."""

    result: Path
    datasheet: Path
    xml: Path
    plots: tuple[Path, ...]
    profile: tuple[Path, Path] | None

    def all(self) -> list[Path]:
        return [self.result, self.datasheet, self.xml, *self.plots, *(self.profile or ())]


def output_paths(out: Path, result: EmvaResult, name: str, with_profile: bool) -> OutputPaths:
    """The files a characterisation writes into ``out``; refuses (`ConfigError` on ``--out``) if any exists or
    ``out`` is not a place to write (`uwlab.outputs.output_dir`)."""
    from uwlab.experiments.emva.plots import figure_names

    out = output_dir(out, "--out")
    with_profile = with_profile and result.model == "linear"
    paths = OutputPaths(
        out / RESULT_NAME,
        out / DATASHEET_NAME,
        out / XML_NAME,
        tuple(out / f"{n}.png" for n in figure_names(result)),
        (out / f"{name}.toml", out / f"{name}_qe.csv") if with_profile else None,
    )
    for path in paths.all():
        if path.exists():
            raise ConfigError("--out", str(path), "exists; refusing to overwrite")
    return paths


def result_document(result: EmvaResult) -> dict:
    """The JSON document of a characterisation (``emva.json``, ``uwlab emva characterize --json``): its values and
    ``provenance`` (`uwlab.provenance.provenance`)."""
    return {**to_jsonable(result.values), "provenance": provenance()}


def write_characterization(
    result: EmvaResult,
    pt: PhotonTransfer,
    paths: OutputPaths,
    *,
    name: str,
    base: SensorProfile | None,
    pixel_size_um: float | None,
    info=None,
) -> dict:
    """Write the figures, datasheet, XML, the profile (when its paths are given) and ``emva.json``; returns the
    document written."""
    from uwlab.experiments.emva.datasheet import SheetInfo, write_datasheet
    from uwlab.experiments.emva.plots import figure_pngs
    from uwlab.experiments.emva.profile import profile_documents
    from uwlab.experiments.emva.results_xml import write_results_xml

    document = result_document(result)
    document["files"] = [str(p) for p in paths.all()]
    if paths.profile is None:
        why = (
            "the general model measures no K or η"
            if result.model == "general"
            else "pixel size unknown (--pixel-size-um)"
        )
        document["notes"] = [*document["notes"], f"no sensor profile written: {why}"]
    out = paths.result.parent
    try:
        out.mkdir(exist_ok=True)
        figures = figure_pngs(result)
        for path in paths.plots:
            path.write_bytes(figures[path.stem])
        write_datasheet(result, figures, paths.datasheet, info or SheetInfo(), document["provenance"])
        write_results_xml(result, paths.xml, document["provenance"])
        if paths.profile is not None:
            exposure_us = (float(np.min(pt.exposure_s) * 1e6), float(np.max(pt.exposure_s) * 1e6))
            toml_text, csv_text = profile_documents(
                result.values,
                name=name,
                width_px=pt.width_px,
                height_px=pt.height_px,
                exposure_range_us=exposure_us,
                pixel_size_um=pixel_size_um,
                base=base,
                made_with=document["provenance"],
            )
            paths.profile[0].write_text(toml_text)
            paths.profile[1].write_text(csv_text)
        paths.result.write_text(dumps(document, indent=2) + "\n")
    except OSError as exc:
        raise ConfigError("--out", str(out), f"cannot write ({exc.strerror or exc})") from None
    return document
