"""Zenoh's own security for the HAL, from validated settings: TLS (mutual), user/password authentication
and access control (docs/real_backend.md, "Security").

:class:`Security` holds the ``tls``, ``auth`` and ``access`` sub-tables of ``[hal.server]`` (robot side)
or ``[hal.zenoh]`` (controller side) and turns them into Zenoh config entries
(:meth:`Security.zenoh_settings`): nothing here encrypts or checks anything itself, Zenoh does. Every
file is checked before a session opens; an endpoint beyond loopback needs TLS (and, on the robot side,
access control) unless ``insecure_network = true`` says otherwise.
"""

from __future__ import annotations

import ipaddress
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from servotau.config import Section, check_settings, load_dataclass, setting
from servotau.errors import ConfigError

from ..errors import HalError

__all__ = ["CAPABILITIES", "AccessRole", "AuthConfig", "Security", "TlsConfig", "check_endpoints", "field_error",
           "is_loopback", "security_from_section"]

TLS_PROTOCOLS = ("tls", "quic")  # Zenoh link protocols that run over TLS
# What a role of [access] may do, and the keys under servotau/v1/<robot>/ each opens: (keys, messages the
# robot accepts from the peer (ingress), messages the robot sends it (egress)). Everything else is denied.
CAPABILITIES: dict[str, tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...]]] = {
    # put commands, hold the controller token, serve the controller's operator queryable
    "command": (("command", "alive/controller/**", "controller/**"),
                ("put", "liveliness_token", "declare_queryable", "reply"),
                ("declare_subscriber", "declare_liveliness_subscriber", "query", "liveliness_query")),
    "claim": (("claim",), ("query",), ("declare_queryable", "reply")),  # claim and release the robot
    "operator": (("operator", "controller/operator"), ("query",), ("declare_queryable", "reply")),  # reset/release
    "observe": (("frame", "truth", "info", "status", "alive/robot"),  # read frames, truth, info, status
                ("declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"),
                ("put", "reply", "liveliness_token", "declare_queryable")),
}


def is_loopback(endpoint: str) -> bool:
    """Whether a Zenoh endpoint ``proto/host:port`` stays on this machine (127.0.0.0/8, ::1, localhost)."""
    proto, _, rest = endpoint.partition("/")
    if proto.startswith("unixsock"):
        return True
    host = rest.split("#", 1)[0].rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _file_error(path: str) -> str | None:
    """Why ``path`` is not a readable file, or None."""
    if not os.path.exists(path):
        return "file not found"
    if not os.path.isfile(path):
        return "not a file"
    if not os.access(path, os.R_OK):
        return "file not readable"
    return None


def _check_file(where: str, path: str | None) -> None:
    if path:
        why = _file_error(path)
        if why:
            raise HalError(f"{where}: {why}: {path}")


@dataclass(frozen=True)
class TlsConfig:
    """``[...tls]``: mutual TLS with certificates from files (PEM; ``servotau certs`` makes a development set)."""

    root_ca_certificate: str = setting("")  # [path] CA that signed the peers' certificates
    certificate: str = setting("")  # [path] this side's certificate
    private_key: str = setting("")  # [path] this side's key
    mutual: bool = setting(True)  # both sides show a certificate (Zenoh's enable_mtls)
    verify_name: bool = setting(True)  # the robot's certificate must name the host connected to

    def __post_init__(self):
        check_settings(self, HalError)
        for name in ("root_ca_certificate", "certificate", "private_key"):
            if not getattr(self, name):
                raise HalError(f"TlsConfig.{name}: missing: expected the path of a PEM file")
            _check_file(f"TlsConfig.{name}", getattr(self, name))

    def zenoh(self) -> dict[str, Any]:
        """Zenoh's ``transport/link/tls`` table (the same identity to listen and to connect)."""
        return {"root_ca_certificate": self.root_ca_certificate, "enable_mtls": self.mutual,
                "listen_certificate": self.certificate, "listen_private_key": self.private_key,
                "connect_certificate": self.certificate, "connect_private_key": self.private_key,
                "verify_name_on_connect": self.verify_name}


