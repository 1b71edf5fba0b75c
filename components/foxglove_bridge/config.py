"""Configuration of the Foxglove bridge (section ``[foxglove_bridge]``).

Where the Foxglove WebSocket server listens (loopback unless told otherwise), how often each
channel may go to the browser, and who may use the operator's services.  README.md has the
table.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from humanpt.runtime.config import Range, live

__all__ = ["FoxgloveBridgeConfig", "LOOPBACK"]

LOOPBACK = ("127.0.0.1", "::1", "localhost")


@dataclass(frozen=True)
class FoxgloveBridgeConfig:
    """``[foxglove_bridge]`` (README.md of the component has the table)."""

    # The address the WebSocket server binds to: loopback by default (a browser on this
    # machine); "0.0.0.0" opens it to the network: then give it TLS (tls_cert_file) or reach
    # it through an SSH tunnel (README.md, "Safe by default").
    host: str = "127.0.0.1"
    # Its TCP port (0: a free one, printed at start).
    port: Annotated[int, Range(0, 65535, "TCP port")] = 8765
    # Each channel goes to the browser at most this often (by arrival at the bridge); events,
    # logs, the path, the seam and the calibration are never thinned (README.md).
    max_hz: Annotated[float, Range(0.1, 1000, "Hz")] = live(60.0, "each channel at most this often")
    # ...camera images at most this often: what a screen needs (a 640 x 480 mono8 image is
    # 300 kB; 10 Hz is 3 MB/s per browser).
    image_max_hz: Annotated[float, Range(0.1, 100, "Hz")] = live(10.0, "camera images at most this often")
    # Messages the server holds per browser (foxglove-sdk's backlog): a slow browser loses
    # its oldest messages, never the bus's.
    client_backlog: Annotated[int, Range(1, 100_000, "messages")] = 256
    # A file holding the operator's token: a service that needs the operator (reset_fault,
    # alter_on/alter_off) is done only for a request carrying it and the operator's name.
    # Empty: no browser may (those services refuse every request, saying why).
    operator_token_file: str = ""
    # Under mTLS: the certificate the bridge's parameter and command requests present (an
    # operator's, `humanpt pki issue NAME --role operator`); empty: [runtime] identity.
    operator_identity: str = ""
    # TLS for the WebSocket (wss://): a PEM certificate and its PKCS#8 key; both or neither.
    tls_cert_file: str = ""
    tls_key_file: str = ""
    # How long a parameter change or a command waits for the component's answer.
    request_timeout_s: Annotated[float, Range(0.1, 60, "s")] = 5.0
    # The server's name, as Foxglove shows it.
    name: str = "humanpt"

    def __post_init__(self) -> None:
        if not self.host:
            raise ValueError("foxglove_bridge.host must be an address to bind to, e.g. \"127.0.0.1\"")
        if bool(self.tls_cert_file) != bool(self.tls_key_file):
            raise ValueError("foxglove_bridge: tls_cert_file and tls_key_file go together (both or neither)")

    @property
    def loopback(self) -> bool:
        """Whether only this machine can connect."""
        return self.host in LOOPBACK or self.host.startswith("127.")
