"""``humanpt pki``: the cell's certificate authority, its certificates and the router's
access control (:mod:`humanpt.runtime.security`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

DESCRIPTION = """\
The cell's PKI for [runtime] security = "mtls": a small certificate authority (CA) and one
certificate per component, tool, operator and router, its name the certificate's common
name. Keys are written 0600 in a 0700 directory; nothing is overwritten without --force.
The router enforces access control generated from the topic table for the certificates the
directory holds (`humanpt pki acl` prints it)."""

EPILOG = """\
examples:
  humanpt pki init --cell cell0                     the CA, in pki/ (or [runtime] pki of -c FILE)
  humanpt pki issue router --host 192.168.1.10      the router's, valid for that address too
  humanpt pki issue controller                      a component's (role component)
  humanpt pki issue tool                            what tools present by default (read-only)
  humanpt pki issue welder --role operator          a person's: may command (console --as welder)
  humanpt pki show                                  every certificate, its role and expiry
  humanpt pki acl                                   the router's access control (JSON5)
"""


HELP = "the cell's certificate authority and certificates (mTLS), and its access control"


def add_parser(sub, add_common) -> argparse.ArgumentParser:
    from humanpt.runtime.security import ROLES

    p = sub.add_parser("pki", help=HELP,
                       description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    psub = p.add_subparsers(dest="pki_verb", metavar="ACTION")

    def common(q):
        add_common(q)
        q.add_argument("--dir", metavar="DIR", help="the PKI directory (default [runtime] pki of --config, else pki/)")

    q = psub.add_parser("init", help="create the cell's CA")
    common(q)
    q.add_argument("--days", type=int, default=3650, help="validity of the CA, days (default 3650)")
    q.add_argument("--force", action="store_true", help="replace an existing CA (every certificate must be re-issued)")
    q = psub.add_parser("issue", help="issue a certificate NAME (its common name)")
    common(q)
    q.add_argument("name", help="a component's name, router, tool, or a person's/tool's name")
    q.add_argument("--role", choices=ROLES,
                   help="default: component for a component's name, router for 'router', else tool")
    q.add_argument("--days", type=int, default=365, help="validity, days (default 365; at most the CA's)")
    q.add_argument("--host", action="append", default=[], metavar="H",
                   help="a DNS name or IP address the certificate is valid for (repeatable; a router's always "
                   "includes localhost and 127.0.0.1): the names clients connect to")
    q.add_argument("--force", action="store_true", help="replace an existing certificate of that name")
    q = psub.add_parser("show", help="list the CA and the certificates: role, expiry, hosts, key permissions")
    common(q)
    q = psub.add_parser("acl", help="print the router's access control (JSON5) for review")
    common(q)
    return p


def _dir_and_cell(args) -> tuple[Path, str]:
    from humanpt.cli.commands import load_cfg
    from humanpt.runtime.security import pki_dir_of

    cfg = load_cfg(args)
    return (Path(args.dir) if args.dir else pki_dir_of(cfg.runtime)), cfg.runtime.cell


def run(args, ap: argparse.ArgumentParser) -> int:
    from humanpt.runtime import security

    if args.pki_verb is None:
        ap.parse_args(["pki", "--help"])
        return 2
    try:
        d, cell = _dir_and_cell(args)
        if args.pki_verb == "init":
            ca = security.init_ca(d, cell, args.days, force=args.force)
            print(f"humanpt pki: CA {ca.name!r} of cell {cell} in {d}/ ({security.CA_CERT}, {security.CA_KEY} 0600), "
                  f"valid until {ca.not_after:%Y-%m-%d} UTC")
            print("next: humanpt pki issue router --host <the router's address>; one per component; tool")
        elif args.pki_verb == "issue":
            c = security.issue(d, args.name, args.role, args.days, tuple(args.host), force=args.force)
            hosts = f", hosts {', '.join(c.hosts)}" if c.hosts else ""
            print(f"humanpt pki: issued {c.name} (role {c.role}{hosts}) in {d}/{c.name}.pem, key {c.name}.key "
                  f"(0600); valid until {c.not_after:%Y-%m-%d %H:%M} UTC")
        elif args.pki_verb == "show":
            from humanpt.cli.commands import load_cfg

            rt = load_cfg(args).runtime
            print(security.show(d, connect=rt.connect if rt.security == "mtls" or args.config else ()))
        elif args.pki_verb == "acl":
            sys.stdout.write(security.acl_json5(cell, security.identities(d)))
    except security.PkiError as e:
        print(f"humanpt pki {args.pki_verb}: error: {e}", file=sys.stderr)
        return 2
    return 0
