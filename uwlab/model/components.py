"""Light and lens profiles (``configs/lights/*.toml``, ``configs/lenses/*.toml``): their schemas, and the design
config values each one stands for.

A profile describes a product; a design config uses it by copying its values: a light gives
``light.luminous_flux_lm``, ``light.beam_half_angle_deg`` and ``light.spectrum`` (its named spectrum, or its
spectrum CSV as an absolute path), a lens ``lens.focal_length_mm`` and ``lens.transmittance`` (a number, or its
CSV as an absolute path). Files named in a profile are relative to the profile. Sensor profiles are
`uwlab.model.sensor.SensorProfile`, used by name or path in ``sensor.profile``.

>>> load_light_profile(config_dir() / "lights" / "paper-tank-led.toml").design_values(config_dir() / "lights")
{'light.luminous_flux_lm': 25000.0, 'light.beam_half_angle_deg': 40.0, 'light.beam_half_angle_in_air_deg': None, \
'light.spectrum': 'generic-led'}
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from pydantic import Field, model_validator

from uwlab.model.config import NAME_OR_FILE
from uwlab.model.data import config_dir, read_toml
from uwlab.model.schema import (
    FocalLengthMm,
    HalfAngleDeg,
    LuminousFluxLm,
    NonEmptyText,
    Schema,
    Transmittance,
    at_most_one,
    invalid,
    number_or,
    parse,
)


class LightProfile(Schema):
    """A light: rated flux, beam half-angle (in water, as the design's ``light.beam_half_angle_deg``) and spectrum
    (a named spectrum of `uwlab.model.spectra`, or a CSV beside the profile)."""

    name: NonEmptyText = Field(description="product name")
    luminous_flux_lm: LuminousFluxLm = Field(description="rated luminous flux [lm]")
    beam_half_angle_deg: HalfAngleDeg = Field(description="beam half-angle [deg]")
    spectrum: NonEmptyText | None = Field(None, description="named relative spectrum")
    spectrum_csv: NonEmptyText | None = Field(None, description="relative spectrum CSV beside the profile")
    provenance: dict[str, str] = Field({}, description="where each value comes from")

    @model_validator(mode="after")
    def _one_spectrum(self):
        if (self.spectrum is None) == (self.spectrum_csv is None):
            raise invalid("spectrum", self.spectrum, "give exactly one of spectrum and spectrum_csv")
        return self

    def design_values(self, folder: Path) -> dict[str, object]:
        """The design config values of this light (``section.key`` → value; None: the key is unset)."""
        spectrum = self.spectrum if self.spectrum_csv is None else str((folder / self.spectrum_csv).resolve())
        return {
            "light.luminous_flux_lm": self.luminous_flux_lm,
            "light.beam_half_angle_deg": self.beam_half_angle_deg,
            "light.beam_half_angle_in_air_deg": None,
            "light.spectrum": spectrum,
        }


class LensProfile(Schema):
    """A lens: focal length and transmittance (a fraction, or a CSV beside the profile)."""

    name: NonEmptyText = Field(description="product name")
    focal_length_mm: FocalLengthMm = Field(description="focal length [mm]")
    transmittance: Annotated[Transmittance | NonEmptyText, number_or(NAME_OR_FILE)] | None = Field(
        None, description="broadband transmittance (or give transmittance_csv)"
    )
    transmittance_csv: NonEmptyText | None = Field(None, description="spectral transmittance CSV beside the profile")
    provenance: dict[str, str] = Field({}, description="where each value comes from")

    @model_validator(mode="after")
    def _one_transmittance(self):
        return at_most_one(self, "transmittance", "transmittance_csv")

    def design_values(self, folder: Path) -> dict[str, object]:
        """The design config values of this lens (``section.key`` → value)."""
        transmittance: float | str
        if self.transmittance_csv is not None:
            transmittance = str((folder / self.transmittance_csv).resolve())
        else:
            transmittance = 1.0 if self.transmittance is None else self.transmittance
        return {"lens.focal_length_mm": self.focal_length_mm, "lens.transmittance": transmittance}


def load_light_profile(path: Path) -> LightProfile:
    return parse(LightProfile, read_toml(path, "light profile"), f"light profile {path.name}:")


def load_lens_profile(path: Path) -> LensProfile:
    return parse(LensProfile, read_toml(path, "lens profile"), f"lens profile {path.name}:")


def shipped(kind: str) -> list[Path]:
    """The profile files of ``configs/<kind>`` (``lights`` or ``lenses``), sorted."""
    return sorted((config_dir() / kind).glob("*.toml"))
