"""Perception's mirror drift watch on the twin: a left view tilted 0.08 deg about x (1.4 px
of vertical disparity, under the 2 px at which pairs are lost) gives one mirror_drift
warning while the target stays tracked; the ideal world gives none."""

from __future__ import annotations

from humanpt.schemas import humanpt_pb2 as pb
from humanpt.twin.run import SystemConfig, run
from humanpt.twin.worlds import World


def _events(world):
    cfg = SystemConfig.for_scenario("arc", 0, world=world)
    res = run(cfg, robot="standin", duration_s=5.0)
    return [pb.Event.FromString(o.data) for o in res.world.outputs() if o.topic.endswith("perception/events")]


def test_a_tilted_mirror_warns_before_the_target_is_lost():
    tilted = World("tilt x 0.08", (), {"sim_camera": {"psvs": {"rotvec_left_deg": [0.08, 0.0, 0.0]}}})
    events = _events(tilted)
    drift = [e for e in events if e.code == "mirror_drift"]
    assert len(drift) == 1 and drift[0].severity == pb.SEVERITY_WARNING
    assert "+1.4" in drift[0].text  # a_v tan(0.08 deg) = 1.40 px
    status = [e.text for e in events if e.code == "tob_status"]
    assert len(status) == 1 and "-> full" in status[0]  # tracked from the first image on, never lost


def test_aligned_mirrors_do_not_warn():
    assert not [e for e in _events(World.ideal()) if e.code.startswith("mirror_drift")]
