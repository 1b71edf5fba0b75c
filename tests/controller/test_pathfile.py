"""Path files: CSV round trip, clear errors with line numbers, RTS smoothing, VAL II export,
and the shell's PathWriter that appends points as they come."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from humanpt.controller import pathfile
from humanpt.controller.shell import PathWriter
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, pose
from tests.conftest import run_cli_here


def _path(n=50, tip=True, seed=0):
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(0, 1, (n, 6)), axis=0)
    x[:, 3:] = (x[:, 3:] + 180) % 360 - 180
    return pathfile.Path6(np.arange(n), np.arange(n, dtype=np.int64) * 280_000_000 + 7, x,
                          x + 5 if tip else None)


@pytest.mark.parametrize("tip", [True, False])
def test_csv_round_trip(tmp_path, tip):
    p = _path(tip=tip)
    f = tmp_path / "p.csv"
    pathfile.write(f, p)
    q = pathfile.read(f)
    np.testing.assert_array_equal(q.stamp_ns, p.stamp_ns)
    np.testing.assert_allclose(q.x_g, p.x_g, atol=1e-6)
    assert (q.x_tip is None) == (not tip)
    assert q.points() is (q.x_tip if tip else q.x_g)


def test_bad_files_name_the_line(tmp_path):
    with pytest.raises(pathfile.PathFileError, match="no such path file"):
        pathfile.read(tmp_path / "none.csv")
    f = tmp_path / "p.csv"
    f.write_text("a,b\n")
    with pytest.raises(pathfile.PathFileError, match=r"p.csv:1: not a humanpt path header"):
        pathfile.read(f)
    f.write_text(",".join(pathfile.HEADER) + "\n0,1,1,2,3,4,5,6\n1,2,1,2,3,4,5\n")
    with pytest.raises(pathfile.PathFileError, match=r"p.csv:3: 7 columns, expected 8"):
        pathfile.read(f)
    f.write_text(",".join(pathfile.HEADER) + "\n0,1,1,2,x,4,5,6\n")
    with pytest.raises(pathfile.PathFileError, match=r"p.csv:2: could not convert"):
        pathfile.read(f)


def test_rts_smoothing_reduces_noise_and_keeps_angles_wrapped():
    rng = np.random.default_rng(4)
    t = np.arange(300) * 0.28
    truth = np.column_stack([10 * t, 2 * t, np.full_like(t, 85.0), np.full_like(t, 179.5), 0 * t, 0 * t])
    noisy = truth + rng.normal(0, 0.3, truth.shape)
    noisy[:, 3:] = (noisy[:, 3:] + 180) % 360 - 180
    sm = pathfile.smooth(noisy, (t * 1e9).astype(np.int64), accel_sigma=1.0, meas_sigma=0.3)
    err_raw = np.abs(noisy[:, :3] - truth[:, :3]).mean()
    err_sm = np.abs(sm[:, :3] - truth[:, :3]).mean()
    assert err_sm < 0.5 * err_raw
    yaw_err = np.abs((sm[:, 3] - 179.5 + 180) % 360 - 180).mean()
    assert yaw_err < 0.2  # not averaged through 0 across the +-180 seam
    assert np.all(np.abs(sm[:, 3:]) <= 180)


def test_val2_export():
    x = _path(5).x_g
    text = pathfile.to_val2(x, "seam 1")
    lines = text.splitlines()
    assert lines[0] == ".PROGRAM seam_1()" and lines[-1] == ".END"
    assert sum(line.strip().startswith("SET p") for line in lines) == 5
    assert sum(line.strip().startswith("MOVES p") for line in lines) == 5
    assert f"TRANS({x[0, 0]:.2f}, {x[0, 1]:.2f}, {x[0, 2]:.2f}" in text


def test_path_writer_appends_as_points_arrive(tmp_path):
    w = PathWriter(tmp_path / "paths")
    w.start(lambda *a: None)
    w.write("controller/events", pb.Event(code="record_started", text=json.dumps({"has_tip": True})))
    T = np.eye(4)
    T[:3, 3] = [0.1, 0.2, 0.3]
    for i in range(3):
        w.write("controller/path", pb.PathPoint(header=header(i * 10, i), index=i, world_T_tob=pose(T),
                                                has_tip=True, world_T_tip=pose(T)))
        # Readable at once (flushed): a crash loses nothing.
        assert len(pathfile.read(tmp_path / "paths" / "path-1.csv")) == i + 1
    w.write("controller/events", pb.Event(code="save", text=json.dumps({"file": "seam.csv"})))
    w.close()
    p = pathfile.read(tmp_path / "paths" / "seam.csv")
    np.testing.assert_allclose(p.x_g[0, :3], [100, 200, 300])
    np.testing.assert_allclose(p.x_tip[2, :3], [100, 200, 300])


def test_cli_path_verbs(tmp_path, capsys, cli_main):
    f = tmp_path / "p.csv"
    pathfile.write(f, _path(30))
    assert cli_main(["path", "smooth", str(f), str(tmp_path / "s.csv")]) == 0
    assert len(pathfile.read(tmp_path / "s.csv")) == 30
    assert cli_main(["path", "val", str(f), str(tmp_path / "p.v2"), "--name", "seam"]) == 0
    assert (tmp_path / "p.v2").read_text().startswith(".PROGRAM seam()")
    assert cli_main(["path", "val", str(tmp_path / "missing.csv"), str(tmp_path / "x.v2")]) == 2
    assert "no such path file" in capsys.readouterr().err
    # Never over the input, never over another file unasked (issue 20: smooth overwrote its input).
    before = f.read_bytes()
    assert cli_main(["path", "smooth", str(f), str(f)]) == 2
    assert "is the input" in capsys.readouterr().err and f.read_bytes() == before
    assert cli_main(["path", "smooth", str(f), str(tmp_path / "s.csv")]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert cli_main(["path", "smooth", str(f), str(tmp_path / "s.csv"), "--overwrite"]) == 0


# -- saving never leaves paths/, never overwrites, never truncates (issue 14, items 8 and 11) --
def _writer_with_a_path(paths, reports):
    w = PathWriter(paths)
    w.start(lambda topic, msg: reports.append((topic, msg.code, msg.text)))
    w.write("controller/events", pb.Event(code="record_started", text="{}"))
    w.write("controller/path", pb.PathPoint(header=header(0, 0), index=0, world_T_tob=pose(np.eye(4))))
    return w


def _save(w, **request):
    w.write("controller/events", pb.Event(code="save", text=json.dumps(request)))


def test_save_goes_only_into_paths_and_never_overwrites_unasked(tmp_path):
    paths, reports = tmp_path / "run" / "paths", []
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    (paths.parent).mkdir()
    w = _writer_with_a_path(paths, reports)
    # The attack: a path out of paths/ (absolute, relative, through a symlink).
    (paths / "link").symlink_to(victim)
    for name in (str(victim), "../victim.txt", "link"):
        _save(w, file=name)
    assert victim.read_text() == "precious"
    assert [code for _, code, _ in reports] == ["save_failed"] * 3
    _save(w, file="seam.csv")
    assert reports[-1][:2] == ("path_file", "path_saved")
    (paths / "seam.csv").write_text("edited by hand")
    _save(w, file="seam.csv")
    assert reports[-1][1] == "save_failed" and "exists" in reports[-1][2]
    assert (paths / "seam.csv").read_text() == "edited by hand"
    _save(w, file="seam.csv", overwrite=True)
    assert reports[-1][1] == "path_saved"
    assert len(pathfile.read(paths / "seam.csv")) == 1
    w.close()


def test_a_restarted_writer_continues_the_numbering_and_truncates_nothing(tmp_path):
    paths = tmp_path / "paths"
    first = _writer_with_a_path(paths, [])
    first.close()
    before = (paths / "path-1.csv").read_bytes()
    second = _writer_with_a_path(paths, [])  # the controller restarted into the same run
    second.close()
    assert (paths / "path-1.csv").read_bytes() == before
    assert second.current == paths / "path-2.csv"
    assert len(pathfile.read(paths / "path-2.csv")) == 1


def _cov_path(n=20, tip=True, seed=1):
    p = _path(n, tip=tip, seed=seed)
    rng = np.random.default_rng(seed)

    def spd():
        a = rng.normal(size=(n, 3, 3))
        return np.einsum("nij,nkj->nik", a, a) * 0.01

    p.orientation_held = rng.random(n) < 0.3
    p.orientation_held[0] = False
    p.cov_g_mm2, p.cov_r_deg2 = spd(), spd()
    p.cov_tip_mm2 = spd() if tip else None
    return p


@pytest.mark.parametrize("tip", [True, False])
def test_csv_round_trip_with_the_held_flag_and_covariance(tmp_path, tip):
    p = _cov_path(tip=tip)
    f = tmp_path / "c.csv"
    pathfile.write(f, p)
    head = f.read_text().splitlines()[0].split(",")
    assert head == pathfile.header(tip, with_covariance=True) and "cov_rzz_deg2" in head
    q = pathfile.read(f)
    np.testing.assert_array_equal(q.orientation_held, p.orientation_held)
    for name in ("cov_g_mm2", "cov_r_deg2") + (("cov_tip_mm2",) if tip else ()):
        np.testing.assert_allclose(getattr(q, name), getattr(p, name), rtol=1e-5, atol=1e-12)
    assert (q.cov_tip_mm2 is None) == (not tip)
    # An old file (no such columns) still reads, without them.
    old = tmp_path / "old.csv"
    pathfile.write(old, _path(5, tip=tip))
    o = pathfile.read(old)
    assert o.orientation_held is None and o.cov_g_mm2 is None and len(o) == 5
    # Not a number: refused, naming the line (the third data row) and the column.
    lines = f.read_text().splitlines()
    lines[3] = lines[3].rsplit(",", 1)[0] + ",nan"
    f.write_text("\n".join(lines) + "\n")
    last = pathfile.header(tip, with_covariance=True)[-1]
    with pytest.raises(pathfile.PathFileError, match=rf"c\.csv:4: {last} is nan, not a finite number"):
        pathfile.read(f)


def test_cli_smooth_and_val_fill_held_orientations(tmp_path, cli_main):
    p = _cov_path(30, tip=False)
    p.x_g[:, 3:] = [10.0, 5.0, 170.0]
    p.x_g[p.orientation_held, 3] = 60.0  # held orientations drifted
    p.orientation_held[-1] = False
    f = tmp_path / "h.csv"
    pathfile.write(f, p)
    assert cli_main(["path", "val", str(f), str(tmp_path / "h.v2")]) == 0
    text = (tmp_path / "h.v2").read_text()
    from scipy.spatial.transform import Rotation

    expect = Rotation.from_euler("ZYX", [10.0, 5.0, 170.0], degrees=True).as_euler("ZYZ", degrees=True)
    for i in np.flatnonzero(p.orientation_held):  # every SET line has the measured orientation
        line = text.splitlines()[3 + i]
        got = [float(v) for v in line.split("TRANS(")[1].rstrip(")").split(",")[3:]]
        np.testing.assert_allclose(got, expect, atol=2e-3)
    assert cli_main(["path", "smooth", str(f), str(tmp_path / "s.csv")]) == 0
    s = pathfile.read(tmp_path / "s.csv")
    np.testing.assert_array_equal(s.orientation_held, p.orientation_held)
    np.testing.assert_allclose(s.cov_g_mm2, p.cov_g_mm2, rtol=1e-5)
    assert np.abs(s.x_g[:, 3] - 10.0).max() < 0.5  # smoothed through the filled orientations, not 60


# ---------------------------------------------------------------------------- issue 29.3 / 29.14

ARC_PATH = Path(__file__).resolve().parents[2] / "recordings" / "arc" / "paths" / "path-1.csv"


def _crafted(tmp_path, line: int, col: int, value: str) -> Path:
    """The recorded arc path with one cell (data line ``line``, column ``col``) replaced."""
    lines = ARC_PATH.read_text().splitlines()
    cells = lines[line].split(",")
    cells[col] = value
    lines[line] = ",".join(cells)
    f = tmp_path / "bad.csv"
    f.write_text("\n".join(lines) + "\n")
    return f


@pytest.mark.parametrize("col, value, says", [
    (2, "1e308", "bad.csv:3: x_mm 1e+308 mm is outside [-10000, 10000]"),
    (6, "-1e300", "bad.csv:3: theta_deg -1e+300 deg is outside [-720, 720]"),
    (2, "inf", "bad.csv:3: x_mm is inf, not a finite number"),
    (1, "9" * 30, "bad.csv:3: stamp_ns 999999999999999999999999999999 is outside int64"),
    (0, "1e300", "bad.csv:3: index 1e+300 is outside [0, 2147483647]"),
    (9, "1e300", "bad.csv:3: cov_xx_mm2 1e+300 is outside [-100000000, 100000000]"),
    (8, "0.5", "bad.csv:3: orientation_held 0.5 is not a whole number"),
], ids=["x 1e308", "theta", "inf", "stamp 30 digits", "index", "covariance", "held"])
@pytest.mark.parametrize("verb", ["smooth", "val", "fit"])
def test_absurd_values_are_refused_naming_line_and_column(tmp_path, verb, col, value, says):
    """`path smooth` of x = 1e308 wrote nan in every row, `path val` wrote 1e308, a
    30-digit stamp raised OverflowError: now one line naming the file, line and column,
    exit 2, no output."""
    f = _crafted(tmp_path, 2, col, value)
    if verb == "fit":
        args = ["--no-plot", "-o", str(tmp_path / "o.json")]
    else:
        args = [str(tmp_path / "o")]
    r = run_cli_here("path", verb, str(f), *args)  # (in this process: a file in, an error out)
    assert r.returncode == 2 and "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert says in r.stderr, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv"]


@pytest.mark.parametrize("content, says", [
    (b"1" * 200_000 + b"\n", "not a path file (field larger than field limit"),  # was _csv.Error
    (b"\xff\xfe\x00\x01\n", "not a path file ('utf-8' codec can't decode"),
    (b"0,1\x00,2\n", "3 columns, expected"),
], ids=["long field", "binary", "NUL"])
def test_broken_files_are_refused_in_one_line(tmp_path, content, says):
    f = tmp_path / "bad.csv"
    f.write_bytes(ARC_PATH.read_bytes().splitlines(keepends=True)[0] + content)
    with pytest.raises(pathfile.PathFileError) as e:
        pathfile.read(f)
    assert says in str(e.value) and "bad.csv" in str(e.value) and "\n" not in str(e.value)


def test_smooth_and_val_refuse_what_they_cannot_write():
    x = np.zeros((5, 6))
    x[:, 0] = [0.0, 1.0, 1e308, 3.0, 4.0]
    with pytest.raises(pathfile.PathFileError, match="beyond"):
        pathfile.smooth(x, np.arange(5, dtype=np.int64) * 280_000_000)
    with pytest.raises(pathfile.PathFileError, match=r"point 2 \(1e\+308, 0, 0\) mm is beyond the workspace"):
        pathfile.to_val2(x)
    x[2, 0] = 1601.0  # the gateway's box ends at x = 1600 mm
    with pytest.raises(pathfile.PathFileError, match=r"point 2 \(1601, 0, 0\) mm is beyond the workspace"):
        pathfile.to_val2(x)
    with pytest.raises(pathfile.PathFileError, match="percent"):
        pathfile.to_val2(np.zeros((2, 6)), speed_percent=1e308)


def test_val_program_name_is_an_identifier():
    """--name reaches the program only through the whitelist (humanpt.seam.sanitise):
    a name with a newline and a statement is one VAL II name."""
    text = pathfile.to_val2(np.tile([0.0, 0.0, 0.0, 10.0, 20.0, 30.0], (2, 1)), "x\nSIGNAL 1\nEND")
    assert text.splitlines()[0] == ".PROGRAM x_signal_1_end()"
    assert len(text.splitlines()) == 2 + 1 + 2 + 2 + 1
    assert pathfile.re_name("MOVE") == "prog_move" and pathfile.re_name("") == "path"


def test_a_long_row_of_short_fields_is_refused(tmp_path):
    f = tmp_path / "bad.csv"
    f.write_text(ARC_PATH.read_text().splitlines()[0] + "\n" + "1," * 5000 + "1\n")
    with pytest.raises(pathfile.PathFileError, match=r"bad.csv:2: a row of more than 4096 characters"):
        pathfile.read(f)