@dataclass(frozen=True)
class AuthConfig:
    """``[...auth]``: Zenoh's user/password authentication. The robot side checks peers against
    ``dictionary_file`` (``user:password`` lines); the controller side shows ``user`` and the password
    in ``password_file`` (first line)."""

    user: str = setting("")
    password_file: str = setting("")  # [path]
    dictionary_file: str = setting("")  # [path]

    def __post_init__(self):
        check_settings(self, HalError)
        if bool(self.user) != bool(self.password_file):
            raise HalError("AuthConfig: user and password_file go together: expected both or neither")
        if not self.user and not self.dictionary_file:
            raise HalError("AuthConfig: expected user and password_file, or dictionary_file")
        _check_file("AuthConfig.password_file", self.password_file)
        _check_file("AuthConfig.dictionary_file", self.dictionary_file)

    def users(self) -> set[str]:
        """The user names of the dictionary file (empty without one)."""
        if not self.dictionary_file:
            return set()
        with open(self.dictionary_file) as f:
            return {line.split(":", 1)[0].strip() for line in f if ":" in line}

    def zenoh(self) -> dict[str, Any]:
        """Zenoh's ``transport/auth/usrpwd`` table."""
        out: dict[str, Any] = {}
        if self.user:
            with open(self.password_file) as f:
                out.update(user=self.user, password=f.readline().strip())
        if self.dictionary_file:
            out["dictionary_file"] = self.dictionary_file
        return out


@dataclass(frozen=True)
class AccessRole:
    """One role of ``[...access]``: who (a Zenoh subject) may do what (:data:`CAPABILITIES`). A peer matches
    when it matches every kind of name the role gives, one name of each kind (Zenoh's subjects: e.g. the
    controller's certificate common name *and* the interface ``eth1``)."""

    name: str
    may: tuple[str, ...]
    cert_common_names: tuple[str, ...] = ()
    usernames: tuple[str, ...] = ()
    interfaces: tuple[str, ...] = ()

    def __post_init__(self):
        unknown = [m for m in self.may if m not in CAPABILITIES]
        if unknown or not self.may:
            raise HalError(f"access role {self.name!r}: may = {list(self.may)}: expected a non-empty list among "
                           f"{list(CAPABILITIES)}")
        if not (self.cert_common_names or self.usernames or self.interfaces):
            raise HalError(f"access role {self.name!r}: expected cert_common_names, usernames or interfaces "
                           "(a role naming nobody would match every peer)")


@dataclass(frozen=True)
class Security:
    """TLS, authentication and access control of one side (all optional: none is the loopback default)."""

    tls: TlsConfig | None = None
    auth: AuthConfig | None = None
    access: tuple[AccessRole, ...] = ()  # empty: no access control (loopback only)
    insecure_network: bool = False  # allow plain endpoints beyond loopback (a trusted, isolated network)

    def __post_init__(self):
        if self.access and self.tls is None and self.auth is None and not any(r.interfaces for r in self.access):
            raise HalError("access roles need an identity to match: expected tls (cert_common_names) or auth "
                           "(usernames)")
        users = self.auth.users() if self.auth is not None else set()
        for role in self.access:
            if role.cert_common_names and (self.tls is None or not self.tls.mutual):
                raise HalError(f"access role {role.name!r}: cert_common_names need mutual tls (a [tls] table "
                               "with mutual = true): peers show no certificate otherwise")
            if role.usernames and not (self.auth and self.auth.dictionary_file):
                raise HalError(f"access role {role.name!r}: usernames need auth.dictionary_file")
            missing = sorted(set(role.usernames) - users)
            if missing:
                raise HalError(f"access role {role.name!r}: usernames {missing} are not in "
                               f"{self.auth.dictionary_file}: expected users of the dictionary file")

    def zenoh_settings(self, key_prefix: str | None = None) -> dict[str, Any]:
        """Zenoh config entries (path -> JSON value); ``key_prefix`` (``servotau/v1/<robot>``): the robot
        side's access-control rules on its keys."""
        out: dict[str, Any] = {}
        if self.tls is not None:
            out["transport/link/tls"] = self.tls.zenoh()
        if self.auth is not None:
            out["transport/auth/usrpwd"] = self.auth.zenoh()
        if self.access and key_prefix is not None:
            out["access_control"] = access_control(self.access, key_prefix)
        return out


