"""The report's spectra figure (`plot_spectra`): per configuration two panels (at the target, at the camera), three
configurations across, the predicted spectrum drawn over the measured one, empty cells hidden."""

from __future__ import annotations

import numpy as np
import pandas as pd

from uwlab.experiments.report import plot_spectra

NM = np.linspace(400.0, 700.0, 7)


def spectra(sweeps: list[str], unmeasured: str) -> pd.DataFrame:
    rows = []
    for i, sweep_id in enumerate(sweeps):
        for j, position in enumerate(("target", "camera")):
            predicted = (i + 1) * (j + 1) * np.exp(-(((NM - 550) / 80) ** 2))
            measured = np.full(NM.size, np.nan) if sweep_id == unmeasured else predicted * 1.05
            rows += [
                {
                    "sweep_id": sweep_id,
                    "position": position,
                    "wavelength_nm": w,
                    "irradiance_w_m2_nm": m,
                    "predicted_w_m2_nm": p,
                }
                for w, m, p in zip(NM, measured, predicted, strict=True)
            ]
    return pd.DataFrame(rows)


def test_four_configurations_fill_two_blocks_of_three_with_the_predictions_on_top():
    sweeps = ["a", "b", "c", "d"]
    frame = spectra(sweeps, unmeasured="c")
    fig = plot_spectra(frame, lambda sweep_id: f"config {sweep_id}")
    axes = np.array(fig.axes).reshape(4, 3)  # 2 blocks × (target, camera) rows, 3 columns
    for j, sweep_id in enumerate(sweeps):
        block, column = divmod(j, 3)
        for i, position in enumerate(("target", "camera")):
            ax = axes[2 * block + i, column]
            sel = frame[(frame["sweep_id"] == sweep_id) & (frame["position"] == position)]
            assert ax.get_title() == f"config {sweep_id}, at the {position}"
            predicted = [line for line in ax.lines if line.get_label() == "predicted"]
            measured = [line for line in ax.lines if line.get_label() == "measured"]
            assert np.array_equal(predicted[0].get_ydata(), sel["predicted_w_m2_nm"])
            assert len(measured) == (0 if sweep_id == "c" else 1)  # no spectrometer reading: no dots
            assert all(predicted[0].get_zorder() > m.get_zorder() for m in measured)
    assert [ax.get_visible() for ax in axes[2:, 1:].ravel()] == [False] * 4
    assert axes[-1, 0].get_xlabel() == "wavelength [nm]"
