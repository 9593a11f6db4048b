"""The rig config's ``[sim]`` section: what only the simulated rig needs (the tank and the EMVA bench alike)."""

from __future__ import annotations

from pydantic import Field

from uwlab.model.schema import DistanceM, Fraction, Schema, Seed, quantity

# The light's dimming curve exponent: flux fraction = level^γ; 1 is linear, 2.2 a typical dimmer.
Gamma = quantity(0.0, 10.0, "", hint="", lo_open=True)
# True flux over rated flux: a manufacturer's rating is rarely off by more than a factor of a few.
Efficiency = quantity(0.0, 10.0, "", hint="a factor on the rated flux", lo_open=True)


class SimSettings(Schema):
    """The rig config's [sim] section: what only the simulated rig needs."""

    seed: Seed = Field(1288, description="seed of the fixed-pattern noise maps")
    light_gamma: Gamma = Field(2.2, description="light output flux fraction = level ** light_gamma")
    board_size_m: tuple[DistanceM, DistanceM] = Field(
        (0.15, 0.12), description="the target board's size [x, y] on the target plane, centred on the axis [m]"
    )
    surround_reflectance: Fraction = Field(0.05, description="reflectance around the board")
    light_efficiency: Efficiency = Field(
        1.0, description="true emitted flux / rated luminous flux (the ground truth a fit should recover)"
    )
