"""A cell's PKI and its access control: who may say what on the bus (issue 19).

* **PKI.** One small certificate authority per cell (``humanpt pki init``) and one
  certificate per machine, component or person (``humanpt pki issue NAME``), its name the
  certificate's common name (CN) and its role (component, tool, operator, router) the
  organizational unit (OU).  A directory holds them: ``ca.pem``, ``ca.key`` and
  ``<name>.pem`` / ``<name>.key`` per identity; the directory is 0700, every private key
  0600.  EC P-256 keys, SHA-256 signatures.
* **mTLS.** :func:`tls_section` is what :func:`humanpt.runtime.bus.zenoh_config` puts under
  ``transport/link/tls`` when ``[runtime] security = "mtls"``: the cell's CA as the only
  root, the identity's own certificate both to listen and to connect, mutual
  authentication, names verified on connect, links closed when a certificate expires.
* **Access control.** :func:`access_control` builds the router's ``access_control``
  section from the topic table (:mod:`humanpt.schemas.topics`: who publishes each key),
  the registry (each component's input ports, the components it watches) and the
  identities the PKI issued: default deny; a component may put only on its own keys,
  subscribe only to what it reads, declare a liveliness token only under its own name and
  serve only its own parameter and rig queryables; a tool may subscribe and read
  liveliness and rigs; an operator also commands (``console/command``) and sets
  parameters.  The router enforces it on what enters it (ingress); what leaves it
  (egress) is allowed to every known identity, because it only ever carries what some
  ingress rule let in, to a subscriber or queryable an ingress rule let be declared.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import ipaddress
import json
import logging
import os
import re
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROLES = ("component", "tool", "operator", "router")
# A name is a CN and a file name: no slashes, no wildcards, nothing a key expression or a
# shell would read as syntax.
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,62}$")
RESERVED = ("ca",)
CA_CERT, CA_KEY = "ca.pem", "ca.key"
DEFAULT_DIR = "pki"
DEFAULT_TOOL_IDENTITY = "tool"

log = logging.getLogger("humanpt.security")

# Components of the twin that publish, in the twin, what a real part of the cell
# publishes (the topic table names the real part): the simulated camera renders the
# camera's images; the stand-in robot reports as the gateway would and gives the truth of
# the simulated robot.  They get those rights only when the PKI issued them a certificate
# (a real cell issues none: then only the gateway publishes robot state).
STANDS_IN: dict[str, tuple[str, ...]] = {
    "sim_camera": ("camera/image",),
    "standin_robot": ("robot_gateway/robot_state", "sim_robot/truth"),
}


class PkiError(ValueError):
    """A PKI problem (no CA, a bad name, a file that would be overwritten...), said plainly."""


@dataclass(frozen=True)
class CertInfo:
    """One issued certificate, as ``humanpt pki show`` lists it."""

    name: str  # the common name
    role: str  # component | tool | operator | router | ca
    not_before: dt.datetime  # UTC
    not_after: dt.datetime  # UTC
    hosts: tuple[str, ...]  # subject alternative names (DNS names and IP addresses)
    serial: int
    path: Path

    def expired(self, now: dt.datetime | None = None) -> bool:
        now = now or dt.datetime.now(dt.UTC)
        return not self.not_before <= now <= self.not_after


# -- files -------------------------------------------------------------------------------------
def _check_name(name: str) -> str:
    if not isinstance(name, str) or not NAME_RE.match(name) or name in RESERVED:
        raise PkiError(f"bad name {name!r}: a certificate's name is 1-63 letters, digits, '_', '-' or '.', "
                       f"starting with a letter or digit, and not {', '.join(RESERVED)}")
    return name


def _secure_dir(d: Path) -> Path:
    d.mkdir(parents=True, exist_ok=True)
    os.chmod(d, 0o700)
    return d


def _write(path: Path, data: bytes, mode: int) -> None:
    """Write ``data`` with ``mode`` from the start (a key is never readable by others, not
    even for an instant)."""
    if path.exists():
        path.unlink()
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    os.chmod(path, mode)  # whatever the umask


def _refuse_overwrite(paths: list[Path], force: bool) -> None:
    there = [str(p) for p in paths if p.exists()]
    if there and not force:
        raise PkiError(f"{', '.join(there)} already exist(s); --force replaces")


def _now(now: dt.datetime | None) -> dt.datetime:
    return (now or dt.datetime.now(dt.UTC)).replace(microsecond=0)


def _load_ca(pki_dir: Path):
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    cert_p, key_p = pki_dir / CA_CERT, pki_dir / CA_KEY
    if not cert_p.is_file():
        raise PkiError(f"no CA in {pki_dir} (no {CA_CERT}); run `humanpt pki init --dir {pki_dir}` first")
    if not key_p.is_file():
        raise PkiError(f"{pki_dir} has the CA's certificate but not its key ({CA_KEY}): certificates are "
                       f"issued where the CA's key is")
    cert = x509.load_pem_x509_certificate(cert_p.read_bytes())
    key = serialization.load_pem_private_key(key_p.read_bytes(), password=None)
    return cert, key


def _cell_of(ca_cert) -> str:
    from cryptography.x509.oid import NameOID

    orgs = ca_cert.subject.get_attributes_for_oid(NameOID.ORGANIZATION_NAME)
    return orgs[0].value.removeprefix("humanpt cell ") if orgs else ""


# -- CA and certificates ----------------------------------------------------------------------
def init_ca(pki_dir: str | Path, cell: str, days: int = 3650, *, force: bool = False,
            now: dt.datetime | None = None) -> CertInfo:
    """Create the cell's CA in ``pki_dir`` (made 0700): ``ca.pem`` and ``ca.key`` (0600),
    valid ``days`` days from ``now`` (UTC; default the clock).  PkiError when a CA is there
    and not ``force``."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    _check_name(cell)
    if not 1 <= days <= 36500:
        raise PkiError(f"--days {days}: a CA lives 1 to 36500 days")
    d = Path(pki_dir)
    _refuse_overwrite([d / CA_CERT, d / CA_KEY], force)
    _secure_dir(d)
    t0 = _now(now)
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, f"humanpt cell {cell}"),
                      x509.NameAttribute(NameOID.COMMON_NAME, f"humanpt {cell} CA")])
    ski = x509.SubjectKeyIdentifier.from_public_key(key.public_key())
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(t0 - dt.timedelta(minutes=5))  # a little clock skew between machines
            .not_valid_after(t0 + dt.timedelta(days=days))
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=False, content_commitment=False, key_encipherment=False,
                                         data_encipherment=False, key_agreement=False, key_cert_sign=True,
                                         crl_sign=True, encipher_only=False, decipher_only=False), critical=True)
            .add_extension(ski, critical=False)
            .sign(key, hashes.SHA256()))
    _write(d / CA_KEY, key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                         serialization.NoEncryption()), 0o600)
    _write(d / CA_CERT, cert.public_bytes(serialization.Encoding.PEM), 0o644)
    return cert_info(d / CA_CERT)


