"""Instruments from Python: `open_camera`, `open_light`, `open_spectrometer` (the drivers' own) and `grab` —
``uwlab devices``, ``uwlab grab``, ``uwlab light``, ``uwlab spectrum``.

Every device is a context manager: ``with uwlab.open_camera("sim") as cam: ...`` closes it (and a light goes to its
safe state) on any exit. Limits are checked before anything is sent; every setting is read back.

>>> import uwlab
>>> with uwlab.open_camera("sim") as cam:
...     cam.exposure_us = 1000.0
...     frame = next(cam.stream(1))
>>> frame.settings.exposure_us, frame.image.ndim
(1000.0, 2)
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from uwlab.errors import ConfigError

from uwlab.experiments.acquisition.grab import Grabbed as Grab

__all__ = ["Grab", "grab", "open_camera", "open_light", "open_spectrometer"]

if TYPE_CHECKING:
    from uwlab.drivers.camera import Camera, Policy
    from uwlab.drivers.serial import Light, Spectrometer


def open_camera(
    backend: str = "sim", device_id: str | None = None, policy: Policy | None = None, **options: Any
) -> Camera:
    """Open a camera (`uwlab.drivers.camera.open_camera`): `backend` ``"sim"``, ``"harvesters"`` (GenTL;
    ``cti=[...]``) or ``"aravis"``; `device_id` the first found when None; ``config=RIG.toml`` for the simulated
    camera's rig. Returns the `uwlab.drivers.camera.Camera` (a context manager).

    Examples
    --------
    See the module docstring.
    """
    from uwlab.drivers.camera import open_camera as open_device

    return open_device(backend, device_id, policy, **options)


def open_light(
    port: str,
    protocol: str | None = None,
    *,
    instrument: str | None = None,
    visa_library: str | None = None,
    max_current_a: float | None = None,
    forward_voltage_v: float | None = None,
    identity_contains: tuple[str, ...] = (),
    **options: Any,
) -> Light:
    """Open a light. With `instrument` (a definition in configs/instruments/ or a file, docs/instruments.md),
    `port` is its resource (a VISA resource, or a serial port for ``uwlab-ascii``), `visa_library` PyVISA's
    (``@py`` by default, ``PATH.yaml@sim`` for pyvisa-sim), `max_current_a` the rig's LED rating (the full level:
    a level above it is refused before anything is sent), `forward_voltage_v` its LED's maximum forward voltage (a
    CV/CC supply's compliance voltage: this plus the definition's margin) and `identity_contains` words its
    ``*IDN?`` must contain (`uwlab.drivers.instruments.LightRig`, `open_light_instrument`): every set is checked as
    sent, error-checked and read back, a CV/CC supply must deliver the set current in CC, the output off on exit.
    Without it, the ``uwlab-ascii`` controller on a serial `port` (`uwlab.drivers.serial.open_light`;
    `protocol` default the drivers' first). Returns the `Light` (a context manager).

    Examples
    --------
    >>> import uwlab
    >>> from uwlab.model.data import config_dir
    >>> sim = config_dir() / "instruments" / "sim" / "keysight-e36100.yaml"
    >>> resource = "USB0::0x2A8D::0x0702::MY00000001::INSTR"
    >>> with uwlab.open_light(
    ...     resource, instrument="keysight-e36100", visa_library=f"{sim}@sim", max_current_a=0.6
    ... ) as light:
    ...     light.set_level(0.5)
    ...     light.set_output(True)  # in CC, delivering the set current (the simulator's LED draws 0.3 A)
    ...     light.state()["current_a"]  # 0.5 of the rig's 0.6 A
    0.3
    >>> light.safe_state_reached
    True
    >>> with uwlab.open_light("/dev/ttyUSB0") as light:  # doctest: +SKIP
    ...     light.set_level(0.5)
    """
    if instrument is not None:
        from uwlab.drivers.instruments import open_light_instrument

        return open_light_instrument(
            instrument, port, visa_library, max_current_a, forward_voltage_v, tuple(identity_contains)
        )
    from uwlab.drivers import serial

    return serial.open_light(port, protocol, **options) if protocol else serial.open_light(port, **options)


def open_spectrometer(
    port: str | None = None,
    protocol: str | None = None,
    *,
    instrument: str | None = None,
    calibration: str | Path | None = None,
    area_cm2: float | None = None,
    backend: str | None = None,
    integration_ms: float | None = None,
    **options: Any,
) -> Spectrometer:
    """Open a spectrometer. With `instrument` (a definition in configs/instruments/, e.g. ``"ocean-insight"``:
    an Ocean Insight spectrometer through python-seabreeze, docs/spectrometers.md), `port` is its serial number
    (None: the first found), `calibration` the lamp calibration file (``wavelength_nm, uJ_per_count``) that turns
    its counts into W/m²/nm, `area_cm2`, `backend` and `integration_ms` default to the definition's
    (`uwlab.drivers.ocean_insight.open_instrument`; ``dark_mode`` in `options`). Without it, the ``uwlab-ascii``
    spectrometer on a serial `port`, already calibrated (`uwlab.drivers.serial.open_spectrometer`). Returns the
    `Spectrometer` (a context manager).

    Examples
    --------
    >>> import uwlab
    >>> with uwlab.open_spectrometer("/dev/ttyUSB1") as spectrometer:  # doctest: +SKIP
    ...     wavelength_nm, irradiance_w_m2_nm = spectrometer.read_spectrum()
    >>> with uwlab.open_spectrometer(instrument="ocean-insight", calibration="cc3-lamp.csv") as flame:  # doctest: +SKIP
    ...     wavelength_nm, irradiance_w_m2_nm = flame.read_spectrum()
    """
    if instrument is not None:
        from uwlab.drivers.ocean_insight import open_instrument

        if calibration is None:
            raise ConfigError(
                "calibration", None, f"{instrument} needs a calibration file (wavelength_nm, uJ_per_count)"
            )
        return open_instrument(
            instrument, port, calibration, area_cm2, backend=backend, integration_ms=integration_ms, **options
        )
    given = {"calibration": calibration, "area_cm2": area_cm2, "backend": backend, "integration_ms": integration_ms}
    for key, value in given.items():
        if value is not None:
            raise ConfigError(key, value, "needs instrument (a serial uwlab-ascii spectrometer is calibrated)")
    if port is None:
        raise ConfigError("port", None, "the serial port of the spectrometer (or give instrument)")
    from uwlab.drivers import serial

    if protocol:
        return serial.open_spectrometer(port, protocol, **options)
    return serial.open_spectrometer(port, **options)


def grab(
    backend: str | None = None,
    device_id: str | None = None,
    *,
    frames: int = 1,
    exposure_us: float | None = None,
    gain_db: float | None = None,
    pixel_format: str | None = None,
    roi: tuple[int, int, int, int] | None = None,
    bayer: str | None = None,
    config: str | None = None,
    sensor: str | None = None,
    cti: list[str] | None = None,
    fake: bool = False,
    timeout_s: float = 5.0,
    save: str | os.PathLike[str] | None = None,
) -> Grab:
    """Acquire `frames` frames with read-back settings and their statistics (``uwlab grab``).

    Parameters
    ----------
    backend, device_id, cti, config, fake
        The camera (`open_camera`; `fake`: the backend's test camera, e.g. Aravis's ``Fake_1``; `config`: the
        simulated camera's rig, a bundled one by name: ``"rigs/sim-tank.toml"``). `backend` None:
        the simulated camera, or with `fake` Aravis (``uwlab grab``'s defaults).
    exposure_us, gain_db, pixel_format, roi
        Settings applied first (checked against plausibility limits, read back); None leaves the camera's.
    bayer
        The colour filter layout (``"RG"``, ``"GR"``, ``"GB"``, ``"BG"``) the camera must deliver; the statistics
        then have a row per colour channel (``channels``).
    sensor
        The sensor profile (name or TOML) giving the saturation clip level (default for ``"sim"``: its rig's;
        else detected from the frames).
    save
        A folder (created if its parent exists, as ``uwlab grab --save``) receiving each frame as TIFF with its
        settings in the metadata (`Grab.saved`: the files).

    Returns
    -------
    Grab

    Examples
    --------
    >>> import uwlab
    >>> shots = uwlab.grab("sim", frames=2, exposure_us=2000, roi=(0, 0, 64, 48))
    >>> len(shots.images), shots.images[0].shape, shots.stats["exposure_us"].tolist()
    (2, (48, 64), [2000.0, 2000.0])
    """
    from uwlab.api.paths import config_file, python_names
    from uwlab.experiments.acquisition.grab import Settings, grab_frames

    settings = Settings(exposure_us=exposure_us, gain_db=gain_db, pixel_format=pixel_format, roi=roi, bayer=bayer)
    with python_names():
        return grab_frames(
            backend,
            device_id,
            frames=frames,
            sensor=sensor,
            config=None if config is None else str(config_file(config, "config")),
            cti=cti,
            fake=fake,
            timeout_s=timeout_s,
            settings=settings,
            save_dir=save,
        )