def access_control(roles: Sequence[AccessRole], prefix: str) -> dict[str, Any]:
    """Zenoh's ``access_control`` table: everything denied but what each role may (:data:`CAPABILITIES`)."""
    rules, subjects, policies = [], [], []
    for cap, (keys, ingress, egress) in CAPABILITIES.items():
        exprs = [f"{prefix}/{k}" for k in keys]
        rules.append({"id": f"{cap}_in", "permission": "allow", "flows": ["ingress"], "messages": list(ingress),
                      "key_exprs": exprs})
        rules.append({"id": f"{cap}_out", "permission": "allow", "flows": ["egress"], "messages": list(egress),
                      "key_exprs": exprs})
    for role in roles:
        subject = {"id": role.name}
        for name in ("cert_common_names", "usernames", "interfaces"):
            if getattr(role, name):
                subject[name] = list(getattr(role, name))
        subjects.append(subject)
        policies.append({"id": f"{role.name}_may", "subjects": [role.name],
                         "rules": [f"{cap}_{d}" for cap in role.may for d in ("in", "out")]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


def check_endpoints(sec: Security, endpoints: Iterable[str], *, robot_side: bool) -> None:
    """Endpoints against the security settings: a tls/ endpoint needs ``tls``, ``tls`` needs a tls/
    endpoint, and (unless ``insecure_network``) an endpoint beyond loopback needs TLS and, robot side,
    access control. Raises HalError saying what is missing."""
    eps = list(endpoints)
    tls_eps = [e for e in eps if e.partition("/")[0] in TLS_PROTOCOLS]
    if tls_eps and sec.tls is None:
        raise HalError(f"endpoint {tls_eps[0]!r} needs tls settings: expected a tls table with "
                       "root_ca_certificate, certificate and private_key (servotau certs makes them)")
    if sec.tls is not None and not tls_eps:
        raise HalError(f"tls settings given but no tls/ endpoint among {eps}: expected e.g. 'tls/<host>:7447'")
    if sec.insecure_network:
        return
    for e in eps:
        if is_loopback(e):
            continue
        if e not in tls_eps:
            raise HalError(f"endpoint {e!r} leaves this machine without TLS: expected 'tls/...' with tls settings "
                           "(or insecure_network = true on a trusted, isolated network)")
        if robot_side and not sec.access:
            raise HalError(f"endpoint {e!r} leaves this machine without access control: expected an access table "
                           "naming who may command (or insecure_network = true on a trusted, isolated network)")


# -- config sections ---------------------------------------------------------------------------------

def field_error(s: Section, key: str, exc: Exception) -> ConfigError:
    """A ConfigError naming the file and the field ``key`` of ``s``, with the reason of ``exc``."""
    name = f"{s.prefix}.{key}" if s.prefix else key
    shown = f" = {s.data[key]!r}" if key in s and not isinstance(s.data[key], Mapping) else ""
    return ConfigError(f"{s.file}: field '{name}'{shown}: {exc}")


def _strings(s: Section, key: str) -> tuple[str, ...]:
    value = s.data.get(key, [])
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise s.error(key, value, "a list of non-empty strings")
    return tuple(value)


def _files(s: Section, keys: Iterable[str]) -> None:
    for key in keys:
        path = s.data.get(key)
        if isinstance(path, str) and path:
            why = _file_error(path)
            if why:
                raise s.error(key, path, f"a readable file ({why})")


def _role(s: Section, name: str) -> AccessRole:
    s.check_keys(["may", "cert_common_names", "usernames", "interfaces"])
    may = _strings(s, "may")
    unknown = [m for m in may if m not in CAPABILITIES]
    if unknown or not may:
        raise s.error("may", list(may), f"a non-empty list among {list(CAPABILITIES)}")
    who = {k: _strings(s, k) for k in ("cert_common_names", "usernames", "interfaces")}
    if not any(who.values()):
        raise s.missing("cert_common_names", "cert_common_names, usernames or interfaces (a role naming nobody "
                        "would match every peer)")
    return AccessRole(name, may, **who)


def security_from_section(s: Section, *, robot_side: bool) -> Security:
    """:class:`Security` from the ``tls``, ``auth``, ``access`` and ``insecure_network`` entries of ``s``
    (``[hal.server]`` or ``[hal.zenoh]``); every error names the file and the field."""
    tls = auth = None
    if "tls" in s:
        t = s.section("tls")
        _files(t, ("root_ca_certificate", "certificate", "private_key"))
        for key in ("root_ca_certificate", "certificate", "private_key"):
            if not t.data.get(key):
                raise t.missing(key, "the path of a PEM file")
        tls = load_dataclass(TlsConfig, t)
    if "auth" in s:
        a = s.section("auth")
        _files(a, ("password_file", "dictionary_file"))
        if not robot_side and "dictionary_file" in a:
            raise a.error("dictionary_file", a.data["dictionary_file"], "no dictionary on the controller side "
                          "(it shows user and password_file; the robot checks them)")
        auth = load_dataclass(AuthConfig, a)
    roles: list[AccessRole] = []
    if "access" in s:
        if not robot_side:
            raise s.error("access", dict(s.section("access").data), "no access table on the controller side "
                          "(the robot enforces who may do what)")
        acc = s.section("access")
        roles = [_role(acc.section(name), name) for name in acc.keys()]
        if not any("command" in r.may for r in roles):
            raise acc.error("*", dict(acc.data), 'a role that may "command" (else nobody can drive the robot)')
    insecure = s.bool("insecure_network", False)
    try:
        return Security(tls, auth, tuple(roles), insecure)
    except HalError as exc:
        raise field_error(s, "access", exc) from None


SECURITY_KEYS = ("tls", "auth", "access", "insecure_network")
"""The entries of ``[hal.server]`` / ``[hal.zenoh]`` that :func:`security_from_section` reads."""
