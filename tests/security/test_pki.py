"""The cell's PKI (``humanpt pki``) and the access control it generates, without a network."""

from __future__ import annotations

import datetime as dt
import os
import stat

import pytest
import zenoh
from cryptography import x509
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from humanpt.runtime import security
from humanpt.runtime.config import ConfigError, RuntimeConfig, from_dict
from humanpt.runtime.registry import COMPONENTS


def mode(p) -> int:
    return stat.S_IMODE(os.stat(p).st_mode)


def test_init_and_issue_write_keys_only_the_owner_reads(tmp_path):
    d = tmp_path / "pki"
    old = os.umask(0)  # the most permissive umask: the modes must not come from it
    try:
        security.init_ca(d, "cell7")
        security.issue(d, "router", hosts=("192.168.1.10", "server.local"))
        security.issue(d, "controller")
    finally:
        os.umask(old)
    assert mode(d) == 0o700
    for key in ("ca.key", "router.key", "controller.key"):
        assert mode(d / key) == 0o600, key
    ca = x509.load_pem_x509_certificate((d / "ca.pem").read_bytes())
    cert = x509.load_pem_x509_certificate((d / "router.pem").read_bytes())
    # signed by the CA (cryptography checks the signature, not us)
    cert.verify_directly_issued_by(ca)
    assert cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == "router"
    assert cert.subject.get_attributes_for_oid(NameOID.ORGANIZATIONAL_UNIT_NAME)[0].value == "router"
    san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert set(map(str, san.get_values_for_type(x509.IPAddress))) == {"192.168.1.10", "127.0.0.1"}
    assert set(san.get_values_for_type(x509.DNSName)) == {"server.local", "localhost"}
    eku = cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
    assert ExtendedKeyUsageOID.CLIENT_AUTH in eku and ExtendedKeyUsageOID.SERVER_AUTH in eku
    assert isinstance(cert.public_key(), ec.EllipticCurvePublicKey)
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    assert not cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca


def test_expiry_is_days_from_now_and_never_past_the_ca(tmp_path):
    now = dt.datetime(2026, 1, 1, tzinfo=dt.UTC)
    security.init_ca(tmp_path, "c", days=100, now=now)
    c = security.issue(tmp_path, "controller", days=30, now=now)
    assert c.not_after == now + dt.timedelta(days=30)
    long = security.issue(tmp_path, "pose_filter", days=365, now=now)
    assert long.not_after == now + dt.timedelta(days=100)  # the CA's end
    assert c.expired(now + dt.timedelta(days=31)) and not c.expired(now + dt.timedelta(days=29))
    assert "EXPIRED" in security.show(tmp_path, now=now + dt.timedelta(days=31))


def test_refuses_to_overwrite_bad_names_and_a_missing_ca(tmp_path):
    with pytest.raises(security.PkiError, match="humanpt pki init"):
        security.issue(tmp_path, "controller")
    security.init_ca(tmp_path, "c")
    first = (tmp_path / "ca.pem").read_bytes()
    with pytest.raises(security.PkiError, match="--force"):
        security.init_ca(tmp_path, "c")
    assert (tmp_path / "ca.pem").read_bytes() == first
    security.issue(tmp_path, "controller")
    with pytest.raises(security.PkiError, match="--force"):
        security.issue(tmp_path, "controller")
    security.issue(tmp_path, "controller", force=True)
    for bad in ("", "a/b", "*", "ca", "../x", "x y", "-x"):
        with pytest.raises(security.PkiError, match="bad name"):
            security.issue(tmp_path, bad)
    with pytest.raises(security.PkiError, match="no component"):
        security.issue(tmp_path, "warp_drive", role="component")
    with pytest.raises(security.PkiError, match="component's name"):
        security.issue(tmp_path, "controller", role="operator")
    with pytest.raises(security.PkiError, match="neither an IP"):
        security.issue(tmp_path, "router", hosts=("bad host",))


def test_the_cli(tmp_path, cli_main, capsys):
    d = str(tmp_path / "p")

    def cli(*args: str) -> tuple[int, str, str]:
        rc = cli_main(["pki", *args])
        out, err = capsys.readouterr()
        return rc, out, err

    assert cli("init", "--dir", d, "--cell", "cellA")[0] == 0
    assert cli("issue", "controller", "--dir", d)[0] == 0
    assert cli("issue", "welder", "--role", "operator", "--dir", d)[0] == 0
    rc, _, err = cli("issue", "controller", "--dir", d)
    assert rc == 2 and "--force" in err
    rc, _, err = cli("show", "--dir", str(tmp_path / "none"))
    assert rc == 2 and "humanpt pki init" in err
    rc, out, _ = cli("show", "--dir", d)
    assert rc == 0
    lines = {ln.split()[0]: ln for ln in out.splitlines()[2:]}
    assert "component" in lines["controller"] and "operator" in lines["welder"]
    rc, out, _ = cli("acl", "--dir", d, "--cell", "cellA")
    assert rc == 0
    # zenoh itself reads what the user reviews
    conf = zenoh.Config.from_json5(out)
    assert '"default_permission":"deny"' in conf.get_json("access_control").replace(" ", "")


