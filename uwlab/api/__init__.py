"""The Python API (`uwlab`'s public names, re-exported lazily by `uwlab/__init__.py`): thin wrappers over
`uwlab.experiments` returning pandas, xarray and ArviZ objects. One module per family of CLI verbs: `design`,
`campaign` (plans, sweeps, datasets), `emva`, `calibration` (fit, report), `instruments`, `paths`."""