def default_role(name: str) -> str:
    """The role a name gets when none is given: a component's name -> component,
    ``router`` -> router, anything else -> tool."""
    from humanpt.runtime.registry import COMPONENTS

    if name == "router":
        return "router"
    return "component" if name in COMPONENTS else "tool"


def issue(pki_dir: str | Path, name: str, role: str | None = None, days: int = 365, hosts: tuple[str, ...] = (),
          *, force: bool = False, now: dt.datetime | None = None) -> CertInfo:
    """Issue ``<name>.pem`` and ``<name>.key`` (0600) in ``pki_dir``, signed by its CA: CN
    ``name``, OU ``role``, valid ``days`` days from ``now`` (UTC; default the clock; a
    certificate cannot outlive its CA).  ``hosts``: DNS names or IP addresses the
    certificate is valid for (subject alternative names); a router's always include
    ``localhost`` and ``127.0.0.1`` (``verify_name_on_connect`` checks the name a client
    connects to against them).  PkiError for a missing CA, a bad name or role, a component
    role for a name that is no component, or an existing certificate without ``force``."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    from humanpt.runtime.registry import COMPONENTS

    _check_name(name)
    role = role or default_role(name)
    if role not in ROLES:
        raise PkiError(f"role {role!r}: one of {', '.join(ROLES)}")
    if role == "component" and name not in COMPONENTS:
        raise PkiError(f"{name!r} is no component (components: {', '.join(sorted(COMPONENTS))}); "
                       f"a person or a tool gets --role operator or --role tool")
    if role != "component" and name in COMPONENTS:
        raise PkiError(f"{name!r} is a component's name: its certificate has the role component "
                       f"(give the {role} a name of its own, e.g. a person's)")
    if not 1 <= days <= 36500:
        raise PkiError(f"--days {days}: a certificate lives 1 to 36500 days")
    d = Path(pki_dir)
    ca_cert, ca_key = _load_ca(d)
    _refuse_overwrite([d / f"{name}.pem", d / f"{name}.key"], force)
    t0 = _now(now)
    not_after = min(t0 + dt.timedelta(days=days), ca_cert.not_valid_after_utc)
    sans: list[x509.GeneralName] = []
    all_hosts = list(hosts) + (["localhost", "127.0.0.1"] if role == "router" else [])
    for h in dict.fromkeys(all_hosts):
        try:
            sans.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            if not re.match(r"^[A-Za-z0-9]([A-Za-z0-9.-]{0,251}[A-Za-z0-9])?$", h):
                raise PkiError(f"--host {h!r} is neither an IP address nor a DNS name") from None
            sans.append(x509.DNSName(h))
    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, f"humanpt cell {_cell_of(ca_cert)}"),
                         x509.NameAttribute(NameOID.ORGANIZATIONAL_UNIT_NAME, role),
                         x509.NameAttribute(NameOID.COMMON_NAME, name)])
    b = (x509.CertificateBuilder().subject_name(subject).issuer_name(ca_cert.subject)
         .public_key(key.public_key()).serial_number(x509.random_serial_number())
         .not_valid_before(t0 - dt.timedelta(minutes=5)).not_valid_after(not_after)
         .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
         .add_extension(x509.KeyUsage(digital_signature=True, content_commitment=False, key_encipherment=False,
                                      data_encipherment=False, key_agreement=False, key_cert_sign=False,
                                      crl_sign=False, encipher_only=False, decipher_only=False), critical=True)
         # every identity both listens (router) and connects (everyone): both purposes
         .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]),
                        critical=False)
         .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
         .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False))
    if sans:
        b = b.add_extension(x509.SubjectAlternativeName(sans), critical=False)
    cert = b.sign(ca_key, hashes.SHA256())
    _write(d / f"{name}.key", key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                                serialization.NoEncryption()), 0o600)
    _write(d / f"{name}.pem", cert.public_bytes(serialization.Encoding.PEM), 0o644)
    return cert_info(d / f"{name}.pem")


def cert_info(path: str | Path) -> CertInfo:
    """What a certificate file says (name, role, validity, hosts)."""
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    p = Path(path)
    cert = x509.load_pem_x509_certificate(p.read_bytes())
    cns = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    ous = cert.subject.get_attributes_for_oid(NameOID.ORGANIZATIONAL_UNIT_NAME)
    try:
        ca = cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    except x509.ExtensionNotFound:
        ca = False
    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        hosts = tuple(str(v) for v in san.get_values_for_type(x509.DNSName)) + tuple(
            str(v) for v in san.get_values_for_type(x509.IPAddress))
    except x509.ExtensionNotFound:
        hosts = ()
    return CertInfo(name=str(cns[0].value) if cns else "", role="ca" if ca else (str(ous[0].value) if ous else ""),
                    not_before=cert.not_valid_before_utc, not_after=cert.not_valid_after_utc, hosts=hosts,
                    serial=cert.serial_number, path=p)


def identities(pki_dir: str | Path) -> list[CertInfo]:
    """Every certificate the directory holds, the CA first, then by name; PkiError when it
    holds no CA."""
    d = Path(pki_dir)
    if not (d / CA_CERT).is_file():
        raise PkiError(f"no CA in {d} (no {CA_CERT}); run `humanpt pki init --dir {d}` first")
    others = sorted(p for p in d.glob("*.pem") if p.name != CA_CERT)
    return [cert_info(d / CA_CERT)] + [cert_info(p) for p in others]


SOON_DAYS = 30  # a certificate that expires within this is worth a warning


def problems(pki_dir: str | Path, connect: tuple[str, ...] = (), now: dt.datetime | None = None) -> list[str]:
    """What would stop or soon stop a cell running on this PKI: expired or soon expiring
    certificates, a key readable by others, no router certificate, or a router endpoint
    in ``connect`` whose host the router's certificate does not name (clients verify it)."""
    d = Path(pki_dir)
    now = now or dt.datetime.now(dt.UTC)
    rows = identities(d)
    out = []
    for c in rows:
        key = d / (CA_KEY if c.role == "ca" else f"{c.name}.key")
        if c.expired(now):
            out.append(f"{c.name}: expired {c.not_after:%Y-%m-%d} (re-issue: humanpt pki issue {c.name} --force)")
        elif (c.not_after - now).days < SOON_DAYS:
            out.append(f"{c.name}: expires in {(c.not_after - now).days} days")
        if key.exists() and key.stat().st_mode & 0o077:
            out.append(f"{key}: readable by others (mode {_mode(key)}; chmod 600)")
    routers = [c for c in rows if c.role == "router"]
    if not routers:
        out.append("no router certificate (humanpt pki issue router --host <its address>)")
    for ep in connect:
        host = ep.split("/", 1)[-1].rsplit(":", 1)[0].strip("[]")
        if routers and all(host not in c.hosts for c in routers):
            out.append(f"the router's certificate does not name {host!r} (endpoint {ep}): clients will refuse it; "
                       f"humanpt pki issue router --host {host} --force")
    return out


