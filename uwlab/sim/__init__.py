"""The simulated world, a sibling of the real drivers: what the simulated rig sees and how it is rendered.

- `world` (the ``[world]`` presets and effect switches), `tank` (the 46 cm tank renderer), `scene` (the rig's
  scene: design, light state, world), `bench` (the EMVA 1288 bench), `target` (a planar board seen through a port),
  `settings` (the rig's ``[sim]`` section), `rig_state` and `state_log` (the simulated light's shared state and
  its true-state log);
- `devices`: the simulated camera, GigE server and serial instruments.

Only ``--sim`` paths import this package (`uwlab.experiments.acquisition.sim_rig`, the ``simulate`` modules,
the demo, the ``uwlab sim`` commands); import-linter contracts in pyproject.toml keep the real rig free of it.
"""
