"""servotau certs: a development CA and TLS certificates for a robot host and a controller host.

Writes into DIR (keys with mode 0600)::

    ca.pem                        the development CA (every peer trusts it: root_ca_certificate)
    ca-key.pem                    the CA's key: keep it off both robots and controllers once done
    robot.pem, robot-key.pem      the robot process (CN servotau-robot, names of --robot-host)
    controller.pem, ...-key.pem   the controller (CN servotau-controller, names of --controller-host)
    <name>.pem, <name>-key.pem    one more identity per --client NAME (CN NAME), e.g. a viewer

and prints the config/hal.toml lines that use them (docs/real_backend.md, "Security"). Made with the
``openssl`` command line (no Python dependency); a development CA, not a production PKI.
"""

from __future__ import annotations

import argparse
import ipaddress
import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

from servotau.errors import ConfigError

ROBOT_CN = "servotau-robot"
CONTROLLER_CN = "servotau-controller"
DAYS = 825  # validity [days] (the longest many TLS stacks accept for a leaf certificate)
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,62}$")


@dataclass(frozen=True)
class Identity:
    """A certificate and its private key (PEM files)."""

    common_name: str
    certificate: Path
    private_key: Path


@dataclass(frozen=True)
class CertSet:
    """What :func:`make_certs` wrote."""

    ca: Path
    ca_key: Path
    robot: Identity
    controller: Identity
    clients: tuple[Identity, ...] = ()


def _san(hosts: list[str]) -> str:
    """The subjectAltName of ``hosts`` (IP addresses as IP:, names as DNS:)."""
    parts = []
    for h in hosts:
        try:
            parts.append(f"IP:{ipaddress.ip_address(h)}")
        except ValueError:
            if not re.fullmatch(r"[A-Za-z0-9*]([A-Za-z0-9.-]*[A-Za-z0-9])?", h):
                raise ConfigError(f"host {h!r}: expected a host name or an IP address") from None
            parts.append(f"DNS:{h}")
    return ",".join(parts)


def _openssl(*args: str) -> None:
    exe = shutil.which("openssl")
    if exe is None:
        raise ConfigError("servotau certs needs the openssl command line: install it (e.g. apt-get install openssl)")
    r = subprocess.run([exe, *args], capture_output=True, text=True)
    if r.returncode != 0:
        raise ConfigError(f"openssl {args[0]} failed: {r.stderr.strip()}")


