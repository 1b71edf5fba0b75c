"""The two installs: the full one (``pip install -e .``: the demo, the client, the tools) and
the server's lean one (``requirements/server.txt``: the router, the robot gateway and its
links, the bus tools), which lacks the packages :data:`FULL_ONLY` names."""

from __future__ import annotations

# Import names of the packages only the full install has: the router's, the gateway's and
# `humanpt up --profile server`'s imports never reach them (tests/deploy/test_server_install.py).
FULL_ONLY = ("cv2", "rerun", "filterpy", "foxglove", "matplotlib", "rich", "numba")


def needs_full_install(e: ImportError) -> str | None:
    """A one-line explanation when ``e`` is a package of the full install missing (a verb of
    the client or the demo run on the server's install); None for any other import error."""
    name = (getattr(e, "name", None) or "").split(".")[0]
    if name not in FULL_ONLY:
        return None
    return (f"needs the full install (no module {name!r} here: this is the server's lean install, "
            f"requirements/server.txt); run it on the client, or `pip install -e .`")