def show(pki_dir: str | Path, now: dt.datetime | None = None, connect: tuple[str, ...] = ()) -> str:
    """``humanpt pki show``: the CA and each certificate, its role, expiry, hosts, and
    whether its key is there with safe permissions; then :func:`problems`."""
    d = Path(pki_dir)
    now = now or dt.datetime.now(dt.UTC)
    rows = identities(d)
    ca = rows[0]
    lines = [f"PKI {d.resolve()} (cell {_cell_of_path(d)}; directory mode {_mode(d)})",
             f"{'name':<22} {'role':<10} {'expires (UTC)':<20} {'left':>8}  key   hosts"]
    for c in rows:
        key = d / (CA_KEY if c is ca else f"{c.name}.key")
        key_s = _mode(key) if key.exists() else "none"
        left = (c.not_after - now).days
        state = "EXPIRED" if c.expired(now) else f"{left} d"
        lines.append(f"{c.name:<22} {c.role:<10} {c.not_after:%Y-%m-%d %H:%M:%S} {state:>8}  {key_s:<5} "
                     f"{', '.join(c.hosts)}")
    lines += [f"problem: {p}" for p in problems(d, connect, now)]
    return "\n".join(lines)


def _cell_of_path(d: Path) -> str:
    from cryptography import x509

    return _cell_of(x509.load_pem_x509_certificate((d / CA_CERT).read_bytes()))


