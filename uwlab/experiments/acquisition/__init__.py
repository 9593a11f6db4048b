"""Acquisition workflow: sweep plans, the sweep engine, the rigs it runs on (tank hardware and the simulated
rig side by side), regions of interest, light calibration and measured spectra."""
