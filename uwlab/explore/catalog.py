"""The components the explorer offers: sensors, lights, lenses, water types, spectra and target materials from
``configs/`` and the model's named data, plus user profiles (a `uwlab emva` sensor profile, a light or lens TOML).

A preset is a label and the design values it sets (``{"sensor.profile": "imx250m"}``, a light's flux, beam and
spectrum); the page shows them as a choice per section. A user profile is named by its absolute path, as
``sensor.profile`` and the spectrum and transmittance keys accept any file.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from uwlab.errors import ConfigError, UwlabError
from uwlab.model.components import load_lens_profile, load_light_profile, shipped
from uwlab.model.sensor import SensorProfile, available_profiles, load_sensor_profile
from uwlab.model.spectra import NAMED_SPECTRA
from uwlab.model.target import NAMED_REFLECTANCE
from uwlab.model.water import WATER_TYPES


@dataclass(frozen=True)
class Preset:
    label: str
    values: dict
    user: bool = False


def _sensor_preset(profile: SensorProfile, value: str, user: bool) -> Preset:
    width, height = profile.resolution_px
    label = (
        f"{profile.name} · {width}×{height} · {profile.pixel_size_um:g} µm · {profile.bit_depth} bit"
        + (" · colour" if profile.color else "")
        + (f" · {profile.source}" if user else "")
    )
    return Preset(label, {"sensor.profile": value}, user)


def _light_preset(path: Path, user: bool) -> Preset:
    light = load_light_profile(path)
    label = f"{light.name} · {light.luminous_flux_lm:g} lm · {light.beam_half_angle_deg:g}°"
    return Preset(label + (f" · {path}" if user else ""), light.design_values(path.parent), user)


def _lens_preset(path: Path, user: bool) -> Preset:
    lens = load_lens_profile(path)
    label = f"{lens.name} · {lens.focal_length_mm:g} mm"
    return Preset(label + (f" · {path}" if user else ""), lens.design_values(path.parent), user)


_LOADERS = {
    "sensor": lambda path: _sensor_preset(load_sensor_profile(str(path)), str(path), True),
    "light": lambda path: _light_preset(path, True),
    "lens": lambda path: _lens_preset(path, True),
}


@dataclass
class Catalog:
    """Presets by section, with the user profiles added (`add_profile`)."""

    user: dict[str, list[Preset]] = field(default_factory=lambda: {kind: [] for kind in _LOADERS})

    def add_profile(self, path: str | Path) -> tuple[str, Preset]:
        """Add a sensor, light or lens profile TOML (the first schema it validates against); returns (section,
        preset). `ConfigError` on ``profile`` when the file is none of them."""
        path = Path(path).expanduser().resolve()
        if path.suffix.lower() != ".toml" or not path.is_file():
            raise ConfigError("profile", str(path), "must be an existing .toml file (a sensor, light or lens profile)")
        reasons = []
        for kind, loader in _LOADERS.items():
            try:
                preset = loader(path)
            except UwlabError as exc:
                reasons.append(f"{kind}: {exc}")
                continue
            if preset not in self.user[kind]:
                self.user[kind].append(preset)
            return kind, preset
        raise ConfigError("profile", str(path), "not a sensor, light or lens profile (" + "; ".join(reasons) + ")")

    def add_profiles(self, path: str | Path) -> list[tuple[str, Preset]]:
        """A profile file, or every profile TOML in a directory (at least one); other TOML files there are skipped."""
        path = Path(path).expanduser()
        if not path.is_dir():
            return [self.add_profile(path)]
        added = []
        for candidate in sorted(path.glob("*.toml")):
            try:
                added.append(self.add_profile(candidate))
            except ConfigError:
                continue
        if not added:
            raise ConfigError("--profile", str(path), "no sensor, light or lens profile in this directory")
        return added

    def presets(self) -> dict[str, list[Preset]]:
        """{section: [presets]}: shipped components first, then the user's."""
        sensors = [_sensor_preset(load_sensor_profile(name), name, False) for name in available_profiles()]
        return {
            "sensor": sensors + self.user["sensor"],
            "light": [_light_preset(p, False) for p in shipped("lights")] + self.user["light"],
            "lens": [_lens_preset(p, False) for p in shipped("lenses")] + self.user["lens"],
            "water": [Preset(name, {"water.type": name}) for name in WATER_TYPES],
            "target": [
                Preset(f"{name} · {value:g}", {"target.reflectance": name}) for name, value in NAMED_REFLECTANCE.items()
            ],
        }

    def user_sensors(self) -> tuple[SensorProfile, ...]:
        return tuple(load_sensor_profile(p.values["sensor.profile"]) for p in self.user["sensor"])


# Suggested values of free-text keys (names the model knows); any file path is accepted too.
SUGGESTIONS = {
    "light.spectrum": NAMED_SPECTRA,
    "water.type": WATER_TYPES,
    "target.reflectance": tuple(NAMED_REFLECTANCE),
}