def _mode(p: Path) -> str:
    return f"{p.stat().st_mode & 0o777:04o}"


# -- zenoh's TLS section ----------------------------------------------------------------------
def pki_dir_of(rt) -> Path:
    """The PKI directory ``[runtime] pki`` names (``pki/`` in the working directory when
    empty; a relative path in a config file is made relative to the file on loading)."""
    return Path(rt.pki or DEFAULT_DIR).expanduser()


def identity_files(pki_dir: str | Path, name: str) -> tuple[Path, Path, Path]:
    """(CA certificate, ``name``'s certificate, ``name``'s key) in ``pki_dir``; PkiError
    naming what is missing and how to make it."""
    d = Path(pki_dir)
    ca, cert, key = d / CA_CERT, d / f"{name}.pem", d / f"{name}.key"
    if not ca.is_file():
        raise PkiError(f'[runtime] security = "mtls" but there is no CA in {d} (no {CA_CERT}); '
                       f"run `humanpt pki init --dir {d}` (or set [runtime] pki)")
    for p in (cert, key):
        if not p.is_file():
            raise PkiError(f'[runtime] security = "mtls": no certificate for {name!r} in {d} (no {p.name}); '
                           f"run `humanpt pki issue {name} --dir {d}` on the machine holding the CA and copy "
                           f"{name}.pem, {name}.key and {CA_CERT} here")
    return ca, cert, key


