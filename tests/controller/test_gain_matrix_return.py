"""Issue 33.6: the paper's K as a 6x6 weight matrix (both laws, flange frame; refused when the
delayed loop would be unstable at the link's cycle) and a prespecified return pose (config,
console option; checked against the envelope)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.console.client import ConsoleError, parse_options
from humanpt.controller import law
from humanpt.controller.config import ControllerConfig, gain_matrix_refusal
from humanpt.controller.core import ControllerCore
from humanpt.runtime.config import ConfigError, from_dict
from humanpt.schemas import humanpt_pb2 as pb
from tests.controller.test_controller import TARGET_X, Rig, T_m, start_flange, static

DT_S = 0.028
BIG = 1e3  # per-cycle limits that never bind


def _flange_rz90():
    """A flange turned 90 deg about the world z: flange x = world y, flange y = world -x."""
    F = np.eye(4)
    F[:3, :3] = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    F[:3, 3] = (0.5, 0.2, 0.9)
    return F


def _target_1mm_along_world_x(F, flange_T_desired):
    """G where D would be, moved 1 mm along the world x (same orientation as D)."""
    T = F @ flange_T_desired
    T[:3, 3] += (1e-3, 0, 0)
    return T


def test_a_gain_matrix_acts_in_the_flange_frame_in_both_laws():
    # Hand calculation: a 1 mm error along world x is -1 mm along the flange's y; K =
    # diag(1, 5, 1, 1, 1, 1) commands -5 mm/s along the flange's y = +5 mm/s along world x;
    # the scalar gain 1 would command 1 mm/s.
    F = _flange_rz90()
    fTd = np.eye(4)
    fTd[:3, 3] = (0, 0, 0.6)
    G = _target_1mm_along_world_x(F, fTd)
    K = np.diag([1.0, 5.0, 1.0, 1.0, 1.0, 1.0])
    common = dict(k_t=1.0, k_r=1.0, dt_s=DT_S, max_step_m=BIG, max_step_rad=BIG)
    for step in (law.thetau_step(F, G, fTd, v_tob_m_s=np.zeros(3), w_tob_rad_s=np.zeros(3), feed_forward=False,
                                 K=K, **common),
                 law.paper_step(F, G, fTd, K=K, **common)):
        np.testing.assert_allclose(step.d_translation_m, [5e-3 * DT_S, 0, 0], atol=1e-15)
        np.testing.assert_allclose(step.d_rotation_rad, 0, atol=1e-15)
    scalar = law.paper_step(F, G, fTd, **common)
    np.testing.assert_allclose(scalar.d_translation_m, [1e-3 * DT_S, 0, 0], atol=1e-15)


def test_a_coupling_term_moves_the_flange_for_a_rotation_error():
    # K[0, 5] = 0.01 m/(rad s): a 0.1 rad error about the flange z (G turned about D's z)
    # gives 1 mm/s along the flange x, the paper's law as the theta-u law.
    F = np.eye(4)
    fTd = np.eye(4)
    fTd[:3, 3] = (0, 0, 0.6)
    G = F @ fTd
    G[:3, :3] = Rotation.from_rotvec([0, 0, 0.1]).as_matrix()
    K = np.zeros((6, 6))
    K[0, 5] = 0.01
    common = dict(k_t=1.0, k_r=1.0, dt_s=DT_S, max_step_m=BIG, max_step_rad=BIG)
    paper = law.paper_step(F, G, fTd, K=K, **common)
    np.testing.assert_allclose(paper.d_translation_m, [0.01 * 0.1 * DT_S, 0, 0], rtol=1e-9)
    thetau = law.thetau_step(F, G, fTd, v_tob_m_s=np.zeros(3), w_tob_rad_s=np.zeros(3), feed_forward=False,
                             K=K, **common)
    # theta-u: the flange pose that puts D on G is turned 0.1 rad about z about G's point (on z)
    np.testing.assert_allclose(thetau.d_translation_m, [0.01 * 0.1 * DT_S, 0, 0], rtol=1e-9)


def test_the_default_diagonal_is_the_two_gains():
    """The scalar gains as a matrix converge the same way on the scripted robot."""
    flange = start_flange(TARGET_X, (20, -10, 15), (3, -2, 4))
    finals = []
    for cfg in (ControllerConfig(), ControllerConfig(gain_matrix_1_s=tuple(tuple(r) for r in np.diag([4.0] * 6)))):
        rig = Rig(ControllerCore(cfg), flange.copy(), static(T_m(TARGET_X)))
        rig.step(40)
        finals.append(rig.flange)
    np.testing.assert_allclose(finals[0], finals[1], atol=1e-12)


def test_an_unstable_gain_matrix_is_refused_like_the_scalar_gains():
    # The scalar rule: k dt < 0.5 (20 x 0.028 = 0.56 refused, 17 x 0.028 = 0.476 kept).
    assert gain_matrix_refusal(np.diag([4, 4, 4, 4, 4, 17.0]), DT_S) is None
    why = gain_matrix_refusal(np.diag([4, 4, 4, 4, 4, 20.0]), DT_S)
    assert why is not None and "|l dt| = 0.56" in why
    # A negative eigenvalue diverges (the root of z^2 - z - 0.028 is 1.027).
    assert "unstable" in gain_matrix_refusal(np.diag([4, 4, 4, -1.0, 4, 4]), DT_S)
    # A lightly damped rotation-like block: eigenvalues 0.1 +- 14j, |l dt| = 0.39 < 0.5 but
    # z^2 - z + (0.0028 + 0.392j) has a root of modulus 1.13 (numpy.roots, by hand below).
    K = np.diag([4.0] * 6)
    K[0:2, 0:2] = [[0.1, -14.0], [14.0, 0.1]]
    a = (0.1 + 14j) * DT_S
    assert max(abs((1 + s * np.sqrt(1 - 4 * a)) / 2) for s in (1, -1)) > 1
    assert "unstable" in gain_matrix_refusal(K, DT_S)
    # From a config file: refused at the cell's cycle as the scalar gains are (ALTER 28 ms).
    from humanpt.runtime.registry import config_types

    with pytest.raises(ConfigError, match=r"gain_matrix_1_s has an eigenvalue 20 1/s.*28 ms cycle"):
        from_dict({"controller": {"gain_matrix_1_s": np.diag([4, 4, 4, 4, 4, 20.0]).tolist()}}, "c.toml",
                  config_types())
    # At run time: rejected, the config unchanged.
    core = ControllerCore(ControllerConfig())
    (_, ev), = core.step(0, "param", pb.ParamSet(key="gain_matrix_1_s",
                                                  value_json=json.dumps(np.diag([30.0] * 6).tolist())))
    assert ev.code == "param_rejected" and "gain_matrix_1_s" in ev.text and core.config.gain_matrix_1_s is None
    (_, ev), = core.step(0, "param", pb.ParamSet(key="gain_matrix_1_s",
                                                  value_json=json.dumps(np.diag([2.0] * 6).tolist())))
    assert ev.code == "param_changed" and core.K is not None and core.K[0, 0] == 2.0


def test_return_goes_to_the_prespecified_pose():
    start = start_flange(TARGET_X, (20, 0, 0))
    home = start.copy()
    home[:3, 3] += (0.05, -0.03, 0.04)  # 50, -30, 40 mm away
    home[:3, :3] = Rotation.from_euler("z", 10, degrees=True).as_matrix() @ home[:3, :3]
    from humanpt.geometry.transforms import x_from_transform

    home_mm = home.copy()
    home_mm[:3, 3] *= 1e3
    x = tuple(float(v) for v in x_from_transform(home_mm))
    core = ControllerCore(ControllerConfig(return_flange_x=x))
    rig = Rig(core, start, static(T_m(TARGET_X)))
    rig.command("return")
    assert "return pose" in [m for t, m in rig.outs if t == "controller/events"][-1].text
    rig.step(300)
    np.testing.assert_allclose(rig.flange, home, atol=1e-6)
    # The lost action "return" goes there too.
    core = ControllerCore(ControllerConfig(return_flange_x=x, lost_action="return"))
    rig = Rig(core, start, static(T_m(TARGET_X)), status_fn=lambda k: pb.TOB_STATUS_LOST)
    rig.step(300)
    np.testing.assert_allclose(rig.flange, home, atol=1e-6)


def test_a_return_pose_outside_the_envelope_is_refused():
    with pytest.raises(ValueError, match="return_flange_x puts the flange at x 1700 mm, above the workspace "
                                         "envelope's max 1600 mm"):
        ControllerConfig(return_flange_x=(1700.0, 0, 500, 0, 0, 0))
    core = ControllerCore(ControllerConfig(return_flange_x=(1000.0, 0, 500, 0, 0, 0)))
    (_, ev), = core.step(0, "param", pb.ParamSet(key="envelope_max_mm", value_json="[900, 1600, 1600]"))
    assert ev.code == "param_rejected" and "return_flange_x" in ev.text, ev.text


def test_the_console_sets_the_return_pose():
    assert parse_options(["return-pose=1000,0,500,0,90,0"]) == {
        "controller": {"return_flange_x": [1000.0, 0.0, 500.0, 0.0, 90.0, 0.0]}}
    assert parse_options(["return-pose=start"]) == {"controller": {"return_flange_x": None}}
    with pytest.raises(ConsoleError, match="six numbers"):
        parse_options(["return-pose=1,2,3"])