def rights_of(acl: dict, cn: str, message: str) -> set[str]:
    """Key expressions ``cn`` may send into the router as ``message`` (ingress)."""
    subjects = {s["id"] for s in acl["subjects"] if cn in s["cert_common_names"]}
    rules = {r for p in acl["policies"] if subjects & set(p["subjects"]) for r in p["rules"]}
    return {k for r in acl["rules"] if r["id"] in rules and message in r["messages"] and "ingress" in r["flows"]
            for k in r["key_exprs"]}


def test_the_access_control_says_what_issue_19_asks(tmp_path):
    """From the issue's words: only the controller puts commands, only the gateway
    publishes robot state, tools read only, operators command, tokens under one's own
    name; default deny."""
    security.init_ca(tmp_path, "c")
    for name in ("router", "tool", *COMPONENTS):
        security.issue(tmp_path, name)
    security.issue(tmp_path, "welder", role="operator")
    certs = security.identities(tmp_path)
    acl = security.access_control("c", [x for x in certs if x.name != "standin_robot"])
    assert acl["enabled"] and acl["default_permission"] == "deny"
    names = [x.name for x in certs if x.role in ("component", "tool", "operator") and x.name != "standin_robot"]

    def who(message: str, key: str) -> set[str]:
        return {n for n in names if key in rights_of(acl, n, message)}

    assert who("put", "humanpt/c/controller/command") == {"controller"}
    assert who("put", "humanpt/c/robot_gateway/robot_state") == {"robot_gateway"}
    assert who("put", "humanpt/c/console/command") == {"welder"}
    for n in names:
        assert rights_of(acl, n, "liveliness_token") <= {f"humanpt/c/{n}"}, n
        assert rights_of(acl, n, "delete") == set(), n
    assert rights_of(acl, "tool", "put") == set()
    assert rights_of(acl, "tool", "query") == {"humanpt/c/*/rig"}
    assert "humanpt/c/*/params" in rights_of(acl, "welder", "query")
    # the gateway reads the controller's commands and the console, and watches the controller
    assert rights_of(acl, "robot_gateway", "declare_subscriber") >= {"humanpt/c/controller/command"}
    assert rights_of(acl, "robot_gateway", "declare_liveliness_subscriber") == {"humanpt/c/controller"}
    assert rights_of(acl, "router", "put") == set()  # a router's certificate grants nothing
    # the twin's stand-in gets the gateway's robot state only when the PKI certified it
    with_standin = security.access_control("c", certs)
    assert "humanpt/c/robot_gateway/robot_state" in rights_of(with_standin, "standin_robot", "put")


def test_runtime_config_for_mtls(tmp_path):
    with pytest.raises(ConfigError, match="peer"):
        from_dict({"runtime": {"security": "mtls", "mode": "peer"}}, "t.toml")
    with pytest.raises(ConfigError, match="endpoint"):
        from_dict({"runtime": {"security": "mtls", "connect": ["udp/127.0.0.1:7447"]}}, "t.toml")
    with pytest.raises(ConfigError, match="security"):
        from_dict({"runtime": {"security": "tls"}}, "t.toml")
    f = tmp_path / "cell.toml"
    f.write_text('[runtime]\nsecurity = "mtls"\npki = "certs"\n')
    from humanpt.runtime.config import load

    assert load(f).runtime.pki == str(tmp_path / "certs")  # relative to the config file
    assert security.tls_endpoint("tcp/10.0.0.1:7447") == "tls/10.0.0.1:7447"
    assert RuntimeConfig().security == "none"


def test_show_names_what_would_stop_the_cell(tmp_path):
    now = dt.datetime(2026, 1, 1, tzinfo=dt.UTC)
    security.init_ca(tmp_path, "c", now=now)
    assert any("no router certificate" in p for p in security.problems(tmp_path, now=now))
    security.issue(tmp_path, "router", hosts=("10.0.0.1",), now=now)
    security.issue(tmp_path, "controller", days=10, now=now)
    assert security.problems(tmp_path, ("tls/10.0.0.1:7447", "tcp/127.0.0.1:7447"), now=now) == [
        "controller: expires in 10 days"]
    os.chmod(tmp_path / "controller.key", 0o644)
    found = security.problems(tmp_path, ("tcp/server.local:7447",), now=now + dt.timedelta(days=11))
    assert any("controller: expired" in p for p in found)
    assert any("controller.key: readable by others" in p for p in found)
    assert any("does not name 'server.local'" in p for p in found)
