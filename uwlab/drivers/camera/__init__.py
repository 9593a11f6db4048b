"""Cameras: one interface (`Camera`), backends ``harvesters`` (GenTL), ``aravis`` and the simulated ``sim``.

`open_camera` picks a backend by name; `discover` lists cameras on every backend, reporting
backends whose libraries are missing instead of failing. Backends are declared as entry points of the group
``uwlab.camera_backends`` (pyproject.toml): the simulated camera (`uwlab.sim.devices.camera`) is one of them, so
this package names no simulator module and a real backend never needs one; another package can add a backend the
same way.
"""

from __future__ import annotations

import functools
import importlib
from types import ModuleType
from typing import Any

from uwlab.drivers.camera.interface import (
    AcquisitionStats,
    Camera,
    CameraInfo,
    DeviceEntry,
    DeviceLost,
    Frame,
    FrameTimeout,
    Policy,
    RawFrame,
    Settings,
    Transport,
)
from uwlab.errors import ConfigError, DeviceError

ENTRY_POINT_GROUP = "uwlab.camera_backends"


@functools.cache
def _backends() -> dict[str, str]:
    """Backend name -> module, in the order pyproject.toml declares them: `BACKENDS`, read from the installed
    distributions' entry points when first asked for (~15 ms, which a command that never opens a camera, such as
    ``uwlab emva characterize``, need not pay)."""
    from importlib.metadata import entry_points

    return {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)}


def __getattr__(name: str) -> Any:
    """``BACKENDS`` (`_backends`), read when first used."""
    if name == "BACKENDS":
        return _backends()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "AcquisitionStats",
    "BACKENDS",
    "BackendUnavailable",
    "Camera",
    "CameraInfo",
    "DeviceEntry",
    "DeviceLost",
    "Frame",
    "FrameTimeout",
    "Policy",
    "RawFrame",
    "Settings",
    "Transport",
    "backend_module",
    "discover",
    "open_camera",
]


class BackendUnavailable(DeviceError):
    """A backend's library (PyGObject/Aravis, harvesters/GenTL producer) is not installed."""


def backend_module(name: str) -> ModuleType:
    backends = _backends()
    if name not in backends:
        raise ConfigError("backend", name, f"expected one of {', '.join(backends)}")
    try:
        module = importlib.import_module(backends[name])
    except ImportError as exc:
        raise BackendUnavailable(f"{name}: not installed ({exc})") from exc
    return module


def discover(backends: tuple[str, ...] | None = None, **options: Any) -> tuple[list[DeviceEntry], dict[str, str]]:
    """Cameras on `backends` (None: every backend), and ``{backend: reason}`` for backends that are unavailable."""
    found: list[DeviceEntry] = []
    unavailable: dict[str, str] = {}
    for name in _backends() if backends is None else backends:
        try:
            found.extend(backend_module(name).discover(**options))
        except BackendUnavailable as exc:
            unavailable[name] = str(exc)
    return found, unavailable


def open_camera(
    backend: str = "sim", device_id: str | None = None, policy: Policy | None = None, **options: Any
) -> Camera:
    """Open ``device_id`` (first found when None) on ``backend``; options go to the backend
    (``cti`` for harvesters, ``config``/``faults``/``sensor`` for sim, ``address`` for aravis)."""
    transport = backend_module(backend).open_transport(device_id, **options)
    try:
        return Camera(transport, policy=policy)
    except BaseException:
        transport.close()
        raise
