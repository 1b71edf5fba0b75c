"""``humanpt path export --arc`` (issue 34 item 6): the arc switched on at the seam's start and
off at its end, in each language's standard way, and every value checked before it is
written.  Expected statements from the vendors' manuals: KUKA KSS ``$OUT[n] = TRUE`` (n
1..4096), URScript ``set_standard_digital_out(n, b)`` (n 0..7), RAPID ``SetDO signal, 1``
and RobotWare Arc's ``ArcLStart`` / ``ArcL`` / ``ArcC`` / ``ArcLEnd`` / ``ArcCEnd`` (ToPoint
[, CirPoint], Speed, Seam, Weld, Zone, Tool); the seam is test_export's hand-made one (a
line, a tangent arc, two lines)."""

from __future__ import annotations

import dataclasses
import json
import re

import pytest

from humanpt.seam.export import ExportError, export
from tests.conftest import run_cli_here
from tests.seam.test_export import SEAM_FILE, hand_made_seam, options

SEAM = hand_made_seam()


def program(fmt: str, arc: str) -> list[str]:
    return export(SEAM, fmt, dataclasses.replace(options(), arc=arc)).splitlines()


def statements(lines: list[str], pattern: str) -> list[str]:
    return [s.strip() for s in lines if re.match(pattern, s.strip())]


def test_krl_switches_the_output_after_the_approach_and_after_the_last_move():
    lines = [s.strip() for s in program("krl", "3")]
    moves = [i for i, s in enumerate(lines) if s.startswith(("PTP ", "LIN ", "CIRC "))]
    on, off = lines.index("$OUT[3] = TRUE"), lines.index("$OUT[3] = FALSE")
    # on between the PTP to the seam's start and the first LIN; off after the last move
    assert lines[moves[0]].startswith("PTP") and moves[0] < on < moves[1]
    assert off > moves[-1] and lines[off + 1] == "END"
    # the moves themselves are those without --arc
    assert [s for s in lines if not s.startswith(("$OUT", ";"))] == [
        s.strip() for s in program("krl", "") if not s.strip().startswith(";")]


def test_urscript_and_rapid_signal_switch_an_output():
    ur = [s.strip() for s in program("urscript", "0")]
    assert ur.index("set_standard_digital_out(0, True)") == next(
        i for i, s in enumerate(ur) if s.startswith("movej(")) + 1
    assert ur[-2:] == ["set_standard_digital_out(0, False)", "end"]
    rapid = [s.strip() for s in program("rapid", "doArcOn")]
    movej = next(i for i, s in enumerate(rapid) if s.startswith("MoveJ "))
    assert rapid[movej + 1] == "SetDO doArcOn, 1;"
    assert rapid[-3:] == ["SetDO doArcOn, 0;", "ENDPROC", "ENDMODULE"]
    assert rapid[-4].startswith("MoveL ") and ", fine, tSeam" in rapid[-4]  # off once stopped at the end


def test_rapid_arcware_welds_with_arc_instructions():
    lines = program("rapid", "arcware:smFillet,wdFillet")
    arcs = statements(lines, r"(Move|Arc)")
    kinds = [s.split()[0] for s in arcs]
    # MoveJ to the start, ArcLStart there (the weld starts where it ends), then the seam's
    # moves as ArcL/ArcC with the last one ending the weld
    assert kinds == ["MoveJ", "ArcLStart", "ArcL", "ArcC", "ArcL", "ArcLEnd"]
    assert arcs[0].split()[1].rstrip(",") == arcs[1].split()[1].rstrip(",")  # the same point
    assert all("smFillet, wdFillet" in s for s in arcs[1:])
    assert re.fullmatch(r"ArcC p\d+, p\d+, vSeam, smFillet, wdFillet, \w+, tSeam \\WObj:=wobj0;", arcs[3])
    assert ", fine, tSeam" in arcs[-1]
    default = statements(program("rapid", "arcware"), r"ArcLStart")[0]
    assert "seam1, weld1, fine" in default


@pytest.mark.parametrize(("fmt", "arc", "says"), [
    ("krl", "0", "1..4096"), ("krl", "4097", "1..4096"), ("krl", "3;HALT", "1..4096"),
    ("urscript", "8", "0..7"), ("urscript", "-1", "0..7"), ("urscript", "1.5", "0..7"),
    ("rapid", "do;Stop", "not a RAPID name"), ("rapid", "1do", "not a RAPID name"),
    ("rapid", "MoveL", "not a RAPID name"), ("rapid", "doArc\nStop", "not a RAPID name"),
    ("rapid", "arcware:sm1", "arcware:SEAMDATA,WELDDATA"), ("rapid", "arcware:sm1,wd 1", "not a RAPID name"),
    ("val", "1", "VAL II"),
])
def test_a_bad_arc_switch_is_refused_by_name(fmt, arc, says):
    with pytest.raises(ExportError, match=re.escape(says)):
        program(fmt, arc)


def test_json_records_where_the_arc_goes_on_and_off():
    doc = json.loads("\n".join(program("json", "doArc")))
    assert doc["arc"] == {"signal": "doArc", "on_after_move": 0, "off_after_move": len(doc["moves"]) - 1}
    assert "arc" not in json.loads("\n".join(program("json", "")))


def test_the_cli_writes_it_and_refuses_without_writing(tmp_path):
    out = tmp_path / "weld.src"
    r = run_cli_here("path", "export", str(SEAM_FILE), "--format", "krl", "--arc", "5", "--output", str(out))
    assert r.returncode == 0, r.stderr
    assert "$OUT[5] = TRUE" in out.read_text()
    bad = tmp_path / "bad.src"
    r = run_cli_here("path", "export", str(SEAM_FILE), "--format", "krl", "--arc", "9999", "--output", str(bad))
    assert r.returncode != 0 and "1..4096" in r.stderr and not bad.exists()
