"""Exclusive control of a robot: one claim at a time, granted or refused by the robot (docs/protocol.md, "Claim").

A controller claims the robot at connect with a query on ``servotau/v1/<robot>/claim`` carrying its Zenoh
session id (zid) and who it is; the robot answers with a random token (granted) or with who holds the claim
(refused). Every command carries the token as its Zenoh attachment: a command without the current token
is rejected and counted. The claim ends when the controller releases it (at close), or when the robot sees
the claimer's own session go: its transport to the robot closes, or (through a router) the liveliness token
``.../alive/controller/<zid>`` that the claiming session declared vanishes.

This module is the wire format of the claim messages (JSON) and the robot's :class:`ClaimTable`; the Zenoh
side is in :mod:`servotau.hal.robot.server` (robot) and :mod:`servotau.hal.backends.zenoh` (controller).
"""

from __future__ import annotations

import hmac
import json
import os
import re
from collections.abc import Collection, Mapping
from dataclasses import asdict, dataclass

from ..errors import ClaimRefused, MalformedMessage

__all__ = ["Claimant", "ClaimTable", "claim_key", "claim_reply", "claim_request", "release_request",
           "token_key"]

TOKEN_BYTES = 16
_ZID = re.compile(r"^[0-9a-f]{1,32}$")
_MAX_REQUEST = 4096  # [bytes]


def claim_key(prefix: str) -> str:
    """The claim queryable of the robot whose keys start with ``prefix`` (``servotau/v1/<robot>``)."""
    return f"{prefix}/claim"


def token_key(alive_controller: str, zid: str) -> str:
    """The liveliness token a claiming session declares: ``<alive_controller>/<zid>``."""
    return f"{alive_controller}/{zid}"


@dataclass(frozen=True)
class Claimant:
    """Who claims: the session's zid (checked by the robot against its transports) and what the claimer says
    of itself (host, pid, user); ``identity``: the authenticated name the robot's link reports (the
    certificate's common name under mutual TLS), None without one."""

    zid: str
    host: str = "?"
    pid: int = 0
    user: str = "?"
    identity: str | None = None

    def describe(self) -> str:
        who = f"{self.user}@{self.host} pid {self.pid}, zenoh session {self.zid}"
        return f"{self.identity} ({who})" if self.identity else who


def claim_request(zid: str, host: str, pid: int, user: str) -> bytes:
    """The payload of a claim query."""
    return json.dumps({"op": "claim", "zid": zid, "host": host, "pid": pid, "user": user}).encode()


def release_request(token: bytes) -> bytes:
    """The payload of a release query (the token of the claim to release)."""
    return json.dumps({"op": "release", "token": token.hex()}).encode()


def _request(buf: bytes) -> dict:
    """A claim or release request, validated (MalformedMessage otherwise)."""
    if len(buf) > _MAX_REQUEST:
        raise MalformedMessage(f"claim request of {len(buf)} bytes: expected at most {_MAX_REQUEST}")
    try:
        req = json.loads(buf)
    except ValueError as exc:
        raise MalformedMessage(f"claim request: not JSON ({exc})") from None
    if not isinstance(req, dict) or req.get("op") not in ("claim", "release"):
        raise MalformedMessage('claim request: expected a JSON object with "op": "claim" or "release"')
    if req["op"] == "claim":
        if not isinstance(req.get("zid"), str) or not _ZID.match(req["zid"]):
            raise MalformedMessage(f"claim request zid = {req.get('zid')!r}: expected a zenoh id (hex)")
        if not isinstance(req.get("pid", 0), int) or not all(isinstance(req.get(k, ""), str) for k in ("host", "user")):
            raise MalformedMessage("claim request: expected host and user strings and an integer pid")
    elif not isinstance(req.get("token"), str) or len(req["token"]) != 2 * TOKEN_BYTES:
        raise MalformedMessage(f"release request: expected a token of {TOKEN_BYTES} bytes in hex")
    return req


