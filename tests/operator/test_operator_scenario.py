"""Scenarios: the file format round-trips, broken files name their line, the built-ins follow
the paper's geometry, trajectories keep their speeds."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from humanpt.geometry import transform_from_x, x_from_transform
from humanpt.operator import (
    TABLE1_X_MM_DEG,
    Arc,
    Cover,
    Dwell,
    Line,
    OperatorConfig,
    Scenario,
    ScenarioError,
    Trajectory,
    Tremor,
    builtin_scenario,
    format_scenario,
    parse_scenario,
)
from humanpt.operator.scenario import ARC_CENTRE_MM, ARC_RADIUS_MM

num = st.floats(-5000, 5000, allow_nan=False, allow_infinity=False)
pos = st.floats(0.001, 1000, allow_nan=False, allow_infinity=False)
vec3 = st.tuples(num, num, num)
speeds = st.tuples(pos, pos)


@st.composite
def segments(draw):
    kind = draw(st.sampled_from(["line", "line6", "arc", "dwell"]))
    v, w = draw(speeds)
    if kind == "dwell":
        return Dwell(draw(st.floats(0, 100)))
    if kind.startswith("line"):
        return Line(draw(vec3), draw(vec3) if kind == "line6" else None, v, w)
    axis = draw(st.sampled_from([(0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (0.3, -0.2, 0.9)]))
    return Arc(draw(vec3), draw(num), axis, draw(st.sampled_from(["follow", "fixed"])), v, w)


@st.composite
def scenarios(draw):
    driver = draw(st.none() | vec3)
    path = draw(st.sampled_from(["tob", "tip"])) if driver is not None else "tob"
    tremor = draw(st.none() | st.builds(Tremor, pos, pos, st.integers(0, 2**31)))
    covers = []
    for _ in range(draw(st.integers(0, 3))):
        start = draw(st.floats(0, 100))
        end = draw(st.just(math.inf) | st.floats(start + 0.001, 200))
        covers.append(Cover(draw(st.integers(0, 2)), draw(st.floats(0, 1)), start, end,
                            draw(st.floats(-360, 360))))
    return Scenario(
        tuple(draw(st.lists(num, min_size=6, max_size=6))),
        tuple(draw(st.lists(segments(), max_size=8))),
        draw(st.from_regex(r"[A-Za-z0-9_.\-]{1,12}", fullmatch=True)),
        driver,
        path,
        tremor,
        tuple(covers),
    )


@settings(max_examples=150, deadline=None)
@given(scenarios())
def test_a_scenario_file_round_trips(scenario):
    text = format_scenario(scenario)
    back = parse_scenario(text)
    assert back == scenario
    assert format_scenario(back) == text


@pytest.mark.parametrize(
    "text, line, fragment",
    [
        ("start 0 0 0 0 0 0\nline 1 2\n", 2, "line: expected 3 or 6 numbers, got 2"),
        ("start 0 0 0 0 0 0\n\n# fine\nspeed -3\n", 4, "speed: must be > 0"),
        ("line 1 2 3\nstart 0 0 0 0 0 0\n", 1, "'line' before 'start'"),
        ("start 0 0 0 0 0 0\nmove 1 2 3\n", 2, "unknown keyword 'move'"),
        ("start 0 0 0 0 0 x\n", 1, "'x' is not a number"),
        ("start 0 0 0 0 0 0\nline 1 2 nan\n", 2, "not a finite number"),
        ("start 0 0 0 0 0 0\narc 1 2 3\n", 2, "arc: expected"),
        ("start 0 0 0 0 0 0\narc 1 2 3 90 axis 0 0 0\n", 2, "axis must not be zero"),
        ("start 0 0 0 0 0 0\ndwell -1\n", 2, "dwell: duration must be >= 0"),
        ("scenario a\nscenario b\nstart 0 0 0 0 0 0\n", 2, "given twice (first on line 1)"),
        ("start 0 0 0 0 0 0\ndriver 0 0 60\n", 2, "'driver' must come before 'start'"),
        ("path tip\nstart 0 0 0 0 0 0\n", 1, "'path tip' needs a driver"),
        ("tremor 0.1 0.2 x\nstart 0 0 0 0 0 0\n", 1, "seed 'x' is not an integer"),
        ("scenario two words\nstart 0 0 0 0 0 0\n", 1, "scenario: expected one name"),
        ("start 0 0 0 0 0 0\ncover D 0.3 from 1\n", 2, "source is A, B or C, got 'D'"),
        ("start 0 0 0 0 0 0\ncover A 1.3 from 1\n", 2, "fraction must be within 0 and 1"),
        ("start 0 0 0 0 0 0\ncover A 0.3 from 2 to 1\n", 2, "needs 0 <= from < to"),
        ("start 0 0 0 0 0 0\ncover A 0.3 at 2\n", 2, "cover: expected <A|B|C>"),
        ("start 0 0 0 0 0 0\ncover A 0.3 from 1 angle\n", 2, "cover: expected <A|B|C>"),
    ],
)
def test_a_broken_scenario_is_rejected_with_its_line(text, line, fragment):
    with pytest.raises(ScenarioError) as e:
        parse_scenario(text, "seam.scn")
    assert e.value.line == line
    assert str(e.value).startswith(f"seam.scn:{line}: ")
    assert fragment in str(e.value)


def test_a_file_without_start_is_rejected():
    with pytest.raises(ScenarioError, match=r"seam.scn: no 'start' line"):
        parse_scenario("# nothing\nspeed 3\n", "seam.scn")


def test_scenario_file_through_the_config_names_file_and_line(tmp_path):
    good = tmp_path / "good.scn"
    good.write_text("scenario mine\nstart 0 0 0 0 0 180\nspeed 50\nline 100 0 0\ndwell 0.5\n")
    cfg = OperatorConfig(scenario_file=str(good))
    assert "line 100 0 0" in cfg.scenario_text  # the text travels with the config
    assert cfg.build_scenario().name == "mine"
    assert Trajectory(cfg.build_scenario()).duration_s == pytest.approx(2.5)
    bad = tmp_path / "bad.scn"
    bad.write_text("start 0 0 0 0 0 0\nline 1 2 3\nline 1 2\n")
    with pytest.raises(ValueError, match=rf"{bad}:3: line: expected 3 or 6 numbers"):
        OperatorConfig(scenario_file=str(bad))
    with pytest.raises(ValueError, match="cannot read it"):
        OperatorConfig(scenario_file=str(tmp_path / "missing.scn"))


def test_static_is_the_papers_table1_pose():
    traj = Trajectory(builtin_scenario("static"))
    for t in (0.0, 1.0, 100.0):
        world_T_tob, tip = traj.pose(t)
        np.testing.assert_allclose(x_from_transform(world_T_tob), TABLE1_X_MM_DEG, atol=1e-9)
        assert tip is None


def test_arc_follows_the_papers_rotating_base():
    traj = Trajectory(builtin_scenario("arc", speed_mm_s=30.0))
    ts = np.linspace(0, traj.duration_s, 200)
    poses = np.array([traj.pose(t)[0] for t in ts])
    rel = poses[:, :3, 3] - np.array(ARC_CENTRE_MM)
    np.testing.assert_allclose(np.hypot(rel[:, 0], rel[:, 1]), ARC_RADIUS_MM, atol=1e-9)
    np.testing.assert_allclose(rel[:, 2], 0.0, atol=1e-9)
    index_deg = np.degrees(np.arctan2(rel[:, 0], -rel[:, 1]))  # from -y, about +z
    assert index_deg[0] == pytest.approx(50.0) and index_deg[-1] == pytest.approx(-50.0)
    yaw = np.array([x_from_transform(p)[3] for p in poses])
    np.testing.assert_allclose(yaw, index_deg, atol=1e-6)  # the TOB turns with the base
    speed = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1) / np.diff(ts)
    moving = speed > 1.0
    assert np.median(speed[moving]) == pytest.approx(30.0, rel=0.01)
    # The TOB faces up (w down), so a camera above sees its lit face.
    np.testing.assert_allclose(poses[:, :3, 2], np.tile([0, 0, -1.0], (200, 1)), atol=1e-9)


def test_trapezium_is_traced_by_the_needle_tip_at_a_constant_torch_angle():
    scenario = builtin_scenario("trapezium")
    traj = Trajectory(scenario)
    corners = [traj.pose(p.t0_s)[1][:3, 3] for p in traj.pieces[:4]] + [
        traj.pose(traj.duration_s)[1][:3, 3]
    ]
    sides = [np.linalg.norm(b - a) for a, b in zip(corners, corners[1:], strict=False)]
    assert sides == pytest.approx([451.0, math.hypot(45, 45), 361.0, math.hypot(45, 45)])
    assert np.allclose([c[2] for c in corners], 0.0)
    for t in np.linspace(0, traj.duration_s, 50):
        world_T_tob, world_T_tip = traj.pose(t)
        np.testing.assert_allclose(world_T_tip, world_T_tob @ scenario.tob_T_tip, atol=1e-9)
        tilt = math.degrees(math.acos(-world_T_tob[2, 2]))  # w from straight down
        assert tilt == pytest.approx(15.0, abs=1e-9)
        assert world_T_tip[2, 3] == pytest.approx(0.0, abs=1e-9)
    assert traj.duration_s == pytest.approx(sum(sides) / 20.0 + 1.0)


def test_freehand_is_seeded_smooth_and_trembles():
    a, b = builtin_scenario("freehand", seed=1), builtin_scenario("freehand", seed=1)
    assert a == b and a != builtin_scenario("freehand", seed=2)
    traj = Trajectory(a)
    ts = np.arange(0.0, traj.duration_s, 0.002)
    clean = np.array([traj.path_pose(t)[:3, 3] for t in ts])
    shaky = np.array([traj.pose(t)[1][:3, 3] for t in ts])
    tremor = shaky - clean
    assert np.sqrt(np.mean(tremor**2, axis=0)) == pytest.approx([0.2, 0.2, 0.2], rel=0.35)
    # Physiological tremor is fast: the 8-12 Hz part shows in the tip velocity.
    assert np.max(np.linalg.norm(np.diff(tremor, axis=0), axis=1) / 0.002) > 5.0
    assert np.ptp(clean[:, 1]) > 20.0  # a wavy seam, not a straight line


def test_line_speed_and_angular_speed_limits():
    s = parse_scenario(
        "start 0 0 0 0 0 0\nspeed 10\nangular_speed 5\nline 100 0 0\nline 100 0 0 90 0 0\n"
        "line 100 100 0\n"
    )
    traj = Trajectory(s)
    assert [p.duration_s for p in traj.pieces] == pytest.approx([10.0, 18.0, 10.0])
    np.testing.assert_allclose(
        x_from_transform(traj.pose(19.0)[0]), [100, 0, 0, 45, 0, 0], atol=1e-9
    )
    np.testing.assert_allclose(
        traj.pose(1e9)[0], transform_from_x(np.array([100, 100, 0, 90, 0, 0.0])), atol=1e-9
    )


def test_scenario_model_rejects_nonsense():
    with pytest.raises(ScenarioError, match="needs a driver"):
        Scenario((0, 0, 0, 0, 0, 0), path="tip")
    with pytest.raises(ScenarioError, match="speed must be > 0"):
        Scenario((0, 0, 0, 0, 0, 0), (Line((1, 2, 3), None, 0.0),))
    with pytest.raises(ScenarioError, match="no built-in scenario"):
        builtin_scenario("zigzag")


def test_the_readme_example_parses():
    from tests.conftest import ROOT

    readme = (ROOT / "components" / "operator" / "README.md").read_text()
    example = readme.split("## Scenario file format", 1)[1].split("```", 2)[1]
    s = parse_scenario(example, "README")
    assert (s.name, s.path, s.driver_mm, s.tremor) == (
        "my_seam",
        "tip",
        (0.0, 0.0, 60.0),
        Tremor(0.2, 0.3, 7),
    )
    assert [type(g).__name__ for g in s.segments] == ["Line", "Line", "Arc", "Arc", "Dwell"]
    assert s.segments[3].orientation == "fixed" and s.segments[3].axis == (1.0, 0.0, 0.0)
    assert s.covers == (Cover(1, 1.0, 2.0, 4.0), Cover(0, 0.3, 1.0, math.inf, 90.0))
    assert Trajectory(s).duration_s > 0


def test_a_cover_hides_its_source_for_its_time_only():
    s = parse_scenario("start 0 0 0 0 0 0\nline 100 0 0\ncover B 1 from 2 to 4\ncover A 0.3 from 3 angle 90\n"
                       "cover A 0.5 from 3.5 to 3.7\n")
    traj = Trajectory(s)
    assert traj.cover(1.999) == ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert traj.cover(2.0) == ((0.0, 1.0, 0.0), (0.0, 0.0, 0.0))
    assert traj.cover(3.0) == ((0.3, 1.0, 0.0), (90.0, 0.0, 0.0))
    assert traj.cover(3.6) == ((0.5, 1.0, 0.0), (0.0, 0.0, 0.0))  # the larger of two at once
    assert traj.cover(4.0) == ((0.3, 0.0, 0.0), (90.0, 0.0, 0.0))  # 'to' is exclusive; A to the end
    assert Trajectory(parse_scenario("start 0 0 0 0 0 0\n")).cover(1.0) is None


@pytest.mark.parametrize("speed", [20.0, 60.0])
def test_the_hard_built_ins_keep_their_speeds_corners_and_covers(speed):
    """issue 18's scenarios: the S-curve's quarter arcs in opposite senses (the torch turns
    +90 then -90 deg) and its 90 deg corners; abrupt's instant stop and reversal; the
    occluded seam hides B from 2 s to 4 s at any speed, partial covers A 30 % from 1 s."""
    s = builtin_scenario("scurve", speed)
    traj = Trajectory(s)
    arcs = [g for g in s.segments if isinstance(g, Arc)]
    assert [a.angle_deg for a in arcs] == [90.0, -90.0]
    t = np.linspace(0, traj.duration_s, 4001)
    tips = np.array([traj.pose(x)[1] for x in t])
    step = np.linalg.norm(np.diff(tips[:, :3, 3], axis=0), axis=1) / np.diff(t)
    moving = step > 1e-6
    assert np.median(step[moving]) == pytest.approx(speed, rel=1e-3)
    assert step.max() <= speed * (1 + 1e-6)
    yaw = np.degrees(np.arctan2(tips[:, 1, 0], tips[:, 0, 0]))
    assert yaw.max() - yaw[0] == pytest.approx(90.0, abs=0.2) and yaw[-1] == pytest.approx(yaw[0], abs=1e-6)
    # the corner: the direction of travel turns by 90 deg within one sample
    d = np.diff(tips[:, :2, 3], axis=0)[moving]
    heading = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    assert np.abs(np.diff(heading)).max() == pytest.approx(90.0, abs=1.0)
    a = builtin_scenario("abrupt", speed)
    assert any(isinstance(g, Dwell) for g in a.segments[:2])
    ta = Trajectory(a)
    x0 = ta.pose(ta.pieces[1].t0_s)[1][0, 3]
    assert ta.pose(ta.pieces[2].t0_s + 0.5)[1][0, 3] < x0  # reversed after the stop
    for name, covered, t_cover in (("occluded", (0.0, 1.0, 0.0), (2.0, 4.0)), ("partial", (0.3, 0.0, 0.0), (1.0, None))):
        tr = Trajectory(builtin_scenario(name, speed))
        assert tr.cover(t_cover[0] - 0.01)[0] == (0.0, 0.0, 0.0)
        assert tr.cover(t_cover[0])[0] == covered
        end = t_cover[1] if t_cover[1] is not None else tr.duration_s + 100
        assert tr.cover(end - 0.01)[0] == covered
        assert tr.duration_s > (t_cover[1] or t_cover[0]) + 1.0  # still moving after the cover ends
