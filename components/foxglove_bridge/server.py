"""The bridge's live I/O: a Foxglove WebSocket server (foxglove-sdk) fed by the core's
``show:`` outputs, with the operator's parameters and services (the live shell's adapter).

Channels are the bus topics under their Zenoh keys (``humanpt/<cell>/camera/image``: the
names a merged run has, so ``docs/foxglove-layout.json`` fits live and recorded alike), each
with its protobuf schema (a FileDescriptorSet; Foxglove's own types as ``foxglove.*``).
Parameter changes and service calls go to the cell as ``humanpt console`` sends them (one
:class:`~humanpt.console.client.Console`: the params queryables, ``console/command`` and the
answering events), after :mod:`humanpt.foxglove_bridge.requests` checked them.  Nothing a
client sends raises out of a callback: a refused request gets its reason back (a service's
error reply; a parameter's status message, its value unchanged).
"""

from __future__ import annotations

import dataclasses
import io
import json
import logging
import queue
import threading
import time
from pathlib import Path

import foxglove
from foxglove import Channel, Context, Parameter, Schema
from foxglove.websocket import (
    Capability,
    MessageSchema,
    ServerListener,
    Service,
    ServiceSchema,
    StatusLevel,
)
from mcap_protobuf.schema import build_file_descriptor_set

from humanpt.foxglove_bridge.config import FoxgloveBridgeConfig
from humanpt.foxglove_bridge.core import BRIDGED_TOPICS
from humanpt.foxglove_bridge.requests import (
    PARAMETERS,
    SERVICES,
    RequestError,
    service_command,
    typed_value,
)
from humanpt.schemas import topics
from humanpt.schemas.topics import show_topic, shown_short

log = logging.getLogger("humanpt.foxglove_bridge")

__all__ = ["FoxgloveAdapter", "adapters", "schema_of"]

CAPABILITIES = [Capability.ClientPublish, Capability.Parameters, Capability.Services, Capability.Time]
TIME_PERIOD_NS = 100_000_000  # the server's time goes to the clients at most every 0.1 s


def schema_of(msg_type) -> Schema:
    """The Foxglove channel schema of a protobuf class: its full name and FileDescriptorSet."""
    return Schema(name=msg_type.DESCRIPTOR.full_name, encoding="protobuf",
                  data=build_file_descriptor_set(msg_type).SerializeToString())


def _read_text(path: str, what: str) -> str:
    try:
        text = Path(path).expanduser().read_text().strip()
    except OSError as e:
        raise ValueError(f"[foxglove_bridge] {what} {path}: {e.strerror or e}") from None
    if not text:
        raise ValueError(f"[foxglove_bridge] {what} {path} is empty")
    return text


class _Listener(ServerListener):
    def __init__(self, adapter: FoxgloveAdapter):
        self.adapter = adapter

    def on_client_advertise(self, client, channel):
        # ClientPublish is offered (Foxglove's publish panels need it), but nothing a browser
        # publishes reaches the bus: the operator acts through parameters and services only.
        log.info("foxglove_bridge: client %s advertised %r: what it publishes is dropped (use the services)",
                 client.id, channel.topic)

    def on_message_data(self, client, client_channel_id, data):
        self.adapter.dropped_client_messages += 1

    def on_get_parameters(self, client, param_names, request_id=None):
        try:
            return self.adapter.get_parameters(param_names)
        except Exception as e:  # noqa: BLE001 - a callback must answer, never raise
            log.exception("foxglove_bridge: getParameters")
            self.adapter.status(f"parameters could not be read: {e}", StatusLevel.Error)
            return []

    def on_set_parameters(self, client, parameters, request_id=None):
        try:
            return self.adapter.set_parameters(client.id, parameters)
        except Exception as e:  # noqa: BLE001
            log.exception("foxglove_bridge: setParameters")
            self.adapter.status(f"parameters could not be set: {e}", StatusLevel.Error)
            return []


