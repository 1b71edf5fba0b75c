"""The only way text from a file or a user reaches a robot program: a whitelist.

A seam file's name, a program name, anything a person or a file chose, is written into
a program only through :func:`comment` (the body of one comment line) or
:func:`identifier` (a name the language accepts).  Both keep what is on a whitelist and
replace or drop everything else, so no newline (``\\n``, ``\\r``, ``\\v``, ``\\f``,
U+0085, U+2028, ...), control character, comment leader or non-ASCII character can end
the comment and start a statement, and no name can be a keyword, one of the program's
own symbols or longer than the language allows.

==========  ===============  ==================================================  ======
language    comment          names                                               length
==========  ===============  ==================================================  ======
krl         ``; ...``        letter, then letters, digits, ``_`` (no ``$``)       24
rapid       ``! ...``        letter, then letters, digits, ``_``                  32
urscript    ``# ...``        letter, then letters, digits, ``_``                  32
val         ``; ...``        letter, then lower-case letters, digits, ``_``       15
json        (a string)       as krl                                              24
==========  ===============  ==================================================  ======

Keywords and the program's own names (``main``, ``tSeam``, ``vSeam``, ``zSeam1``,
``p0``, ``movel``, ...) get a ``prog_`` prefix; the comparison ignores case where the
language does (KRL, RAPID, VAL II).
"""

from __future__ import annotations

import re
import string
from dataclasses import dataclass

__all__ = ["LANGUAGES", "COMMENT_CHARS", "MAX_COMMENT", "comment", "comment_line", "identifier", "shown"]

# Printable ASCII without the comment leaders of any of the languages (; ! #), the
# backslash (a line continuation or an escape), quotes that open strings ("), the KRL
# system-variable sigil ($) and the braces of KRL aggregates.
COMMENT_CHARS = frozenset(string.ascii_letters + string.digits + " _-.,:+=/()[]'<>@%*~^?")
MAX_COMMENT = 200  # characters of one comment's body; longer is cut, marked "..."
_REPLACEMENT = "?"


@dataclass(frozen=True)
class Language:
    leader: str  # what starts a comment running to the end of the line
    name_max: int  # longest name
    case_insensitive: bool
    lower: bool  # names are written in lower case
    reserved: frozenset[str]  # keywords and the program's own names (as compared)


def _words(s: str, upper: bool) -> frozenset[str]:
    return frozenset(w.upper() if upper else w for w in s.split())


_KRL = _words("""
    DEF END DEFFCT ENDFCT DEFDAT ENDDAT GLOBAL PUBLIC DECL CONST SIGNAL STRUC ENUM IMPORT IS
    INT REAL BOOL CHAR FRAME POS E6POS AXIS E6AXIS TRUE FALSE NOT AND OR EXOR B_AND B_OR B_NOT B_EXOR
    IF THEN ELSE ENDIF FOR TO STEP ENDFOR WHILE ENDWHILE LOOP ENDLOOP REPEAT UNTIL SWITCH CASE DEFAULT
    ENDSWITCH GOTO RETURN EXIT HALT WAIT SEC DELAY CONTINUE INTERRUPT TRIGGER WHEN DISTANCE DO PRIO ON OFF
    BRAKE RESUME PTP LIN CIRC PTP_REL LIN_REL CIRC_REL SPLINE ENDSPLINE SPL SLIN SCIRC SPTP C_DIS C_PTP
    C_VEL C_ORI C_SPL ANIN ANOUT IN OUT MAXIMUM MINIMUM""", True)
_RAPID = _words("""
    MODULE ENDMODULE PROC ENDPROC FUNC ENDFUNC TRAP ENDTRAP RECORD ENDRECORD IF THEN ELSE ELSEIF ENDIF
    FOR FROM TO STEP DO ENDFOR WHILE ENDWHILE TEST CASE DEFAULT ENDTEST GOTO RETURN RAISE RETRY TRYNEXT
    EXIT CONST PERS VAR LOCAL TASK ALIAS AND OR XOR NOT DIV MOD TRUE FALSE BACKWARD ERROR UNDO CONNECT
    WITH NOSTEPIN VIEWONLY READONLY SYSMODULE INOUT NOVIEW
    MAIN TSEAM VSEAM V100 FINE WOBJ0 TOOL0 MOVEJ MOVEL MOVEC CONFJ CONFL WAITTIME""", True)
_URSCRIPT = _words("""
    def end if elif else while for in return thread run kill join True False and or not xor global local
    halt break continue pass sec
    movej movel movec set_tcp sleep p""", False)
_VAL = _words("""
    PROGRAM END MOVE MOVES SET TRANS SPEED ALWAYS TOOL BREAK DELAY IF THEN ELSE GOTO RETURN CALL
    STOP PAUSE HALT TYPE ABORT EXECUTE""", True)

LANGUAGES: dict[str, Language] = {
    "krl": Language(";", 24, True, False, _KRL),
    "rapid": Language("!", 32, True, False, _RAPID),
    "urscript": Language("#", 32, False, False, _URSCRIPT),
    "val": Language(";", 15, True, True, _VAL),
    "json": Language("", 24, False, False, frozenset()),
}
# The programs' own numbered names (p0 robtargets and VAL points, zSeam1 zonedata).
_OWN = re.compile(r"^(p|zseam)\d+$", re.IGNORECASE)


def _language(lang: str) -> Language:
    try:
        return LANGUAGES[lang]
    except KeyError:
        raise ValueError(f"no sanitiser for language {lang!r}; one of {', '.join(LANGUAGES)}") from None


def comment(text: str, lang: str = "json") -> str:
    """``text`` as the body of ONE comment line of ``lang``: characters outside
    :data:`COMMENT_CHARS` become ``?`` (a newline or a comment leader among them), at most
    :data:`MAX_COMMENT` characters."""
    _language(lang)
    out = "".join(c if c in COMMENT_CHARS else _REPLACEMENT for c in str(text))
    return out if len(out) <= MAX_COMMENT else out[:MAX_COMMENT - 3] + "..."


def comment_line(text: str, lang: str, indent: str = "") -> str:
    """A whole comment line of ``lang`` (no line end): the indent, the leader, the body."""
    lead = _language(lang).leader
    if not lead:
        raise ValueError(f"{lang} has no comment lines")
    if indent.strip(" "):
        raise ValueError("an indent is spaces")
    return f"{indent}{lead} {comment(text, lang)}"


def identifier(name: str, lang: str, default: str = "seam") -> str:
    """``name`` as a name ``lang`` accepts (see the module doc): other characters become
    ``_``, leading and trailing ``_`` go, a name not starting with a letter gets ``p_``, a
    keyword or one of the program's own names ``prog_``; cut to the language's length;
    ``default`` when nothing is left."""
    lg = _language(lang)
    clean = "".join(c if c.isascii() and c.isalnum() else "_" for c in str(name)).strip("_")
    clean = re.sub(r"_+", "_", clean) or default
    if lg.lower:
        clean = clean.lower()
    if not clean[0].isalpha():
        clean = f"p_{clean}"
    key = clean.upper() if lg.case_insensitive else clean
    if key in lg.reserved or _OWN.match(clean):
        clean = f"prog_{clean}"
    return clean[:lg.name_max].rstrip("_")


def shown(text: object) -> str:
    """``text`` (a file name, a value from a file) fit for a one-line message: itself when
    printable, else Python's escaped ``ascii()`` form (a newline shows as ``\\n``)."""
    s = str(text)
    return s if s.isprintable() and s.isascii() else ascii(s)
