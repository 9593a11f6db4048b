"""The report figures' rules (uwlab.experiments.figures): nothing beyond an axis without a marker and its value,
linear residual axes, log axes ticked at 1-2-5, the datasheet's n/a entries each with a reason and a remedy."""

from __future__ import annotations

import numpy as np
import pandas as pd

from uwlab.experiments.calibration.output import _residuals
from uwlab.experiments.emva.datasheet import missing_notes
from uwlab.experiments.figures import Figure, log_ticks


def points(residual_percent):
    residual = np.asarray(residual_percent, float)
    x = np.geomspace(20, 2000, residual.size)
    centre = np.full(residual.size, 1000.0)
    return pd.DataFrame(
        {
            "exposure_us": x,
            "predicted_median": centre,
            "observed_p2_5": centre * 0.997,
            "observed_p97_5": centre * 1.003,
            "residual_percent": residual,
        }
    )


def test_a_residual_beyond_the_axis_is_a_marker_at_the_edge_with_its_value():
    ax = Figure().add_subplot()
    _residuals(ax, points([0.1, -0.2, 0.05, 242.0, 0.0]), None)
    lo, hi = ax.get_ylim()
    assert ax.get_yscale() == "linear" and hi == -lo and hi < 1.0  # sized to the band and the residuals
    labels = [t.get_text() for t in ax.texts]
    assert labels == ["+242 %"]
    edge = [line for line in ax.lines if line.get_marker() == "^"]
    assert len(edge) == 1 and edge[0].get_ydata()[0] == hi


def test_a_held_out_band_entirely_beyond_the_axis_is_marked_and_its_offset_written():
    pts = points([0.1, -0.1, 0.05, 0.0])
    held = pts.assign(
        predicted_median=pts["predicted_median"] * 3.4,
        observed_p2_5=pts["predicted_median"] * 2.3,
        observed_p97_5=pts["predicted_median"] * 5.4,
    )
    ax = Figure().add_subplot()
    _residuals(ax, pts, held)
    assert any(t.get_text().startswith("held out: +240 %\nband +130 to +440 %") for t in ax.texts)
    up = [line for line in ax.lines if line.get_marker() == "^"]
    assert len(up) == 1 and len(up[0].get_xdata()) == 4  # one marker per held-out point


def test_log_axes_are_ticked_at_one_two_five():
    ax = Figure().add_subplot()
    ax.set_yscale("log")
    ax.set_ylim(0.5, 200)
    log_ticks(ax.yaxis)
    shown = [v for v in ax.yaxis.get_majorticklocs() if 0.5 <= v <= 200]
    assert np.allclose(shown, [0.5, 1, 2, 5, 10, 20, 50, 100, 200])


def test_every_missing_nonuniformity_says_why_and_what_fixes_it():
    spatial = {
        "dark": {"total": -0.01, "row": 0.002, "col": -0.001, "pixel": 0.004},
        "bright": {"total": -5.0, "row": 0.5, "col": 0.3, "pixel": 3.0},
        "frames": 2,
    }
    values = {
        "model": "linear",
        "spatial_variances": spatial,
        "dsnu_e": None,
        "dsnu_row_e": 0.1,
        "dsnu_col_e": None,
        "dsnu_pixel_e": 0.2,
        "prnu_percent": None,
        "prnu_row_percent": 0.02,
        "prnu_col_percent": 0.01,
        "prnu_pixel_percent": 0.1,
    }
    notes = dict(missing_notes(values))
    assert set(notes) == {"DSNU1288, DSNU1288.col", "PRNU1288"}
    assert "(-0.01, -0.001 DN²) from 2 frames" in notes["DSNU1288, DSNU1288.col"]
    assert "(-5 DN²)" in notes["PRNU1288"] and "at least 16 bright and dark frames" in notes["PRNU1288"]
    assert "larger than 19 px" in dict(missing_notes({**values, "spatial_variances": None}))["PRNU1288"]