def _key(path: Path) -> None:
    """A new P-256 private key at ``path`` (PKCS#8 PEM), mode 0600 from the start."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    os.close(fd)
    _openssl("genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256", "-out", str(path))
    os.chmod(path, 0o600)


def _leaf(d: Path, stem: str, cn: str, hosts: list[str], ca: Path, ca_key: Path, tmp: Path) -> Identity:
    key, cert, csr, ext = d / f"{stem}-key.pem", d / f"{stem}.pem", tmp / f"{stem}.csr", tmp / f"{stem}.ext"
    _key(key)
    _openssl("req", "-new", "-key", str(key), "-subj", f"/CN={cn}", "-out", str(csr))
    ext.write_text("basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature,keyAgreement\n"
                   "extendedKeyUsage=serverAuth,clientAuth\n" + (f"subjectAltName={_san(hosts)}\n" if hosts else ""))
    _openssl("x509", "-req", "-in", str(csr), "-CA", str(ca), "-CAkey", str(ca_key), "-set_serial",
             str(int.from_bytes(os.urandom(8), "big")), "-days", str(DAYS), "-sha256", "-extfile", str(ext),
             "-out", str(cert))
    return Identity(cn, cert, key)


def make_certs(directory: str | Path, *, robot_hosts: list[str], controller_hosts: list[str],
               clients: list[str] = (), force: bool = False) -> CertSet:
    """Write a development CA and the robot's, the controller's and each client's certificate into
    ``directory`` (created; existing files are kept unless ``force``)."""
    d = Path(directory)
    for name in clients:
        if not _NAME.match(name) or name in ("ca", "robot", "controller", ROBOT_CN, CONTROLLER_CN):
            raise ConfigError(f"--client {name!r}: expected a new name of letters, digits, '_', '.' or '-' (not the "
                              f"robot's or the controller's, {ROBOT_CN!r} and {CONTROLLER_CN!r}: a client certificate "
                              "of that name would carry their rights)")
    stems = ["ca", "robot", "controller", *clients]
    existing = [p for s in stems for p in (d / f"{s}.pem", d / f"{s}-key.pem") if p.exists()]
    if existing and not force:
        raise ConfigError(f"{existing[0]} exists: expected an empty directory (or --force to replace)")
    for hosts in (robot_hosts, controller_hosts):
        _san(hosts)  # checks the names before anything is written
    d.mkdir(parents=True, exist_ok=True)
    ca, ca_key = d / "ca.pem", d / "ca-key.pem"
    with tempfile.TemporaryDirectory() as tmp:
        _key(ca_key)
        ext = Path(tmp) / "ca.ext"
        ext.write_text("[v3]\nbasicConstraints=critical,CA:TRUE\nkeyUsage=critical,keyCertSign,cRLSign\n"
                       "subjectKeyIdentifier=hash\n")
        _openssl("req", "-x509", "-new", "-key", str(ca_key), "-subj", "/CN=servotau development CA", "-days",
                 str(DAYS), "-sha256", "-config", str(ext), "-extensions", "v3", "-out", str(ca))
        t = Path(tmp)
        robot = _leaf(d, "robot", ROBOT_CN, robot_hosts, ca, ca_key, t)
        controller = _leaf(d, "controller", CONTROLLER_CN, controller_hosts, ca, ca_key, t)
        extra = tuple(_leaf(d, n, n, [], ca, ca_key, t) for n in clients)
    return CertSet(ca, ca_key, robot, controller, extra)


def hal_toml(certs: CertSet, *, robot_host: str, port: int = 7447) -> str:
    """The config/hal.toml lines for both hosts (robot: [hal.server]; controller: [hal.zenoh])."""
    host = f"[{robot_host}]" if ":" in robot_host else robot_host
    r, c = certs.robot, certs.controller
    return f"""# --- robot host (servotau sim, or the real robot's bridge): config/hal.toml
[hal.server]
listen = ["tls/{host}:{port}"]

[hal.server.tls]
root_ca_certificate = "{certs.ca}"
certificate = "{r.certificate}"
private_key = "{r.private_key}"

[hal.server.access]  # who may do what on servotau/v1/<robot>/...: nobody else connects or reads
controller = {{ cert_common_names = ["{c.common_name}"], may = ["command", "claim", "operator", "observe"] }}

# --- controller host (servotau control): config/hal.toml
[hal.zenoh]
connect = ["tls/{host}:{port}"]

[hal.zenoh.tls]
root_ca_certificate = "{certs.ca}"
certificate = "{c.certificate}"
private_key = "{c.private_key}"
"""


def register(sub) -> None:
    p = sub.add_parser("certs", help="make a development CA and TLS certificates for a robot and a controller",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("directory", metavar="DIR", help="where to write the certificates and keys")
    p.add_argument("--robot-host", action="append", help="robot host name or IP (repeatable; default: localhost "
                   "and 127.0.0.1)")
    p.add_argument("--controller-host", action="append", help="controller host name or IP (repeatable; default: "
                   "localhost and 127.0.0.1)")
    p.add_argument("--client", action="append", default=[], metavar="NAME",
                   help="one more identity (certificate CN NAME), e.g. a viewer (repeatable)")
    p.add_argument("--port", type=int, default=7447, help="the robot's TLS port in the printed lines")
    p.add_argument("--force", action="store_true", help="replace existing files")
    p.set_defaults(func=main)


def main(args) -> int:
    default = ["localhost", "127.0.0.1"]
    robot_hosts = args.robot_host or default
    certs = make_certs(Path(args.directory).resolve(), robot_hosts=robot_hosts,
                       controller_hosts=args.controller_host or default, clients=args.client, force=args.force)
    print(f"servotau certs: wrote a development CA and {2 + len(certs.clients)} certificates to {certs.ca.parent} "
          f"(keys mode 0600; keep ca-key.pem off the robot and the controller)\n")
    print(hal_toml(certs, robot_host=robot_hosts[0], port=args.port))
    return 0