def tls_section(pki_dir: str | Path, name: str) -> dict:
    """zenoh's ``transport/link/tls`` for identity ``name``: the cell's CA as the only
    root, ``name``'s certificate to listen and to connect, mutual authentication, the
    server's name verified on connect, links closed when a certificate expires."""
    ca, cert, key = identity_files(pki_dir, name)
    c = cert_info(cert)
    left = c.not_after - dt.datetime.now(dt.UTC)
    if left < dt.timedelta(days=SOON_DAYS):  # an expired one is refused by the peer: say why here
        log.warning("certificate %s %s", cert, "has EXPIRED" if left.total_seconds() < 0 else
                    f"expires in {left.days} days ({c.not_after:%Y-%m-%d} UTC)")
    return {"root_ca_certificate": str(ca.resolve()),
            "listen_certificate": str(cert.resolve()), "listen_private_key": str(key.resolve()),
            "connect_certificate": str(cert.resolve()), "connect_private_key": str(key.resolve()),
            "enable_mtls": True, "verify_name_on_connect": True, "close_link_on_expiration": True}


def tls_endpoint(ep: str) -> str:
    """``tcp/host:port`` as ``tls/host:port`` (one config serves both settings); a
    ``tls/`` endpoint as it is; anything else a ValueError (mTLS runs over TLS only)."""
    if ep.startswith("tls/"):
        return ep
    if ep.startswith("tcp/"):
        return "tls/" + ep[4:]
    raise ValueError(f'endpoint {ep!r}: with security = "mtls" endpoints are tcp/ (taken as tls/) or tls/')


# -- access control ---------------------------------------------------------------------------
ALL_MESSAGES = ("put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
                "liveliness_token", "liveliness_query", "declare_liveliness_subscriber")


def component_rights(name: str, cell: str) -> dict[str, list[str]]:
    """What component ``name`` may send into the router: message kind -> key expressions.
    From the topic table (the keys it publishes; ``STANDS_IN`` for the twin's stand-ins),
    its core's input ports (what it subscribes to) and ``watch`` (whose liveliness it
    follows); its own liveliness token and its parameter and rig queryables."""
    from humanpt.runtime.bus import liveliness_key, params_key, rig_key
    from humanpt.runtime.registry import core_class
    from humanpt.schemas import topics

    cls = core_class(name)
    own = [t.short for t in topics.TOPICS.values() if t.publisher == name] + list(STANDS_IN.get(name, ()))
    reads = [p.topic for p in cls.ports if p.on_bus]
    serve = [params_key(cell, name), rig_key(cell, name)]
    rights = {
        "put": [topics.TOPICS[s].key(cell) for s in dict.fromkeys(own)],
        "declare_subscriber": [topics.TOPICS[s].key(cell) for s in reads],
        "liveliness_token": [liveliness_key(cell, name)],
        "declare_liveliness_subscriber": [liveliness_key(cell, w) for w in cls.watch],
        # a liveliness subscriber with history asks for the tokens already there
        "liveliness_query": [liveliness_key(cell, w) for w in cls.watch],
        "declare_queryable": serve,
        "reply": serve,
    }
    return {k: v for k, v in rights.items() if v}


