"""Issue 29.2: nothing a file or a user names reaches a robot program except through the
whitelist (humanpt.seam.sanitise).

The attack as it was done: a seam file whose NAME holds newlines and statements
(``N=$'inj\\n$OUT[1]=TRUE\\nPTP {A1 0}\\n;.seam.json'; humanpt path export "$N" --format
krl -o out.src``) put ``$OUT[1]=TRUE`` and ``PTP {A1 0}`` into the program as statements.
Here each language gets its own payload (statements it would run) in a real file name,
exported by the real CLI; the program must be the benign-named file's program line for
line, but for the one header comment line, which must be one comment holding no
statement.
"""

from __future__ import annotations

import re
import shutil

import pytest

from humanpt.seam import sanitise
from humanpt.seam.export import FORMATS, SUFFIXES
from tests.conftest import run_cli_here
from tests.seam.test_export import SEAM_FILE

# Per language: the comment leader, statements the robot would run, and how a line of
# the program that is code (not a comment, not blank) looks.
PAYLOADS = {
    "krl": (";", ["$OUT[1]=TRUE", "PTP {A1 0}"]),
    "rapid": ("!", ["SetDO doTorch, 1;", "MoveAbsJ [[0,0,0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v7000, fine, tool0;"]),
    "urscript": ("#", ["set_digital_out(1, True)", "movej([0, 0, 0, 0, 0, 0], a=10, v=3)"]),
    "val": (";", ["SIGNAL 1", "MOVE #safe"]),
}
# Every line break a parser might honour: LF, CR, VT, FF, FS, NEL, LS, PS.
BREAKS = ["\n", "\r", "\x0b", "\x0c", "\x1c", "\x85", "\u2028", "\u2029"]


def _code_lines(text: str, leader: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith(leader)]


@pytest.mark.parametrize("fmt", sorted(PAYLOADS))
@pytest.mark.parametrize("brk", ["\n", "mixed"])
def test_a_crafted_seam_file_name_is_one_comment_line(tmp_path, fmt, brk):
    assert set(PAYLOADS) == set(FORMATS) - {"json"}  # every program format `path export --help` lists
    leader, stmts = PAYLOADS[fmt]
    if brk == "mixed":
        name = "inj" + "".join(b + s for b, s in zip(BREAKS, stmts, strict=False)) + BREAKS[-1] + leader + ".seam.json"
    else:
        name = "inj" + "".join(brk + s for s in stmts) + brk + leader + ".seam.json"
    crafted, benign = tmp_path / name, tmp_path / "benign.seam.json"
    shutil.copyfile(SEAM_FILE, crafted)
    shutil.copyfile(SEAM_FILE, benign)
    outs = {}
    for src in (crafted, benign):
        out = tmp_path / f"{'c' if src == crafted else 'b'}{SUFFIXES[fmt]}"
        r = run_cli_here("path", "export", str(src), "--format", fmt, "-o", str(out), "--name", "seam")
        assert r.returncode == 0, r.stderr
        assert len(r.stdout.splitlines()) == 1  # the report names the file on one line too
        outs[src] = out.read_text()
    got, want = outs[crafted].splitlines(), outs[benign].splitlines()
    # As many lines, as many statements as the benign program (the attack added 2 of each).
    assert len(got) == len(want), "\n".join(got[:6])
    assert _code_lines(outs[crafted], leader) == _code_lines(outs[benign], leader)
    differ = [i for i, (a, b) in enumerate(zip(got, want, strict=True)) if a != b]
    assert len(differ) == 1  # the header line that names the file
    line = got[differ[0]]
    assert line.lstrip().startswith(leader + " humanpt path export --format")
    body = line.lstrip()[len(leader):]
    assert set(body) <= sanitise.COMMENT_CHARS and leader not in body
    assert not any(line.strip() == s for s in stmts for line in got)
    # The text itself splits into no more lines under any line-break rule (str.splitlines
    # honours every break above).
    assert outs[crafted].count("\n") == len(outs[crafted].splitlines())


@pytest.mark.parametrize("fmt", sorted(PAYLOADS))
def test_a_crafted_program_name_is_an_identifier(tmp_path, fmt):
    leader, stmts = PAYLOADS[fmt]
    name = "x\n" + "\n".join(stmts) + "\nEND"
    out = tmp_path / f"p{SUFFIXES[fmt]}"
    benign = tmp_path / f"b{SUFFIXES[fmt]}"
    assert run_cli_here("path", "export", str(SEAM_FILE), "-f", fmt, "-o", str(out), "--name", name).returncode == 0
    assert run_cli_here("path", "export", str(SEAM_FILE), "-f", fmt, "-o", str(benign), "--name", "seam").returncode == 0
    got, want = out.read_text(), benign.read_text()
    assert len(got.splitlines()) == len(want.splitlines())
    first = got.splitlines()[0]
    prog = sanitise.identifier(name, fmt)
    assert re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", prog) and len(prog) <= sanitise.LANGUAGES[fmt].name_max
    assert first == want.splitlines()[0].replace("seam", prog, 1)


def test_json_program_carries_the_name_through_the_whitelist(tmp_path):
    crafted = tmp_path / "inj\n$OUT[1]=TRUE\n;.seam.json"
    shutil.copyfile(SEAM_FILE, crafted)
    out = tmp_path / "p.json"
    assert run_cli_here("path", "export", str(crafted), "-f", "json", "-o", str(out), "--name", "a\nb").returncode == 0
    import json

    d = json.loads(out.read_text())
    assert d["name"] == "a_b" and set(d["source"]) <= sanitise.COMMENT_CHARS


def test_comment_whitelist():
    for lang in ("krl", "rapid", "urscript", "val"):
        text = "a" + "".join(BREAKS) + ";!#\\\"$&{}`\x00\x7f\u00e9" + "b" * 300
        c = sanitise.comment(text, lang)
        assert set(c) <= sanitise.COMMENT_CHARS and len(c) == sanitise.MAX_COMMENT and c.endswith("...")
        assert c.startswith("a" + "?" * (len(BREAKS) + 13))
        assert sanitise.comment_line("x\ny", lang, "  ") == f"  {sanitise.LANGUAGES[lang].leader} x?y"
    assert sanitise.comment("humanpt path export --format krl: path-1.seam.json") == \
        "humanpt path export --format krl: path-1.seam.json"


@pytest.mark.parametrize("name, lang, want", [
    ("seam", "krl", "seam"), ("path-1 (copy)", "rapid", "path_1_copy"), ("1st", "urscript", "p_1st"),
    ("END", "krl", "prog_END"), ("end", "krl", "prog_end"), ("main", "rapid", "prog_main"),
    ("movej", "urscript", "prog_movej"), ("MOVE", "val", "prog_move"), ("p0", "rapid", "prog_p0"),
    ("zSeam1", "rapid", "prog_zSeam1"), ("Seam", "val", "seam"), ("\u00e9t\u00e9", "krl", "t"),
    ("", "krl", "seam"), ("$OUT", "krl", "prog_OUT"), ("$VEL", "krl", "VEL"), ("a" * 40, "krl", "a" * 24), ("a" * 40, "rapid", "a" * 32),
    ("a" * 40, "val", "a" * 15), ("_" * 5, "val", "seam"),
])
def test_identifier(name, lang, want):
    assert sanitise.identifier(name, lang) == want


def test_shown_escapes_a_name_for_one_line():
    assert sanitise.shown("a.json") == "a.json"
    assert sanitise.shown("a\nb") == "'a\\nb'" and "\n" not in sanitise.shown("a\u2028b")
