"""Calibration workflow: priors, the vectorised forward model, the emcee fit, validation, outputs on disk, the
fit-validate-write pipeline, interval coverage, and fast simulated campaigns."""