class FoxgloveAdapter:
    """The bridge's live-shell adapter (module docstring)."""

    topics_out = tuple(show_topic(t) for t in BRIDGED_TOPICS)

    def __init__(self, config: FoxgloveBridgeConfig, config_file=None):
        self.config = config
        self.config_file = config_file
        self.cell = config_file.runtime.cell if config_file is not None else "cell0"
        self.server = None
        self.url = ""
        self.channels: dict[str, Channel] = {}
        self.context: Context | None = None
        self.console = None
        self.token: str | None = None
        self._lock = threading.Lock()  # one request on the console at a time
        self._time_ns = 0
        self.dropped_client_messages = 0  # what clients published (never forwarded)
        # Components whose parameters changed (their param_changed events): re-read and pushed
        # to the clients that subscribed to them, off the shell's thread.
        self._changed: queue.Queue = queue.Queue()
        self._pusher: threading.Thread | None = None

    # -- the live shell's calls ----------------------------------------------------------------
    def start(self, put) -> None:
        cfg = self.config
        try:
            if cfg.operator_token_file:
                self.token = _read_text(cfg.operator_token_file, "operator_token_file")
            tls = {}
            if cfg.tls_cert_file:
                tls = {"tls_cert": _read_text(cfg.tls_cert_file, "tls_cert_file").encode() + b"\n",
                       "tls_key": _read_text(cfg.tls_key_file, "tls_key_file").encode() + b"\n"}
            ctx = self.context = Context()  # kept: the server's channels live in it
            self.channels = {short: Channel(topics.TOPICS[short].key(self.cell), schema=schema_of(topics.TOPICS[short].type),
                                            message_encoding="protobuf", context=ctx)
                             for short in BRIDGED_TOPICS}
            self.server = foxglove.start_server(
                name=cfg.name, host=cfg.host, port=cfg.port, capabilities=CAPABILITIES,
                server_listener=_Listener(self), supported_encodings=["json"], services=self._services(),
                context=ctx, message_backlog_size=cfg.client_backlog, **tls)
        except Exception as e:  # noqa: BLE001 - a taken port, a bad certificate: say so, keep the cell
            # A view that cannot open must not take the run down (`humanpt up` stops every
            # component when one dies).
            log.error("foxglove_bridge: cannot serve Foxglove on %s:%s (%s): nothing will be shown; the run goes on",
                      cfg.host, cfg.port, e)
            return
        scheme = "wss" if cfg.tls_cert_file else "ws"
        host = f"[{cfg.host}]" if ":" in cfg.host else cfg.host
        self.url = f"{scheme}://{host}:{self.server.port}"
        where = "this machine only (loopback)" if cfg.loopback else (
            f"the network on {cfg.host}" + ("" if cfg.tls_cert_file else ", UNENCRYPTED: give it TLS or a tunnel"))
        # The address goes to stdout (what `humanpt up` and the demo show) and to the log.
        print(f"humanpt foxglove_bridge: Foxglove WebSocket server at {self.url} for {where} "
              f"(Foxglove: Open connection > Foxglove WebSocket)", flush=True)
        log.info("foxglove_bridge: serving %s", self.url)
        if self.config_file is not None:
            self._connect()
            self._pusher = threading.Thread(target=self._push_changes, name="foxglove_bridge-params", daemon=True)
            self._pusher.start()

    def _connect(self) -> None:
        """The console session the requests go through (under mTLS: operator_identity's)."""
        from humanpt.console.client import Console, ConsoleError

        cfgf = self.config_file
        if self.config.operator_identity:
            cfgf = dataclasses.replace(cfgf, runtime=dataclasses.replace(
                cfgf.runtime, identity=self.config.operator_identity))
        try:
            self.console = Console(cfgf, timeout_s=self.config.request_timeout_s, out=io.StringIO())
        except (ConsoleError, ValueError, OSError) as e:
            log.error("foxglove_bridge: no session for parameters and services (%s): they will refuse", e)

    def write(self, topic: str, msg) -> None:
        ch = self.channels.get(shown_short(topic))
        if ch is None or self.server is None:
            return
        ch.log(msg.SerializeToString())
        if getattr(msg, "code", None) == "param_changed" and msg.source in _PARAM_COMPONENTS:
            self._changed.put(msg.source)  # a change from anywhere: the console, humanpt param, a browser
        now = time.time_ns()
        if now - self._time_ns >= TIME_PERIOD_NS:
            self._time_ns = now
            self.server.broadcast_time(now)

    def _push_changes(self) -> None:
        """Re-read the live parameters of a component that changed one and push them to the
        clients subscribed to them (Foxglove's Parameters panel follows the console)."""
        while (comp := self._changed.get()) is not None:
            try:
                values = self._values([comp])
                if values and self.server is not None:
                    self.server.publish_parameter_values([_parameter(n, v) for n, v in values.items()])
            except Exception:  # noqa: BLE001 - a failed refresh is a log line, the next one tries again
                log.exception("foxglove_bridge: could not refresh %s's parameters", comp)

    def close(self) -> None:
        if self._pusher is not None:
            self._changed.put(None)
            self._pusher.join(timeout=2 * self.config.request_timeout_s)
            self._pusher = None
        if self.server is not None:
            self.server.stop()
            self.server = None
        if self.console is not None:
            self.console.close()
            self.console = None

    # -- parameters ------------------------------------------------------------------------------
    def status(self, text: str, level=StatusLevel.Warning, ident: str | None = None) -> None:
        log.log(logging.ERROR if level == StatusLevel.Error else logging.WARNING, "foxglove_bridge: %s", text)
        if self.server is not None:
            self.server.publish_status(text[:1000], level, ident)

    def _ask(self, component: str, sets: dict | None = None) -> dict | None:
        """A component's reply to a parameter request (None: nobody answered)."""
        from humanpt.console.client import ConsoleError

        if self.console is None:
            raise RequestError("the bridge has no session on the cell (see its log)")
        try:
            with self._lock:
                return self.console.params(component, sets, timeout_s=self.config.request_timeout_s)
        except ConsoleError:
            return None

    def _values(self, components) -> dict[str, object]:
        values = {}
        for comp in sorted(set(components)):
            body = self._ask(comp)
            params = (body or {}).get("params") or {}
            values.update({p.name: params[p.key] for p in PARAMETERS.values()
                           if p.component == comp and p.key in params})
        return values

    def get_parameters(self, names: list[str]) -> list[Parameter]:
        wanted = [n for n in names if n in PARAMETERS] if names else list(PARAMETERS)
        values = self._values(PARAMETERS[n].component for n in wanted)
        return [_parameter(n, values[n]) for n in wanted if n in values]

    def set_parameters(self, client_id: int, parameters: list[Parameter]) -> list[Parameter]:
        done = []
        for prm in parameters:
            name = prm.name
            try:
                p, value = typed_value(name, prm.get_value())
                body = self._ask(p.component, {p.key: value})
                if body is None:
                    raise RequestError(f"{name}: {p.component} did not answer in cell {self.cell} (is it running?)")
                result = next((r for r in body.get("results", []) if r.get("key") == p.key), None)
                if result is None or not result.get("ok"):
                    raise RequestError(f"{name} = {json.dumps(value)[:60]} refused: "
                                       f"{(result or {}).get('text') or 'no answer'}")
                log.info("foxglove_bridge: client %s set %s", client_id, (result or {}).get("text"))
                self.status(f"{name} set: {result.get('text')}", StatusLevel.Info, f"param:{name}")
            except RequestError as e:
                self.status(str(e), StatusLevel.Warning, f"param:{name}")
            if name in PARAMETERS:
                done.append(name)
        values = self._values(PARAMETERS[n].component for n in done)
        return [_parameter(n, values[n]) for n in done if n in values]

    # -- services --------------------------------------------------------------------------------
    def _services(self) -> list[Service]:
        out = []
        for svc in SERVICES.values():
            schema = Schema(name=f"humanpt.{svc.name}", encoding="jsonschema",
                            data=json.dumps(svc.schema()).encode())
            out.append(Service(svc.name, schema=ServiceSchema(
                name=f"humanpt.{svc.name}", request=MessageSchema(encoding="json", schema=schema)),
                handler=self._handler(svc.name)))
        return out

    def _handler(self, name: str):
        def handle(request) -> bytes:
            try:
                return self.call(name, request.payload, request.client_id)
            except RequestError as e:
                log.warning("foxglove_bridge: client %s: %s", request.client_id, e)
                raise
            except Exception as e:  # noqa: BLE001 - a bug must be an error reply, not a dead server
                log.exception("foxglove_bridge: service %s", name)
                raise RequestError(f"{name}: {type(e).__name__}: {e}") from None
        return handle

    def call(self, name: str, payload: bytes, client_id) -> bytes:
        """Do service ``name`` for a client: its JSON reply, or RequestError with the reason."""
        from humanpt.console.client import ConsoleError

        component, verb, args = service_command(name, bytes(payload), self.token, str(client_id))
        if self.console is None:
            raise RequestError(f"{name}: the bridge has no session on the cell (see its log)")
        with self._lock:
            self.console.out = io.StringIO()
            try:
                rc = self.console.command(verb, args, component=component)
            except ConsoleError as e:
                raise RequestError(f"{name}: {e}") from None
            answer = self.console.out.getvalue().strip()
        log.info("foxglove_bridge: client %s called %s: %s", client_id, name, answer)
        if rc != 0:
            raise RequestError(answer or f"{name} refused")
        return json.dumps({"ok": True, "service": name, "answer": answer}).encode()


_PARAM_COMPONENTS = frozenset(p.component for p in PARAMETERS.values())


def _parameter(name: str, value) -> Parameter:
    if isinstance(value, tuple):
        value = json.loads(json.dumps(value))  # nested tuples -> lists
    return Parameter(name, value=value)


def adapters(config: FoxgloveBridgeConfig, config_file=None) -> list:
    """Registry factory: the WebSocket server; ``config_file`` names the cell and the
    session the operator's requests go through."""
    return [FoxgloveAdapter(config, config_file=config_file)]