def tool_rights(cell: str, operator: bool) -> dict[str, list[str]]:
    """What a tool may send into the router: read everything of the cell (subscribe, who
    is alive, the rigs); an operator also commands (``console/command``) and reads and
    sets parameters (a parameter query may carry a change, so it is an operator's)."""
    from humanpt.runtime.bus import liveliness_key, params_key, rig_key
    from humanpt.schemas import topics

    everything = f"{topics.KEY_PREFIX}/{cell}/**"
    rights = {"declare_subscriber": [everything], "declare_liveliness_subscriber": [everything],
              "liveliness_query": [liveliness_key(cell, "*")], "query": [rig_key(cell, "*")]}
    if operator:
        rights["put"] = [topics.TOPICS["console/command"].key(cell)]
        rights["query"] = [rig_key(cell, "*"), params_key(cell, "*")]
    return rights


def access_control(cell: str, certs: list[CertInfo]) -> dict:
    """The router's ``access_control`` section for ``cell`` and the identities ``certs``
    (from :func:`identities`): default deny; per identity, ingress rights as
    :func:`component_rights` / :func:`tool_rights` say, by its certificate's CN; egress
    of everything to every known identity (it only carries what ingress let in).  The
    router itself needs no rights (a subject is a remote link).  An identity that is no
    component, tool or operator (a router, the CA) gets none."""
    rules: list[dict] = []
    subjects: list[dict] = []
    policies: list[dict] = []
    known: list[str] = []
    for c in certs:
        if c.role == "component":
            rights = component_rights(c.name, cell)
        elif c.role in ("tool", "operator"):
            rights = tool_rights(cell, operator=c.role == "operator")
        else:
            continue
        sid = f"cn:{c.name}"
        subjects.append({"id": sid, "cert_common_names": [c.name]})
        ids = []
        for msg, keys in rights.items():
            rid = f"{c.name}:{msg}"
            rules.append({"id": rid, "messages": [msg], "flows": ["ingress"], "permission": "allow",
                          "key_exprs": list(keys)})
            ids.append(rid)
        policies.append({"id": f"{c.role}:{c.name}", "rules": ids, "subjects": [sid]})
        known.append(sid)
    if known:
        rules.append({"id": "egress", "messages": list(ALL_MESSAGES), "flows": ["egress"], "permission": "allow",
                      "key_exprs": ["**"]})
        policies.append({"id": "egress", "rules": ["egress"], "subjects": known})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


def acl_json5(cell: str, certs: list[CertInfo]) -> str:
    """:func:`access_control` as the JSON5 a person reviews (``humanpt pki acl``): a rule,
    a subject, a policy a line, with a comment per identity; zenoh's config reads it as is
    (``zenoh.Config.from_json5``)."""
    acl = access_control(cell, certs)
    roles = {c.name: c.role for c in certs}
    out = [f"// access_control of cell {cell}'s router, generated from the topic table and the PKI's",
           f"// certificates ({', '.join(c.name for c in certs if c.role != 'ca')}); default deny: what no rule",
           "// allows is refused. Ingress: what an identity may send into the router; egress (to every",
           "// known identity) carries only what ingress let in."]
    stand = [c.name for c in certs if c.role == "component" and c.name in STANDS_IN]
    if stand:
        out.append(f"// twin stand-ins certified: {', '.join(stand)} may publish "
                   f"{', '.join(k for n in stand for k in STANDS_IN[n])} (a real cell issues them no certificate)")
    out += ["{", '  "access_control": {', f'    "enabled": {json.dumps(acl["enabled"])},',
            f'    "default_permission": {json.dumps(acl["default_permission"])},', '    "rules": [']
    last = None
    for r in acl["rules"]:
        who = r["id"].split(":")[0]
        if who != last:
            out.append(f"      // {who} ({roles.get(who, 'every known identity')})")
            last = who
        out.append(f"      {json.dumps(r)},")
    out.append("    ],")
    out.append('    "subjects": [')
    out += [f"      {json.dumps(x)}," for x in acl["subjects"]]
    out.append("    ],")
    out.append('    "policies": [')
    out += [f"      {json.dumps(x)}," for x in acl["policies"]]
    out += ["    ],", "  },", "}"]
    return "\n".join(out) + "\n"


