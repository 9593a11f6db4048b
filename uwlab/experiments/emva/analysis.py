"""EMVA 1288 Release 4.0 characterisation of a photon transfer: the linear model (`uwlab.experiments.emva.linear`,
EMVA 1288 Release 4.0 Linear) or the general model (`uwlab.experiments.emva.general`, Release 4.0 General), plus the
spectrograms, profiles and histograms of the nonuniformity stacks' images (§8.6–8.8 of both documents,
`uwlab.experiments.frames.nonuniformity`).

The implementation follows the texts of the standard (EMVA Standard 1288 Release 4.0 Linear and General, release
candidates of March 15, 2021); docs/emva.md lists the method per quantity with the equation numbers. The reference
implementation (github.com/EMVA1288/emva1288) was read for the descriptor format and the XML names; no code was
taken from it, and it differs where it still follows Release 3.1 (e.g. the sensitivity threshold, the linearity
error, the 5×5 highpass).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

from uwlab.errors import ConfigError
from uwlab.experiments.emva.general import characterize_general
from uwlab.experiments.emva.linear import characterize_linear
from uwlab.experiments.frames.nonuniformity import ImageAnalysis, analyse_images
from uwlab.experiments.emva.transfer import NonuniformityStack, PhotonTransfer

MODELS = ("linear", "general")


@dataclass(frozen=True)
class EmvaResult:
    """The EMVA 1288 parameters (`values`, JSON keys), the curves for the plots (`curves`) and the analysis of the
    nonuniformity images when the stacks' mean images were kept (`images`, from ``stack``)."""

    values: dict
    curves: dict
    stack: NonuniformityStack | None = field(default=None, repr=False, compare=False)

    @property
    def model(self) -> str:
        return self.values["model"]

    @cached_property
    def images(self) -> ImageAnalysis | None:
        """The spectrograms, profiles and histograms (§8.6–8.8) of the stacks' mean images, or None without them:
        computed at the first use (the figures, the XML, the datasheet), so that a run that only reports the values
        (``--json``, the summary, a fleet's rows) does not spend a third of a second of CPU on a lab-size camera's
        two images for nothing."""
        stack = self.stack
        if stack is None or stack.bright.mean_image is None or stack.dark.mean_image is None:
            return None
        return analyse_images(stack.bright.mean_image, stack.dark.mean_image, stack.bright.frames, stack.dark.frames)


def characterize(pt: PhotonTransfer, model: str = "linear") -> EmvaResult:
    """All EMVA 1288 Release 4.0 parameters of ``pt`` under ``model`` ("linear" or "general")."""
    if model not in MODELS:
        raise ConfigError("--model", model, f"must be one of {', '.join(MODELS)}")
    if len(pt.dark) == 0:
        raise ConfigError("dark frames", 0, "no dark frames: EMVA 1288 needs dark statistics")
    values, curves = (characterize_linear if model == "linear" else characterize_general)(pt)
    if pt.stack is None:
        values["notes"].append(
            "no nonuniformity stacks: spectrograms, profiles and defect-pixel histograms need L "
            "averaged bright and dark frames (Release 4.0 §8)"
        )
    return EmvaResult(values, curves, pt.stack)
