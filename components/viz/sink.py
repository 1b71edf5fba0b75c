"""Where the rerun data goes: the viz shell's adapter and the stream it opens.

All of viz's I/O is here.  :func:`open_stream` makes a ``rerun.RecordingStream`` with the
sinks of ``[viz] mode`` (a spawned viewer, a gRPC server, a remote viewer, an .rrd file;
a file as well when ``rrd_path`` is set) and humanpt's blueprint.  :class:`ViewerAdapter`
is the live shell's adapter: it opens the stream when the shell starts and logs each
``show:<topic>`` output of the core (a message the core chose to show) with the
:class:`~humanpt.viz.logger.RerunLogger`.
"""

from __future__ import annotations

import logging
import os
import socket
import sys
import time
from pathlib import Path

import rerun as rr

from humanpt.geometry.rig import Rig
from humanpt.schemas.topics import show_topic, shown_short
from humanpt.viz.blueprint import blueprint
from humanpt.viz.config import VizConfig
from humanpt.viz.core import SHOWN_TOPICS
from humanpt.viz.logger import RerunLogger

log = logging.getLogger("humanpt.viz")

__all__ = ["ViewerAdapter", "adapters", "open_stream", "has_display"]


def has_display() -> bool:
    """False on a Linux machine without X11 or Wayland (a spawned viewer could not open)."""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _port_free(ip: str, port: int) -> bool:
    with socket.socket(socket.AF_INET6 if ":" in ip else socket.AF_INET) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((ip, port))
        except OSError:
            return False
    return True


def open_stream(
    config: VizConfig,
    *,
    mode: str | None = None,
    rrd_path: str | Path | None = None,
    name: str | None = None,
) -> tuple[rr.RecordingStream, str]:
    """A recording stream sending to ``mode`` (default ``config.mode``), with the blueprint.

    ``rrd_path``: the file of ``save`` mode, or an extra file in the other modes (default
    ``config.rrd_path``).  ``spawn`` on a machine without a display serves instead.
    Returns the stream and a sentence saying where the data goes.
    """
    mode = mode or config.mode
    path = str(rrd_path if rrd_path is not None else config.rrd_path)
    rec = rr.RecordingStream(config.application_id)
    sinks = []
    where = []
    if mode == "spawn" and not has_display():
        log.warning(
            "viz: no display (DISPLAY/WAYLAND_DISPLAY unset): serving over gRPC instead of spawning "
            "a viewer"
        )
        mode = "serve"
    if mode == "spawn":
        # The viewer is started alone, then joined as one sink among others (rr.spawn(connect=True)
        # would replace any file sink).
        rec.spawn(port=config.grpc_port, connect=False, memory_limit="75%")
        url = f"rerun+http://127.0.0.1:{config.grpc_port}/proxy"
        sinks.append(rr.GrpcSink(url))
        where.append(f"a viewer spawned on port {config.grpc_port}")
    elif mode == "serve":
        if not _port_free(
            config.bind_ip, config.grpc_port
        ):  # rerun would only log it and serve nothing
            raise OSError(
                f"port {config.grpc_port} on {config.bind_ip} is in use (another viewer or viz?); "
                "set [viz] grpc_port"
            )
        server = rr.GrpcServerSink(
            config.bind_ip, config.grpc_port, server_memory_limit=config.server_memory_limit
        )
        sinks.append(server)
        host = "HOST" if config.bind_ip in ("0.0.0.0", "::") else config.bind_ip
        where.append(f"a gRPC server: rerun --connect rerun+http://{host}:{config.grpc_port}/proxy")
    elif mode == "connect":
        sinks.append(rr.GrpcSink(config.connect_url))
        where.append(f"the viewer at {config.connect_url}")
    elif mode != "save":
        raise ValueError(f"unknown viz mode {mode!r}")
    if mode == "save" or path:
        if not path:
            raise ValueError("viz: save mode needs an .rrd path")
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        sinks.append(rr.FileSink(path))
        where.append(f"the file {path}")
    rec.set_sinks(*sinks, default_blueprint=blueprint())
    if name:
        rec.send_recording_name(name)
    return rec, " and ".join(where)


def close_stream(rec: rr.RecordingStream, timeout_s: float = 5.0) -> None:
    """Flush what is buffered (a gone viewer must not hang or fail the caller) and stop."""
    try:
        rec.flush(timeout_sec=timeout_s)
    except Exception as e:  # noqa: BLE001 - e.g. a viewer the user closed
        log.warning("viz: could not flush the rerun stream: %s", e)
    try:
        rec.disconnect()
    except Exception as e:  # noqa: BLE001
        log.warning("viz: could not close the rerun stream: %s", e)


class ViewerAdapter:
    """The viz live shell's adapter: logs what the core forwards (``show:`` topics) to rerun."""

    topics_out = tuple(show_topic(t) for t in SHOWN_TOPICS)

    def __init__(self, config: VizConfig, run_dir: str | Path | None = None, rig: Rig | None = None):
        self.config = config
        self.rig = rig
        self.rrd_path = config.rrd_path
        if config.mode == "save" and not self.rrd_path:
            self.rrd_path = str(Path(run_dir or ".") / "viz.rrd")
        self.rec: rr.RecordingStream | None = None
        self.logger: RerunLogger | None = None
        self.name = Path(run_dir).name if run_dir else None

    def start(self, put) -> None:
        try:
            self.rec, where = open_stream(self.config, rrd_path=self.rrd_path, name=self.name)
        except Exception as e:  # noqa: BLE001 - e.g. the gRPC port is taken
            # A view that cannot open must not take the run down (``humanpt up`` stops every
            # component when one dies): say so loudly and keep recording.
            log.error(
                "viz: cannot open the rerun %s sink (%s): nothing will be shown; the run goes on",
                self.config.mode,
                e,
            )
            return
        self.logger = RerunLogger(self.rec, self.config, rig=self.rig)
        log.info("viz: showing the run in %s", where)

    def write(self, topic: str, msg) -> None:
        if self.logger is not None:
            # Arrival at viz stands for "when it was made" in the latency plots (same machine
            # clock as the stamps: the deployment keeps them synchronised).
            self.logger.log(shown_short(topic), msg, time.time_ns())

    def close(self) -> None:
        if self.rec is not None:
            close_stream(self.rec)
            self.rec = None


def adapters(config: VizConfig, run_dir=None, rig: Rig | None = None) -> list:
    """Registry factory: the viewer adapter (``save`` mode defaults to ``<run dir>/viz.rrd``;
    the views draw the camera and the target as ``rig`` says)."""
    return [ViewerAdapter(config, run_dir=run_dir, rig=rig)]