# -- refused attempts -------------------------------------------------------------------------
# Zenoh 1.10 says that its access control refused a message only in a trace line
# (zenoh::net::routing::interceptor::access_control), written to stdout by its logger, e.g.
# "... on Interface(lo)+CertCommonName(perception)+Transport(Tls)+... is unauthorized to
# Put (ingress) on humanpt/cell0/controller/command".
ACL_LOG_TARGET = "zenoh::net::routing::interceptor::access_control"
_DENIED_RE = re.compile(r"is unauthorized to (\w+) \((\w+)\) on (\S+)")
_CN_RE = re.compile(r"CertCommonName\(([^)]*)\)")
_CACHING_RE = re.compile(r"caching permissions for `([^`]*)`")
_THREAD_RE = re.compile(r"ThreadId\((\d+)\)")
_RESULT_RE = re.compile(r"is (?:un)?authorized to .* on (\S+)")
_ZID_RE = re.compile(r"\b([0-9a-f]{32})\b")
_ANSI_RE = re.compile(r"\x1b\[[0-9;]*m")


@dataclass(frozen=True)
class Denial:
    """One message the router's access control refused."""

    cn: str  # the certificate's common name ("" when the link had none)
    message: str  # zenoh's name of the message: Put, DeclareSubscriber, LivelinessToken...
    flow: str  # ingress | egress
    key: str  # its key expression


def parse_denial(line: str) -> Denial | None:
    """The refusal a line of zenoh's access-control trace reports, or None."""
    line = _ANSI_RE.sub("", line)
    m = _DENIED_RE.search(line)
    if m is None:
        return None
    cn = _CN_RE.search(line)
    return Denial(cn=cn.group(1) if cn else "", message=m.group(1), flow=m.group(2), key=m.group(3))


class DenialWatch:
    """Reads zenoh's access-control trace in this process and calls ``on_denied`` for each
    refusal; every other line of stdout goes on to the real stdout, the allowed-message
    trace is dropped.  :meth:`start` must come before the process's first ``zenoh.open``
    (it sets zenoh's logging, once per process; ``RUST_LOG``, when set, wins) and replaces
    file descriptor 1 by a pipe; :meth:`stop` puts it back."""

    def __init__(self, on_denied: Callable[[Denial], None]):
        self.on_denied = on_denied
        self._orig_fd: int | None = None
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        import zenoh

        sys.stdout.flush()
        self._orig_fd = os.dup(1)
        r, w = os.pipe()
        os.dup2(w, 1)
        os.close(w)
        # Never let zenoh wait on this pipe: its routing threads write the trace, and a
        # flood of refused puts (a million a second) outruns any reader; a full pipe then
        # drops lines (the counts of a flood are low) instead of stopping the router.
        os.set_blocking(1, False)
        self._thread = threading.Thread(target=self._pump, args=(r,), name="acl-denials", daemon=True)
        self._thread.start()
        zenoh.init_log_from_env_or(f"warn,{ACL_LOG_TARGET}=trace")

    def _pump(self, fd: int) -> None:
        # When a key is first declared, zenoh fills its permission cache for every message
        # kind: "ACL (ingress): caching permissions for `K` ..." then one "is (un)authorized
        # to <kind>" line per kind, in that thread. Those are not attempts: a subscriber's
        # declaration would read as a refused Put, Query, Reply... (thread -> key being cached)
        caching: dict[str, str] = {}
        # A check from the permission cache ("Using cached result: <zid> is unauthorized...")
        # names the session, not its certificate: the certificate seen with that zid before.
        names: dict[str, str] = {}
        with os.fdopen(fd, "rb") as f:
            for raw in f:
                line = raw.decode(errors="replace")
                if ACL_LOG_TARGET in line:
                    plain = _ANSI_RE.sub("", line)
                    thread = _THREAD_RE.search(plain)
                    tid = thread.group(1) if thread else ""
                    header = _CACHING_RE.search(plain)
                    if header is not None:
                        caching[tid] = header.group(1)
                        continue
                    result = _RESULT_RE.search(plain)
                    if (result is not None and "Using cached result" not in plain
                            and caching.get(tid) == result.group(1)):
                        continue  # filling the cache, not a message
                    caching.pop(tid, None)
                d = parse_denial(line)
                if ACL_LOG_TARGET in line:
                    zid = _ZID_RE.search(_ANSI_RE.sub("", line))
                    if zid is not None:
                        if d is not None and d.cn:
                            names[zid.group(1)] = d.cn
                        elif d is not None and zid.group(1) in names:
                            d = dataclasses.replace(d, cn=names[zid.group(1)])
                        elif d is None and "CertCommonName(" in line:
                            cn = _CN_RE.search(_ANSI_RE.sub("", line))
                            if cn is not None:
                                names[zid.group(1)] = cn.group(1)
                if d is not None:
                    try:
                        self.on_denied(d)
                    except Exception:  # noqa: BLE001 - a failing report must not stop the pump
                        log.exception("reporting a refused attempt")
                elif ACL_LOG_TARGET not in line:
                    os.write(self._orig_fd, raw)

    def stop(self) -> None:
        """Stdout back to where it was (the pipe closes; the pump reads to its end)."""
        if self._orig_fd is None:
            return
        try:
            sys.stdout.flush()
        except BlockingIOError:  # the pipe is full (a flood): what is left of it is dropped
            pass
        os.dup2(self._orig_fd, 1)  # the pipe's last writer closes: the pump sees its end
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        os.close(self._orig_fd)
        self._orig_fd = None


