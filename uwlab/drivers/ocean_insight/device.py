"""Ocean Insight (Ocean Optics) USB spectrometers through python-seabreeze, returning calibrated W/m²/nm.

`open_ocean_insight` opens the device by serial number (``resource``; None: the first one found) through
``seabreeze.spectrometers.Spectrometer`` on the chosen backend (``pyseabreeze``: pure Python over pyusb;
``cseabreeze``: the compiled libseabreeze, used by "auto" where it is installed) and returns an
`OceanInsightSpectrometer`: the rig's `uwlab.drivers.serial.base.Spectrometer` interface (integration time,
averaging, `read_spectrum` in W/m²/nm with `last_saturated`, read-backs), so a rig or ``uwlab spectrum`` can use
it like the serial spectrometer.

Each acquisition reads the *raw* counts (``Spectrometer.intensities()`` without corrections), so that saturation
is judged on the ADC's own scale (`uwlab.drivers.ocean_insight.radiometry.saturated`: within 1 % of
``max_intensity``); the device's electric-dark level and nonlinearity polynomial — the data seabreeze's
``correct_dark_counts`` / ``correct_nonlinearity`` use, read once through seabreeze's feature accessor
(``f.spectrometer.get_electric_dark_pixel_indices()``, ``f.nonlinearity_coefficients``) — are then applied in
seabreeze's order (`radiometry.linearize`). seabreeze's corrected output alone would hide a saturated pixel: its
dark-subtracted value sits ~2 % below full scale on a typical 16-bit device.

Dark D of the irradiance relation (`dark_mode`): "electric" (the device's electric-dark pixels, where it has
them), "measured" (a `DarkSpectrum` at the same integration time with the light blocked: `measure_dark`,
`use_dark`, `read_dark` / `write_dark`; a dark at another integration time is refused) or "none" (a rig whose
sweep subtracts its own light-off reading); "auto" is "electric" where the device has the pixels, else "none" (what
a rig opens with). seabreeze cannot read the integration time back: the read-back is
the value the device accepted last (set on opening to the definition's ``default_integration_ms``). Averaging is
done here (``averaging`` acquisitions, each corrected, averaged); a reading is saturated if any acquisition was.
"""

from __future__ import annotations

import csv
import importlib.util
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from uwlab.drivers.ocean_insight.radiometry import (
    AUTO_FRACTION,
    calibration_on,
    irradiance_w_m2_nm,
    linearize,
    next_integration_us,
    saturated,
)
from uwlab.drivers.ocean_insight.definition import CollectionAreaCm2, load_definition
from uwlab.drivers.ocean_insight.files import cosine_corrector_area_cm2
from uwlab.drivers.ocean_insight.radiometry import Calibration, read_calibration_file
from uwlab.drivers.serial.base import Spectrometer, check_averaging, check_integration_ms
from uwlab.errors import ConfigError, DeviceError
from uwlab.model.data import read_csv_columns
from uwlab.model.schema import check

DarkMode = Literal["electric", "measured", "none", "auto"]
AUTO_STEPS = 12
AREA_MATCH = 0.01
"""A collection area given with a calibration that states its own must agree with it within 1 %."""
DARK_COLUMNS = ("wavelength_nm", "dark_counts", "integration_ms")
WAVELENGTH_MATCH_NM = 1e-6
_backend_in_use: str | None = None


@dataclass(frozen=True)
class DarkSpectrum:
    """Dark counts per pixel (linearised, electric dark not subtracted) at ``integration_ms``, light blocked."""

    wavelength_nm: np.ndarray
    counts: np.ndarray
    integration_ms: float


def read_dark(path: str | Path) -> DarkSpectrum:
    """A dark spectrum written by `write_dark` (columns ``wavelength_nm, dark_counts, integration_ms``)."""
    columns = read_csv_columns(Path(path), DARK_COLUMNS, "dark")
    integration = np.unique(columns["integration_ms"])
    if integration.size != 1 or not integration[0] > 0:
        raise ConfigError("dark", str(path), "integration_ms must be one positive value for every row")
    return DarkSpectrum(columns["wavelength_nm"], columns["dark_counts"], float(integration[0]))


