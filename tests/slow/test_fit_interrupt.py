"""Ctrl-C while emcee samples leaves the fit as one KeyboardInterrupt: emcee prints nothing (its wrapper prints a
traceback for anything a log-probability raises), so `uwlab fit` can say its one line `interrupted`."""

from __future__ import annotations

import pytest

from uwlab.experiments.calibration.fit import Posterior, fit_points
from uwlab.experiments.calibration.simulate import simulate_campaign

TRUTH = {"light_efficiency": 0.8, "attenuation_scale": 1.2, "K_dn_per_e:imx250m": 0.36, "K_dn_per_e:icx285alm": 1.05}


@pytest.mark.parametrize("interrupt_at_call", [800, 6100, 9000])  # the start's MAP search, then emcee (from ≈ 2200)
def test_an_interrupt_inside_the_sampler_is_one_keyboard_interrupt(monkeypatch, capsys, interrupt_at_call):
    points, rigs = simulate_campaign(TRUTH, seed=3)
    calls = [0]
    log_u = Posterior.log_u

    def interrupted(self, u):
        calls[0] += 1
        if calls[0] == interrupt_at_call:
            raise KeyboardInterrupt
        return log_u(self, u)

    monkeypatch.setattr(Posterior, "log_u", interrupted)
    with pytest.raises(KeyboardInterrupt):
        fit_points(points, rigs)
    out, err = capsys.readouterr()
    assert "emcee" not in out + err and "Traceback" not in out + err
    assert calls[0] == interrupt_at_call  # nothing evaluated after the interrupt