def claim_reply(buf: bytes, robot: str) -> bytes:
    """The token of a granted claim; raises :class:`ClaimRefused` naming the holder and what to do."""
    try:
        r = json.loads(buf)
        if r.get("granted"):
            return bytes.fromhex(r["token"])
        if "error" in r:
            raise ClaimRefused(f'robot "{robot}" refused the claim: {r["error"]}')
        holder, since = Claimant(**r["holder"]), float(r["since_s"])
    except (ValueError, TypeError, KeyError, AttributeError) as exc:
        raise MalformedMessage(f'robot "{robot}" answered the claim with {buf[:200]!r}: {exc}') from None
    raise ClaimRefused(f'robot "{robot}" is already controlled by {holder.describe()} (claimed {since:.1f} s ago): '
                       "one controller at a time. Stop that controller (its claim ends with its session, "
                       "at once if it is killed), then connect again.")


class ClaimTable:
    """The robot's one claim (not thread-safe: the server calls it under its lock)."""

    def __init__(self):
        self.holder: Claimant | None = None
        self.token: bytes | None = None
        self.since = 0.0  # time.monotonic() [s] of the grant
        self.claims_refused = 0
        self.commands_not_claimer = 0  # commands without the holder's token (or with no claim held)

    def handle(self, buf: bytes, links: Mapping[str, str | None], tokens: Collection[str] | None,
               now: float) -> tuple[bytes, str | None]:
        """Answer a claim or release request. ``links``: the robot's open transports, zid -> authenticated
        identity (None if none); ``tokens``: the zids whose ``alive/controller/<zid>`` token is alive (None: do
        not check). A claim is granted only to a session the robot can watch (a transport or a token), so
        that every claim ends with the session behind it. Returns the reply and ``"granted"``, ``"released"``
        or None (nothing changed)."""
        try:
            req = _request(buf)
        except MalformedMessage as exc:
            self.claims_refused += 1
            return json.dumps({"granted": False, "error": str(exc)}).encode(), None
        if req["op"] == "release":
            if self.token is None or not hmac.compare_digest(bytes.fromhex(req["token"]), self.token):
                return json.dumps({"released": False, "error": "not the current claim's token"}).encode(), None
            self.release()
            return json.dumps({"released": True}).encode(), "released"
        zid = req["zid"]
        if self.holder is not None:  # the holder's token is never handed out again: a zid is no secret
            self.claims_refused += 1
            return json.dumps({"granted": False, "holder": asdict(self.holder),
                               "since_s": now - self.since}).encode(), None
        if self.holder is None and tokens is not None and zid not in links and zid not in tokens:
            self.claims_refused += 1
            return json.dumps({"granted": False, "error": f"session {zid} has neither a transport to the robot nor "
                               "its alive/controller/<zid> token: declare the token, then claim"}).encode(), None
        self.holder = Claimant(zid, req.get("host", "?"), req.get("pid", 0), req.get("user", "?"), links.get(zid))
        self.token, self.since = os.urandom(TOKEN_BYTES), now
        return json.dumps({"granted": True, "token": self.token.hex(), "holder": asdict(self.holder)}).encode(), \
            "granted"

    def release(self) -> Claimant | None:
        """End the claim; returns who held it."""
        holder, self.holder, self.token = self.holder, None, None
        return holder

    def session_gone(self, zid: str) -> bool:
        """The session ``zid`` is gone (transport closed or its token vanished): release if it held the claim."""
        if self.holder is None or self.holder.zid != zid:
            return False
        self.release()
        return True

    def allows(self, attachment: bytes | None) -> bool:
        """Whether a command with this attachment comes from the holder (counted otherwise)."""
        ok = self.token is not None and attachment is not None and hmac.compare_digest(attachment, self.token)
        if not ok:
            self.commands_not_claimer += 1
        return ok

    def status(self) -> dict:
        """JSON-ready: who holds the claim, since when, the refused claims and commands."""
        holder = self.holder
        return {"claim_holder": holder.describe() if holder else None,
                "claims_refused": self.claims_refused, "commands_not_claimer": self.commands_not_claimer}