class DenialReporter:
    """What the router does with a refused attempt: a log line and a warning event on
    ``router/events`` (once :meth:`attach` gave it the router's session), for the 1st,
    10th, 100th... refusal of each (identity, message, key), so a flood stays a trickle."""

    QUEUE = 256  # events waiting to be published; beyond: dropped (and counted)

    def __init__(self, cell: str):
        import queue

        self.cell = cell
        self.counts: dict[tuple[str, str, str], int] = {}
        self.dropped = 0  # events the queue had no room for
        self._session = None
        self._lock = threading.Lock()
        # Published from a thread of its own: the watch's pump must never wait on zenoh, whose
        # routing writes its trace into the pump's pipe (a put from the pump deadlocks once
        # the pipe is full: a flood of refused puts stopped the router).
        self._queue: queue.Queue = queue.Queue(self.QUEUE)
        self._thread: threading.Thread | None = None

    def attach(self, session) -> None:
        self._session = session
        self._thread = threading.Thread(target=self._publish, name="acl-reports", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop publishing (before the session closes)."""
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join(timeout=2.0)
            self._thread = None

    def _publish(self) -> None:
        from humanpt.runtime.bus import topic_encoding
        from humanpt.schemas import topics

        key = topics.TOPICS["router/events"].key(self.cell)
        while (ev := self._queue.get()) is not None:
            try:
                self._session.put(key, ev.SerializeToString(), encoding=topic_encoding("router/events"))
            except Exception:  # noqa: BLE001 - the session closing: nothing more to report to
                log.debug("router/events: could not publish", exc_info=True)

    def __call__(self, d: Denial) -> None:
        import time

        from humanpt.runtime.core import count_decades
        from humanpt.schemas import humanpt_pb2 as pb
        from humanpt.schemas.convert import header

        with self._lock:
            n = count_decades(self.counts, (d.cn, d.message, d.key))
        if n is None:
            return
        who = repr(d.cn) if d.cn else "a link without a certificate name"
        text = (f"router: access control refused {d.message} ({d.flow}) on {d.key} from {who} "
                f"({n} so far)")
        log.warning("%s", text)
        if self._thread is not None:
            import queue

            ev = pb.Event(header=header(time.time_ns()), severity=pb.SEVERITY_WARNING, source="router",
                          code="access_denied", text=text)
            try:
                self._queue.put_nowait(ev)
            except queue.Full:
                self.dropped += 1
