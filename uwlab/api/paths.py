"""The bundled configs (designs, plans, rigs, sensors, fit configs): `config_path`."""

from __future__ import annotations

from pathlib import Path

from uwlab.errors import ConfigError


def config_path(relative: str) -> Path:
    """The path of a bundled config file, relative to the configs directory (``UWLAB_CONFIG_DIR``, default the
    repository's ``configs/``); refused (one line) when it does not exist.

    Examples
    --------
    >>> import uwlab
    >>> uwlab.config_path("design/example.toml").name
    'example.toml'
    """
    from uwlab.model.data import config_dir

    path = config_dir() / relative
    if not path.exists():
        raise ConfigError("config", relative, f"no such file under {config_dir()}")
    return path
