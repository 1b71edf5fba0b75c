"""Centroid SD and bias (px) of the perception's blob centres over frames of a static
target, per sensor setting of the twin (issue 16: which settings give the "2005-era"
0.03 px). Not a test; run it:

    python -m tests.sim_camera.centroid_noise "[{'gain_e_per_dn': 10, 'read_noise_e': 52}]"

Each argument setting (a list of dicts of SimCameraConfig changes) is printed after the
default: 60 frames of three poses, SD and bias per coordinate, RMS over the 18 blobs.
"""

from __future__ import annotations

import ast
import dataclasses
import sys

import numpy as np

from humanpt.geometry import camera_T_desired, transform_from_x
from humanpt.perception.config import PerceptionConfig
from humanpt.perception.pipeline import Perception
from humanpt.sim_camera import Renderer, SimCameraConfig

POSES = (
    camera_T_desired(600.0),
    transform_from_x(np.array([20, -15, 700, 10, -8, 5.0])),
    transform_from_x(np.array([-30, 10, 550, -15, 10, -5.0])),
)


def centroid_sd_px(config: SimCameraConfig, frames: int = 60) -> tuple[float, float]:
    """(SD, bias) in px, per coordinate, RMS over the blobs of :data:`POSES`."""
    perception = Perception(PerceptionConfig())
    renderer = Renderer(config)
    sds, biases = [], []
    for pose in POSES:
        truth = renderer.blobs(renderer.discs(pose))
        truth = truth.centre_px[truth.label < 3]
        got = []
        for f in range(frames):
            uv = perception.measure(renderer.render(pose, frame_index=f)).blobs.uv_px
            d = np.linalg.norm(uv[:, None] - truth[None], axis=-1)
            j = d.argmin(axis=0)
            if np.all(d[j, np.arange(len(truth))] < 1.0):
                got.append(uv[j])
        got = np.array(got)
        sds.append(got.std(axis=0, ddof=1))
        biases.append(got.mean(axis=0) - truth)
    return float(np.sqrt(np.mean(np.square(sds)))), float(np.sqrt(np.mean(np.square(biases))))


def main(argv: list[str]) -> None:
    settings = [{}] + (list(ast.literal_eval(argv[0])) if argv else [])
    for changes in settings:
        sd, bias = centroid_sd_px(dataclasses.replace(SimCameraConfig(), **changes))
        print(f"{changes}: centroid SD {sd:.4f} px, bias RMS {bias:.4f} px", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
