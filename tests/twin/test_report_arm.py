"""The arm's stage in the job's accuracy report (issue 32.4, humanpt.twin.report): its
estimate, 1-sigma and checks against the world's arm; on the stand-in it is not run, said
once and not warned of."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np

from humanpt.geometry.rig import Arm, Calibration, Rig
from humanpt.twin.report import Check, job_report
from humanpt.twin.teach import StageResult

SEAM = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]])
LINE = np.column_stack([np.linspace(0, 100, 201), np.full(201, 0.05), np.zeros(201)])


def _result(stage: StageResult, rig: Rig, arm_share_mm: float):
    return SimpleNamespace(stages=[stage], rig=rig, seam_mm=SEAM, taught_path_mm=LINE, fitted_path_mm=LINE,
                           played_path_mm=LINE, fitted=None,
                           checks=[Check("arm", "the arm's share of the played-back error after its calibration, RMS",
                                         arm_share_mm, 0.5, "mm")])


def test_the_arm_on_the_stand_in_is_said_not_warned():
    stage = StageResult("arm", False, 0.0, skipped="the standin robot has no joints (exact kinematics): no arm to "
                                                   "calibrate")
    rep = job_report(_result(stage, Rig(), 0.1))
    assert "    arm        not run: the standin robot has no joints" in rep.text()
    assert rep.passed and not any("arm" in w for w in rep.warnings)


def test_the_calibrated_arm_shows_its_estimate_sigma_and_checks():
    arm = Arm("puma762", (0.0, -0.02, 0.03, -0.03, 0.02, 0.0), (0.3, -0.2, 0.3, -0.2, 0.0),
              Calibration("arm+ax=yb", "2026-11-27", "", {"joint_offsets_deg": 0.006, "link_length_errors_mm": 0.09}))
    rig = dataclasses.replace(Rig(), arm=arm)
    ok = StageResult("arm", True, 1.0, checks=[Check("arm", "a2_mm off the truth", 1.2, 3.0, "sigma")])
    text = job_report(_result(ok, rig, 0.12)).text()
    assert ("arm        puma762: joint offsets [+0.0000, -0.0200, +0.0300, -0.0300, +0.0200, +0.0000] deg, d2 a2 a3 "
            "d4 d6 errors [+0.300, -0.200, +0.300, -0.200, +0.000] mm; 1-sigma joint_offsets_deg 0.006, "
            "link_length_errors_mm 0.09; acceptance met") in text
    assert text.splitlines()[-1].startswith("PASS")
    bad = StageResult("arm", True, 1.0, checks=[Check("arm", "a2_mm off the truth", 4.0, 3.0, "sigma")])
    rep = job_report(_result(bad, rig, 0.6))
    assert "WARN arm: a2_mm off the truth 4 sigma (beyond 3 sigma)" in rep.warnings
    assert any(w.startswith("WARN arm: the arm's share") for w in rep.warnings) and not rep.passed


def test_the_hand_eye_the_arm_stage_replaced_is_history_not_a_warning():
    """The hand-eye stage on the nominal arm is 1.8 mm off on the realistic world (it takes
    the arm's errors where it calibrates); the arm's stage estimates the hand-eye again with
    the arm and the rig keeps that one: its check counts, the old one is shown, not warned."""
    arm = Arm("puma762", calibration=Calibration("arm+ax=yb"))
    rig = dataclasses.replace(Rig(), arm=arm, hand_eye=dataclasses.replace(
        Rig().hand_eye, calibration=Calibration("arm+ax=yb")))
    he = StageResult("hand-eye", True, 1.0, checks=[Check("hand-eye", "position off the truth", 1.796, 0.2, "mm"),
                                                    Check("time offset", "off the truth", 0.03, 1.0, "ms")])
    ok = StageResult("arm", True, 1.0, checks=[Check("arm", "the hand-eye estimated with it, position off the truth",
                                                     0.15, 0.2, "mm")])
    res = _result(ok, rig, 0.1)
    res.stages = [he, ok]
    rep = job_report(res)
    assert ("hand-eye   superseded by the arm's stage (the rig's hand-eye is the one estimated with the arm, below); "
            "its own on the nominal arm: position off the truth 1.796 mm") in rep.text()
    assert rep.passed, rep.warnings
    res.stages = [he, StageResult("arm", False, 1.0, error="ArmCalibrationError: too few poses")]
    rep = job_report(res)
    assert "WARN hand-eye: position off the truth 1.796 mm (beyond 0.2 mm)" in rep.warnings  # no arm: it counts


def test_with_a_calibrated_arm_the_taught_seams_are_judged_in_its_frame():
    """The fitted seam 0.3 mm beside the seam as designed but on it in the arm's frame (the
    world turned by the arm's unobservable joint-1 offset): met; the torch is judged in the
    world's frame."""
    res = _result(StageResult("arm", True, 1.0), Rig(), 0.1)
    res.fitted_path_mm = LINE + [0.0, 0.3, 0.0]
    res.seam_arm_frame_mm = SEAM + [0.0, 0.3 + 0.05, 0.0]
    res.arm_frame_note = "taught and fitted seams against the seam in the calibrated arm's frame: ..."
    text = job_report(res).text()
    assert "    (taught and fitted seams against the seam in the calibrated arm's frame: ...)" in text
    assert "ok   fitted seam (lines and arcs)       RMS  0.000" in text
    assert "ok   played-back torch (true path)      RMS  0.050" in text
