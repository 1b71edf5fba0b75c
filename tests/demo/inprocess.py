"""``humanpt ARGV`` in the test's own process (no interpreter start-up, no imports again:
`humanpt --help` alone takes 1.17 s, issue 31), for commands whose process boundary is not what a
test checks: not for one whose children write to its stdout (``humanpt up``: they inherit the fd,
which capsys does not see).
Use the ``cli`` fixture (``cli = inprocess.cli`` in a module): ``cli(*argv)`` is ``(exit status,
stdout, stderr)``, a ``SystemExit`` message on stderr as the interpreter prints it."""

from __future__ import annotations

import io
import signal
import sys

import pytest

from tests.conftest import in_process_cli


class Cli:
    """``humanpt.cli.main.main`` with its output captured (capsys) and, if asked, a stdin."""

    def __init__(self, main, capsys, monkeypatch):
        self.main, self.capsys, self.monkeypatch = main, capsys, monkeypatch

    def __call__(self, *argv: str, stdin: str | None = None) -> tuple[int, str, str]:
        self.capsys.readouterr()  # what came before is not this command's
        # (a command that handles SIGINT/SIGTERM, as `humanpt demo` does, leaves pytest's as they were)
        handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
        with self.monkeypatch.context() as mp:
            if stdin is not None:
                mp.setattr(sys, "stdin", io.StringIO(stdin))
            try:
                code = self.main(list(argv))
            except SystemExit as e:  # as the interpreter ends: a message is printed, status 1
                code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
                if not isinstance(e.code, int) and e.code is not None:
                    print(e.code, file=sys.stderr)
            finally:
                for sig, handler in handlers.items():
                    signal.signal(sig, handler)
        got = self.capsys.readouterr()
        return code, got.out, got.err


@pytest.fixture
def cli(capsys, monkeypatch):
    """:class:`Cli` for one test (the process's settings left as they were: in_process_cli)."""
    with in_process_cli() as main:
        yield Cli(main, capsys, monkeypatch)