def write_dark(path: str | Path, dark: DarkSpectrum) -> Path:
    """Write ``dark`` to a new file; an existing file is never replaced (`ConfigError` on ``save-dark``)."""
    path = Path(path)
    try:
        with open(path, "x", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(DARK_COLUMNS)
            writer.writerows(
                (repr(float(w)), repr(float(c)), repr(dark.integration_ms))
                for w, c in zip(dark.wavelength_nm, dark.counts, strict=True)
            )
    except FileExistsError:
        raise ConfigError("save-dark", str(path), "file exists; refusing to overwrite it") from None
    except OSError as exc:
        raise ConfigError("save-dark", str(path), f"cannot write ({exc.strerror})") from None
    return path


def resolve_backend(backend: str) -> Literal["cseabreeze", "pyseabreeze"]:
    """ "auto" → ``cseabreeze`` where its compiled wrapper is installed, else ``pyseabreeze``."""
    if backend == "auto":
        return "cseabreeze" if importlib.util.find_spec("seabreeze.cseabreeze._wrapper") else "pyseabreeze"
    if backend == "cseabreeze":
        return "cseabreeze"
    if backend == "pyseabreeze":
        return "pyseabreeze"
    raise ConfigError("backend", backend, "must be auto, pyseabreeze or cseabreeze")


def seabreeze_spectrometer_class(backend: str) -> Any:
    """seabreeze's ``Spectrometer`` class on ``backend`` (``seabreeze.use`` once per process: the backend cannot be
    changed after the first device was opened)."""
    global _backend_in_use
    name = resolve_backend(backend)
    try:
        import seabreeze

        if _backend_in_use is None:
            seabreeze.use(name)
            _backend_in_use = name
        elif _backend_in_use != name:
            raise ConfigError("backend", backend, f"this process already uses {_backend_in_use}")
        from seabreeze.spectrometers import Spectrometer as SeabreezeSpectrometer
    except ImportError as exc:
        raise DeviceError(f"python-seabreeze backend {name} unavailable ({exc})") from None
    return SeabreezeSpectrometer


def _seabreeze_errors() -> tuple[type[BaseException], ...]:
    from seabreeze.spectrometers import SeaBreezeError  # both backends' errors derive from it

    return SeaBreezeError, OSError


class OceanInsightSpectrometer(Spectrometer):
    """An open Ocean Insight spectrometer (a seabreeze ``Spectrometer`` ``device``) returning W/m²/nm.

    ``calibration`` is (wavelength_nm, C [µJ/count]) of the lamp calibration, interpolated to the device's pixels
    here (refused where it does not cover them; None: counts only — `read_counts`, `read_raw` — as for
    calibrating); ``area_cm2`` the collection area A [cm²]; ``dark_mode`` the dark D (module docstring;
    "electric" needs the device's electric-dark pixels); ``nonlinearity`` applies the device's
    nonlinearity polynomial where it has one (`nonlinearity_corrected` says whether it does).
    """

    def __init__(
        self,
        device: Any,
        calibration: tuple[np.ndarray, np.ndarray] | None,
        area_cm2: float,
        *,
        dark_mode: DarkMode = "electric",
        nonlinearity: bool = True,
        integration_ms: float = 10.0,
        calibration_source: str = "calibration",
    ):
        self._device = device
        self._closed = False
        self._errors = _seabreeze_errors()
        try:
            self.serial = str(device.serial_number)
            self.model = str(device.model)
            self.wavelength_nm = np.asarray(device.wavelengths(), dtype=float)
            self.max_intensity = float(device.max_intensity)
            low_us, high_us = device.integration_time_micros_limits
            self._limits_us = (int(low_us), int(high_us))
            features = device.f
            self._dark_indices = list(features.spectrometer.get_electric_dark_pixel_indices())
            nonlinearity_feature = features.nonlinearity_coefficients
            coefficients = (
                nonlinearity_feature.get_nonlinearity_coefficients()
                if nonlinearity and nonlinearity_feature is not None
                else None
            )
        except self._errors as exc:
            self.close()
            raise DeviceError(f"Ocean Insight spectrometer: {exc}") from None
        self.port = self.serial
        self._coefficients = None if coefficients is None else np.asarray(coefficients, dtype=float)
        self.area_cm2 = float(area_cm2)
        self.dark_mode: DarkMode = dark_mode
        self.dark: DarkSpectrum | None = None
        self.last_saturated = False
        self._averaging = 1
        self._integration_us = 0
        try:
            self.uj_per_count = (
                None if calibration is None else calibration_on(*calibration, self.wavelength_nm, calibration_source)
            )
            if dark_mode == "auto":
                self.dark_mode = "electric" if self._dark_indices else "none"
            elif dark_mode == "electric" and not self._dark_indices:
                raise ConfigError(
                    "dark",
                    "electric",
                    f"{self.model} {self.serial} has no electric-dark pixels; "
                    "measure a dark spectrum (--dark FILE or --dark-now)",
                )
            self.set_integration_ms(integration_ms)
        except BaseException:
            self.close()
            raise

    @property
    def electric_dark_pixels(self) -> list[int]:
        """The indices of the device's optically masked (electric-dark) pixels: they never see light."""
        return list(self._dark_indices)

    @property
    def nonlinearity_corrected(self) -> bool:
        """Whether readings are corrected by the device's nonlinearity polynomial."""
        return self._coefficients is not None

    @property
    def recoveries(self) -> int:
        """Always 0: a USB spectrometer that disappears is not reopened; its next reading raises `DeviceError`."""
        return 0

    def identity(self) -> str:
        """Model and serial number with what its readings use (recorded with a sweep's devices)."""
        return (
            f"Ocean Insight {self.model} {self.serial} (dark {self.dark_mode}, nonlinearity "
            f"{'corrected' if self.nonlinearity_corrected else 'not corrected'}, A {self.area_cm2:g} cm²)"
        )

    def integration_ms_limits(self) -> tuple[float, float]:
        """The device's integration range [ms] (seabreeze's ``integration_time_micros_limits``)."""
        return self._limits_us[0] / 1000.0, self._limits_us[1] / 1000.0

    def set_integration_ms(self, integration_ms: float) -> None:
        """Set the integration time; `ConfigError` outside the device's range, before anything is sent."""
        low, high = self.integration_ms_limits()
        if isinstance(integration_ms, bool) or not np.isfinite(integration_ms) or not low <= integration_ms <= high:
            raise ConfigError(
                "integration_ms", integration_ms, f"must be in [{low:g}, {high:g}] ms ({self.model}'s range)"
            )
        self._set_integration_us(int(round(integration_ms * 1000.0)))

    def _set_integration_us(self, integration_us: int) -> None:
        self._call(self._device.integration_time_micros, integration_us)
        self._integration_us = integration_us

    def integration_ms(self) -> float:
        """The integration time the device accepted last [ms] (seabreeze cannot query it)."""
        return self._integration_us / 1000.0

    def set_averaging(self, averaging: int) -> None:
        self._averaging = check_averaging(averaging)

    def averaging(self) -> int:
        return self._averaging

    def reset(self) -> None:
        """Back to the driver's starting state: integration at the device's minimum × 10 (within range), no
        averaging, no measured dark."""
        self.set_averaging(1)
        low, high = self._limits_us
        self._set_integration_us(min(high, 10 * low))
        if self.dark_mode == "measured":
            self.dark = None

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            try:
                self._device.close()
            except self._errors:
                pass

    def _call(self, method, *args):
        try:
            return method(*args)
        except self._errors as exc:
            raise DeviceError(f"{self.port}: {exc}") from None

    def _acquire(self) -> tuple[np.ndarray, bool]:
        """One raw acquisition: (raw counts, saturated)."""
        raw = np.asarray(self._call(self._device.intensities), dtype=float)
        if raw.shape != self.wavelength_nm.shape:
            raise DeviceError(f"{self.port}: {raw.size} pixels read, {self.wavelength_nm.size} wavelengths")
        return raw, saturated(raw, self.max_intensity)

    def _averaged_counts(self, subtract_electric_dark: bool) -> tuple[np.ndarray, bool]:
        """Linearised counts averaged over `averaging` acquisitions, and whether any saturated."""
        total = np.zeros_like(self.wavelength_nm)
        any_saturated = False
        for _ in range(self._averaging):
            raw, is_saturated = self._acquire()
            counts, _ = linearize(raw, self._dark_indices, self._coefficients, subtract_electric_dark)
            total += counts
            any_saturated |= is_saturated
        return total / self._averaging, any_saturated

    def measure_dark(self) -> DarkSpectrum:
        """A dark spectrum at the current integration time and averaging (the caller has blocked the light)."""
        counts, _ = self._averaged_counts(subtract_electric_dark=False)
        return DarkSpectrum(self.wavelength_nm.copy(), counts, self.integration_ms())

    def use_dark(self, dark: DarkSpectrum, source: str = "dark") -> None:
        """Subtract ``dark`` from now on (`dark_mode` "measured"); refused unless it was taken on this device's
        pixels at the current integration time."""
        if (
            dark.wavelength_nm.shape != self.wavelength_nm.shape
            or np.max(np.abs(dark.wavelength_nm - self.wavelength_nm)) > WAVELENGTH_MATCH_NM
        ):
            raise ConfigError(
                "dark",
                source,
                f"its {dark.wavelength_nm.size} wavelengths are not the device's {self.wavelength_nm.size} pixels",
            )
        self._check_dark_integration(dark, source)
        self.dark_mode, self.dark = "measured", dark

    def _check_dark_integration(self, dark: DarkSpectrum, source: str) -> None:
        if abs(dark.integration_ms - self.integration_ms()) > 1e-3:
            raise ConfigError(
                "dark",
                source,
                f"taken at {dark.integration_ms:g} ms integration, the reading at "
                f"{self.integration_ms():g} ms; a dark must match the integration time",
            )

    def read_counts(self) -> tuple[np.ndarray, bool]:
        """(S − D [counts] per pixel, saturated) of one averaged reading with the configured dark."""
        if self.dark_mode == "measured":
            if self.dark is None:
                raise ConfigError("dark", None, "dark mode 'measured' needs a dark spectrum first")
            self._check_dark_integration(self.dark, "dark")
            counts, is_saturated = self._averaged_counts(subtract_electric_dark=False)
            return counts - self.dark.counts, is_saturated
        return self._averaged_counts(subtract_electric_dark=self.dark_mode == "electric")

    def read_raw(self) -> tuple[np.ndarray, bool]:
        """(raw counts per pixel as the device gives them — no electric dark, nonlinearity or dark subtracted —
        averaged over `averaging` acquisitions, saturated); sets `last_saturated`."""
        total = np.zeros_like(self.wavelength_nm)
        any_saturated = False
        for _ in range(self._averaging):
            raw, is_saturated = self._acquire()
            total += raw
            any_saturated |= is_saturated
        self.last_saturated = any_saturated
        return total / self._averaging, any_saturated

    def read_spectrum(self) -> tuple[np.ndarray, np.ndarray]:
        """One (averaged) reading: (wavelength_nm, spectral irradiance [W/m²/nm]); sets `last_saturated`."""
        if self.uj_per_count is None:
            raise ConfigError("calibration", None, "irradiance needs a calibration file (µJ/count)")
        counts, self.last_saturated = self.read_counts()
        irradiance = irradiance_w_m2_nm(
            counts, 0.0, self.uj_per_count, self.integration_ms() / 1000.0, self.area_cm2, self.wavelength_nm
        )
        return self.wavelength_nm.copy(), irradiance

    def auto_integration(self) -> float:
        """Choose the longest integration whose raw peak stays under 80 % of full scale
        (`radiometry.next_integration_us` from each trial reading, at most `AUTO_STEPS` readings), set it and
        return it [ms]; `DeviceError` when even the device's minimum integration reaches 80 %."""
        low, high = self._limits_us
        trial, best = self._integration_us, None
        for _ in range(AUTO_STEPS):
            self._set_integration_us(trial)
            raw, _ = self._acquire()
            peak = float(raw.max())
            _, baseline = linearize(raw, self._dark_indices, None, True)
            wanted = next_integration_us(trial, peak, baseline, self.max_intensity, self._limits_us)
            if peak < AUTO_FRACTION * self.max_intensity:
                best = trial if best is None else max(best, trial)
                if trial == high or wanted <= trial * 1.01:
                    break  # at the device's maximum, or within 1 % of the predicted best
                trial = wanted
            else:
                if trial == low:
                    raise DeviceError(
                        f"{self.port}: the peak reaches 80 % of full scale even at the minimum "
                        f"integration {low / 1000:g} ms"
                    )
                trial = max(low, min(wanted, int(trial * 0.95)))
                if best is not None and trial <= best:
                    break
        if best is None:
            raise DeviceError(
                f"{self.port}: no integration time under 80 % of full scale found in {AUTO_STEPS} readings"
            )
        self._set_integration_us(best)
        return self.integration_ms()


def open_ocean_insight(
    resource: str | None,
    calibration: tuple[np.ndarray, np.ndarray] | None,
    area_cm2: float,
    *,
    backend: str = "auto",
    spectrometer_class: Any = None,
    **options,
) -> OceanInsightSpectrometer:
    """Open the spectrometer with serial number ``resource`` (None: the first one found) on the python-seabreeze
    ``backend``; ``options`` go to `OceanInsightSpectrometer`. `DeviceError` when no such device is attached.
    ``spectrometer_class`` replaces seabreeze's ``Spectrometer`` class (a class with its API and its
    ``from_serial_number``, e.g. a simulated spectrometer chosen by the caller; the driver itself knows none)."""
    if spectrometer_class is None:
        spectrometer_class = seabreeze_spectrometer_class(backend)
    errors: tuple[type[BaseException], ...] = (*_seabreeze_errors(), ValueError)
    try:
        device = spectrometer_class.from_serial_number(resource)
    except errors as exc:  # pyusb's NoBackendError (no libusb) is a ValueError
        found = "the first spectrometer" if resource is None else f"spectrometer {resource!r}"
        raise DeviceError(
            f"{found}: not found through seabreeze's {resolve_backend(backend)} backend ({exc})"
        ) from None
    return OceanInsightSpectrometer(device, calibration, area_cm2, **options)


def collection_area_cm2(
    definition_area_cm2: float,
    calibration: Calibration | None,
    area_cm2: float | None = None,
    cosine_corrector: str | None = None,
) -> float:
    """The collection area A [cm²] a reading uses: ``area_cm2`` (``--area-cm2``) or ``cosine_corrector``'s
    (``--cosine-corrector CC-3``: its diffuser's area) when given, else the calibration file's own (an
    ``OOIIrrad.cal``'s ``Fiber (micron)`` diameter d: π (d/2)²), else the definition's. A calibration belongs to the
    optic it was made with: an area given that differs from the one the file states by more than `AREA_MATCH` is a
    `ConfigError`, as is giving both ``area_cm2`` and ``cosine_corrector``."""
    if area_cm2 is not None and cosine_corrector is not None:
        raise ConfigError("cosine-corrector", cosine_corrector, "give --area-cm2 or --cosine-corrector, not both")
    given, option = None, ""
    if area_cm2 is not None:
        given, option = check(CollectionAreaCm2, area_cm2, "area_cm2"), f"--area-cm2 {area_cm2:g}"
    elif cosine_corrector is not None:
        given, option = cosine_corrector_area_cm2(cosine_corrector), f"--cosine-corrector {cosine_corrector}"
    stated = None if calibration is None else calibration.area_cm2
    if given is not None and calibration is not None and stated is not None and abs(given / stated - 1) > AREA_MATCH:
        raise ConfigError(
            "area_cm2",
            given,
            f"the calibration {calibration.source} was made with a {stated:.5g} cm² optic (its Fiber (micron)); "
            f"{option} differs: a calibration belongs to its optic",
        )
    if given is not None:
        return given
    return stated if stated is not None else definition_area_cm2


def open_instrument(
    name: str,
    resource: str | None,
    calibration: str | Path | None,
    area_cm2: float | None = None,
    *,
    cosine_corrector: str | None = None,
    backend: str | None = None,
    integration_ms: float | None = None,
    dark_mode: DarkMode = "electric",
    spectrometer_class: Any = None,
) -> OceanInsightSpectrometer:
    """Open the spectrometer of instrument definition ``name`` (``configs/instruments/<name>.toml``) with the
    calibration file ``calibration`` (``*_OOIIrrad.cal`` or uwlab's CSV; None: counts only); the collection area is
    `collection_area_cm2`'s; ``backend`` and ``integration_ms`` default to the definition's;
    ``spectrometer_class`` as in `open_ocean_insight`. The definition, the calibration file and the values are
    checked before the device is opened."""
    definition = load_definition(name)
    loaded = None if calibration is None else read_calibration_file(calibration)
    area = collection_area_cm2(definition.collection_area_cm2, loaded, area_cm2, cosine_corrector)
    integration_ms = (
        definition.default_integration_ms if integration_ms is None else check_integration_ms(integration_ms)
    )
    return open_ocean_insight(
        resource,
        None if loaded is None else (loaded.wavelength_nm, loaded.uj_per_count),
        area,
        backend=backend or definition.backend,
        spectrometer_class=spectrometer_class,
        dark_mode=dark_mode,
        nonlinearity=definition.nonlinearity_correction,
        integration_ms=integration_ms,
        calibration_source=str(calibration),
    )
