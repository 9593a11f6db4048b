"""EMVA 1288 from Python: `characterize` and its `EmvaResult` — ``uwlab emva characterize``.

The figures are those of EMVA Standard 1288 Release 4.0 (Linear, or General for non-linear cameras), computed by
`uwlab.experiments.emva` (docs/emva.md gives the method and equation of each).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from uwlab.errors import ConfigError

if TYPE_CHECKING:
    import pandas as pd

    from uwlab.experiments.acquisition.plan import Plan

    from uwlab.api.campaign import Dataset
    from uwlab.experiments.emva.analysis import EmvaResult as Analysis
    from uwlab.experiments.emva.datasheet import SheetInfo
    from uwlab.experiments.emva.transfer import PhotonTransfer
    from uwlab.experiments.figures import Figure
    from uwlab.model.sensor import SensorProfile


class EmvaResult:
    """An EMVA 1288 characterisation: the figures as attributes (``K_dn_per_e``, ``quantum_efficiency``,
    ``dark_noise_e``, ``saturation_e``, ``snr_max_db``, ``dynamic_range_db``, ``linearity_error_percent``,
    ``dark_current_e_per_s``, ``dsnu_e``, ``prnu_percent``, ... — every key of ``emva.json``; None where the model
    or the data give none), `to_xml` (the reference implementation's XML), `datasheet` (the HTML datasheet),
    `sensor_profile` (a profile `uwlab.load_design` can use), `figures` (the EMVA figures as matplotlib Figures)
    and `write` (everything ``--out`` writes).

    Examples
    --------
    >>> import tempfile, uwlab
    >>> from uwlab.experiments.emva.simulate import simulate_photon_transfer
    >>> from uwlab.model.sensor import load_sensor_profile
    >>> from uwlab.sim.devices.camera import SimTruth
    >>> truth = SimTruth.from_sensor_profile(load_sensor_profile("imx250m"), resolution_px=(32, 32))
    >>> root = tempfile.mkdtemp() + "/pt"
    >>> _ = simulate_photon_transfer(root, truth, rate_e_per_s=2e6, quantum_efficiency=0.6,
    ...                              exposures_us=[50 * i for i in range(1, 25)], dark_exposures_us=[1e5, 3e5])
    >>> result = uwlab.characterize(root)
    >>> abs(result.K_dn_per_e / truth.K_dn_per_e - 1) < 0.05, result.model
    (True, 'linear')
    >>> result.to_xml().startswith("<?xml")
    True
    >>> figures = result.figures()
    >>> list(figures)[:3], figures["snr"].axes[0].get_ylabel()
    (['photon_transfer', 'snr', 'linearity'], 'SNR')
    """

    def __init__(
        self,
        analysis: Analysis,
        transfer: PhotonTransfer,
        *,
        camera: str = "camera",
        base: SensorProfile | None = None,
        info: SheetInfo | None = None,
        pixel_size_um: float | None = None,
    ) -> None:
        self.analysis = analysis
        self.transfer = transfer
        self.camera = camera
        self.base = base
        self.info = info
        self.pixel_size_um = pixel_size_um

    @property
    def values(self) -> dict[str, Any]:
        """Every figure, note and curve summary as JSON-able values (the document of ``emva.json``)."""
        from uwlab.experiments.emva.output import result_document

        document: dict[str, Any] = result_document(self.analysis)
        return document

    @property
    def model(self) -> str:
        """``"linear"`` or ``"general"``."""
        return str(self.analysis.model)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_") or name in ("analysis", "transfer"):
            raise AttributeError(name)
        values = self.analysis.values
        if name in values:
            return values[name]
        raise AttributeError(f"EmvaResult has no figure {name!r}")

    def __dir__(self) -> list[str]:
        return sorted({*super().__dir__(), *self.analysis.values})

    def to_pandas(self) -> pd.Series:
        """The scalar figures as a Series (index: the ``emva.json`` keys)."""
        import pandas as pd

        scalars = {k: v for k, v in self.values.items() if isinstance(v, (int, float)) or v is None}
        return pd.Series(scalars, dtype=object)

    def to_xml(self) -> str:
        """The characterisation as the EMVA 1288 reference implementation's XML
        (`uwlab.experiments.emva.results_xml`)."""
        from uwlab.experiments.emva.results_xml import results_xml

        return str(results_xml(self.analysis))

    def figures(self) -> Mapping[str, Figure]:
        """The EMVA 1288 figures the data allow, by name, as matplotlib Figures (a notebook shows each inline):
        ``photon_transfer`` (the general model: ``characteristic``), ``snr``, ``linearity`` (linear model),
        ``stability``, ``dark_current``, then where measured ``dark_current_temperature``, ``spatial_variances``
        and the DSNU/PRNU spectrograms, profiles and histograms — the same figures as the datasheet and the
        ``NAME.png`` files of `write` (`uwlab.experiments.emva.plots`). Each is drawn when first asked for
        (`uwlab.experiments.figures.DrawnOnDemand`)."""
        from uwlab.experiments.emva.plots import figures

        return figures(self.analysis)

    def datasheet(self, path: str | os.PathLike[str]) -> Path:
        """Write the self-contained HTML datasheet (figures embedded) to `path`; returns it."""
        from uwlab.experiments.emva.datasheet import SheetInfo, write_datasheet
        from uwlab.experiments.emva.plots import figure_pngs
        from uwlab.outputs import output_file

        target = output_file(path, "path")
        return write_datasheet(self.analysis, figure_pngs(self.analysis), target, self.info or SheetInfo())

    def sensor_profile(self, name: str | None = None, directory: str | os.PathLike[str] | None = None) -> SensorProfile:
        """The measured sensor profile (linear model only: K, η, dark noise, saturation; the rest from the
        dataset's named profile), written as ``<name>.toml`` and ``<name>_qe.csv`` into `directory` (default a
        temporary one) and loaded, ready for a design's ``sensor.profile``."""
        import numpy as np

        from uwlab.experiments.emva.output import profile_name
        from uwlab.experiments.emva.profile import profile_documents
        from uwlab.model.sensor import load_sensor_profile

        if self.model != "linear":
            raise ConfigError("model", self.model, "the general model measures no K or η: no sensor profile")
        stem = profile_name(name or f"measured-{self.camera}")
        pt = self.transfer
        exposure_us = (float(np.min(pt.exposure_s) * 1e6), float(np.max(pt.exposure_s) * 1e6))
        toml_text, csv_text = profile_documents(
            self.analysis.values,
            name=stem,
            width_px=pt.width_px,
            height_px=pt.height_px,
            exposure_range_us=exposure_us,
            pixel_size_um=self.pixel_size_um,
            base=self.base,
        )
        folder = Path(directory) if directory is not None else Path(tempfile.mkdtemp(prefix="uwlab-profile-"))
        (folder / f"{stem}.toml").write_text(toml_text)
        (folder / f"{stem}_qe.csv").write_text(csv_text)
        return load_sensor_profile(str(folder / f"{stem}.toml"))

    def write(self, out: str | os.PathLike[str], name: str | None = None) -> dict[str, Any]:
        """Write everything ``uwlab emva characterize --out`` writes (emva.json, datasheet, XML, figures, the
        profile) into the new or empty directory `out`; returns the ``emva.json`` document."""
        from uwlab.api.paths import python_names
        from uwlab.experiments.emva.output import output_paths, profile_name, write_characterization

        stem = profile_name(name or f"measured-{self.camera}")
        with python_names():
            paths = output_paths(Path(out), self.analysis, stem, bool(self.pixel_size_um or self.base))
        document: dict[str, Any] = write_characterization(
            self.analysis,
            self.transfer,
            paths,
            name=stem,
            base=self.base,
            pixel_size_um=self.pixel_size_um,
            info=self.info,
        )
        return document

    def __repr__(self) -> str:
        k, eta = self.analysis.values.get("K_dn_per_e"), self.analysis.values.get("quantum_efficiency")
        return f"EmvaResult({self.camera!r}, model={self.model!r}, K_dn_per_e={k!r}, quantum_efficiency={eta!r})"


def characterize(
    source: Dataset | PhotonTransfer | str | os.PathLike[str],
    *,
    model: str = "linear",
    sweep: str | None = None,
    pixel_size_um: float | None = None,
    channel: str | None = None,
    irradiance: float | str | os.PathLike[str] | None = None,
    wavelength_nm: float | None = None,
) -> EmvaResult:
    """EMVA 1288 Release 4.0 characterisation of a camera (``uwlab emva characterize``), or of one colour channel of
    a colour camera's raw Bayer sweep (Release 4.0 Linear §1.2: each channel is a sensor of its own).

    Parameters
    ----------
    source
        A sweep dataset (a `Dataset` or its directory), an EMVA 1288 descriptor file (``EMVA1288*.txt``), or the
        measurement arrays as a `uwlab.experiments.emva.transfer.PhotonTransfer`.
    model
        ``"linear"`` (Release 4.0 Linear) or ``"general"`` (non-linear cameras).
    sweep
        The dataset's photon-transfer sweep (default: the only one).
    pixel_size_um
        The pixel pitch (default: the dataset's sensor profile; needed for a descriptor's sensor profile).
    channel
        ``"red"``, ``"green"`` or ``"blue"``: that channel of a dataset's raw Bayer sweep, from its per-channel
        statistics (required for a colour sweep; refused for a monochrome one). Its η is the channel's QE at the
        light's wavelength.
    irradiance, wavelength_nm
        The irradiance at the sensor plane replacing a dataset's spectrometer readings (``uwlab emva characterize
        --irradiance``): a number in W/m² of monochromatic light at `wavelength_nm`, or a spectrum CSV
        (``wavelength_nm, irradiance_w_m2_nm``).

    Returns
    -------
    EmvaResult

    Examples
    --------
    See `EmvaResult`.
    """
    from uwlab.api.campaign import dataset_path
    from uwlab.api.paths import python_names
    from uwlab.experiments.emva.analysis import characterize as run
    from uwlab.experiments.emva.transfer import PhotonTransfer
    from uwlab.model.schema import PixelSizeUm, WavelengthNm, check

    if pixel_size_um is not None:
        check(PixelSizeUm, pixel_size_um, "pixel_size_um")
    if wavelength_nm is not None:
        check(WavelengthNm, wavelength_nm, "wavelength_nm")
    if irradiance is not None and (isinstance(source, PhotonTransfer) or dataset_path(source).is_file()):
        raise ConfigError("irradiance", irradiance, "replaces a dataset's readings; this source has its own")
    if isinstance(source, PhotonTransfer):
        if channel is not None:
            raise ConfigError("channel", channel, "for a dataset; a PhotonTransfer is one sensor's already")
        return EmvaResult(run(source, model), source, pixel_size_um=pixel_size_um)
    path = dataset_path(source)
    if path.is_file():
        if channel is not None:
            raise ConfigError("channel", channel, "for a dataset; a descriptor holds one sensor")
        from uwlab.experiments.emva.descriptor import parse_descriptor, photon_transfer_from_descriptor, sheet_info

        pt = photon_transfer_from_descriptor(path, pixel_size_um)
        info = sheet_info(parse_descriptor(path))
        camera = info.model if info.model != "—" else "descriptor"
        return EmvaResult(run(pt, model), pt, camera=camera, info=info, pixel_size_um=pixel_size_um)
    if not path.is_dir():
        raise ConfigError("source", str(path), "neither a dataset directory nor a descriptor file")
    from uwlab.experiments.emva.from_dataset import CHANNELS, IrradianceOverride, load_dataset_inputs

    with python_names():
        inputs = load_dataset_inputs(
            path,
            sweep_id=sweep,
            pixel_size_um=pixel_size_um,
            override=IrradianceOverride.given(irradiance, wavelength_nm),
            wavelength_nm=wavelength_nm,
            channel=channel,
        )
    if len(inputs) > 1:
        raise ConfigError(
            "channel",
            None,
            f"a colour (raw Bayer) sweep: choose one of {', '.join(CHANNELS)} (each is a sensor of its own, "
            "EMVA 1288 Release 4.0 Linear §1.2)",
        )
    loaded = next(iter(inputs.values()))
    return EmvaResult(
        run(loaded.transfer, model),
        loaded.transfer,
        camera=loaded.camera,
        base=loaded.profile,
        info=loaded.info,
        pixel_size_um=pixel_size_um,
    )


def characterize_on_bench(plan: Plan | str | os.PathLike[str], *, seed: int = 0) -> dict[str, EmvaResult]:
    """Each camera of a plan characterised on the simulated EMVA 1288 bench, as a lab characterises its cameras
    before a tank campaign (``uwlab demo``'s step 3): the plan's simulated sensor (its profile and the rig world's
    sensor realism: the non-linearity near full well, DSNU, PRNU, hot pixels) under flat light of known photon
    irradiance, 40 exposures from 1 % to 110 % of saturation and a dark series, characterised by the Release 4.0
    linear model. ``result.write(DIR)`` writes what ``uwlab emva characterize --out DIR`` writes, the sensor
    profile with its measured response curve among it: the ``sensor=`` of `uwlab.fit`.

    Parameters
    ----------
    plan
        A plan (`uwlab.load_plan`) or its file (a bundled plan by name: ``"plans/tank-exposure-sweep.toml"``).
    seed
        Seeds the bench's noise (equal seeds, equal figures; ``uwlab demo --seed``).

    Returns
    -------
    dict
        {camera (the plan's sensor profile name): `EmvaResult`}.

    Examples
    --------
    >>> import uwlab
    >>> cameras = uwlab.characterize_on_bench("plans/tank-exposure-sweep.toml")  # doctest: +SKIP
    >>> {name: round(result.K_dn_per_e, 3) for name, result in cameras.items()}  # doctest: +SKIP
    {'icx285alm': 1.11, 'imx250m': 0.347}
    """
    from uwlab.api.campaign import load_plan
    from uwlab.experiments.acquisition.plan import Plan
    from uwlab.experiments.demo import bench_characterisations, bench_sheet_info

    loaded = plan if isinstance(plan, Plan) else load_plan(os.fspath(plan))
    return {
        name: EmvaResult(analysis, pt, camera=name, base=profile, info=bench_sheet_info(profile))
        for name, (analysis, pt, profile) in bench_characterisations(loaded, seed).items()
    }
