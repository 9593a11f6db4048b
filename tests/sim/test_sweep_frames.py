"""Raw frames of a sweep on the simulated rig (``save_frames = true``): every frame a point was computed from, bright
and dark, stored with its settings, found through `Dataset.frames`."""

import os

import numpy as np

from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.dataset_check import check
from uwlab.experiments.dataset_frames import read_frame

from tests.support.plans import camera, record, write_plan

DEFAULTS = {"black_level_dn": 32, "frames_per_point": 4, "dark_frames": 2, "save_frames": True, "roi": [2, 3, 16, 12]}
SWEEPS = [
    {"id": "per-point", "kind": "exposure", "values": [100, 300], "dark": "point"},
    {"id": "block", "kind": "light-level", "values": [0.5, 1.0], "exposure_us": 200, "dark": "block"},
]


def test_saved_frames_are_the_frames_each_point_was_computed_from(tmp_path, sim_rig):
    plan = load_plan(write_plan(tmp_path / "plan.toml", "frames", SWEEPS, camera=camera(24, 20), defaults=DEFAULTS))
    data = record(plan, tmp_path / "d", sim_rig)
    assert check(data).ok
    for point in data.points().itertuples():
        frames = data.frames(point.sweep_id, point.point_index)
        assert len(frames.bright) == point.frames == 4 and len(frames.dark) == point.dark_frames == 2
        bright = [read_frame(p) for p in frames.bright]
        dark = [read_frame(p) for p in frames.dark]
        x, y, w, h = point.roi_x, point.roi_y, point.roi_w, point.roi_h
        assert [m["frame_id"] for _, m in bright] == list(point.frame_ids)
        assert all(image.shape == (20, 24) and image.dtype == np.uint16 for image, _ in bright + dark)
        stack = np.stack([image[y : y + h, x : x + w] for image, _ in bright]).astype(float)
        assert stack.mean() == point.mean_dn
        dark_stack = np.stack([image[y : y + h, x : x + w] for image, _ in dark]).astype(float)
        assert dark_stack.mean() == point.dark_mean_dn
        for _, meta in bright:
            assert meta["role"] == "bright" and meta["light_on"] and meta["roi"] == [x, y, w, h]
            assert meta["settings"]["exposure_us"] == point.exposure_us_readback
            assert meta["sweep_id"] == point.sweep_id and meta["point_index"] == point.point_index
        assert all(meta["role"] == "dark" and not meta["light_on"] for _, meta in dark)
    block = [data.frames("block", index) for index in (0, 1)]
    # one dark block, linked into both points
    assert all(os.path.samefile(a, b) for a, b in zip(block[0].dark, block[1].dark, strict=True))
    per_point = [data.frames("per-point", index) for index in (0, 1)]
    assert read_frame(per_point[0].dark[0])[1]["frame_id"] != read_frame(per_point[1].dark[0])[1]["frame_id"]
    assert not list((tmp_path / "d" / "frames").glob("*/.*"))  # no staging folder left
