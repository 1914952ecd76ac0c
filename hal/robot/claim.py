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
import time
from collections.abc import Callable, Collection, Mapping
from dataclasses import asdict, dataclass

from ..errors import ClaimRefused, ClaimUnseen, MalformedMessage

__all__ = ["CLAIM_ATTEMPTS", "Claimant", "ClaimTable", "claim_key", "claim_reply", "claim_request",
           "claim_with_retry", "release_request", "token_key"]

TOKEN_BYTES = 16
_ZID = re.compile(r"^[0-9a-f]{1,32}$")
_MAX_REQUEST = 4096  # [bytes]
CLAIM_ATTEMPTS = 5  # claims a controller sends before it gives up on a robot that cannot see its session yet


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
            raise (ClaimUnseen if r.get("retry") else ClaimRefused)(f'robot "{robot}" refused the claim: {r["error"]}')
        holder, since = Claimant(**r["holder"]), float(r["since_s"])
    except (ValueError, TypeError, KeyError, AttributeError) as exc:
        raise MalformedMessage(f'robot "{robot}" answered the claim with {buf[:200]!r}: {exc}') from None
    raise ClaimRefused(f'robot "{robot}" is already controlled by {holder.describe()} (claimed {since:.1f} s ago): '
                       "one controller at a time. Stop that controller (its claim ends with its session, "
                       "at once if it is killed), then connect again.")


def claim_with_retry(ask: Callable[[float], bytes | None], robot: str, timeout: float,
                     attempts: int = CLAIM_ATTEMPTS, delay: float = 0.02,
                     sleep: Callable[[float], None] = time.sleep) -> bytes | None:
    """Claim with ``ask(timeout [s])`` (sends the claim query: the reply's bytes, or None without an answer) and return
    the token, or None if the robot did not answer. A claim refused only because the robot could not see this
    session yet (:class:`ClaimUnseen`: through a router, the session's token can reach the robot after the claim) is
    sent again, at most ``attempts`` times in all, waiting ``delay`` [s], doubling, in between, within ``timeout``;
    then :class:`ClaimRefused` says so. Any other refusal is raised at once."""
    if attempts < 1:
        raise ValueError(f"claim_with_retry: attempts = {attempts!r}: expected at least 1")
    t0 = time.monotonic()
    deadline = t0 + timeout
    for i in range(attempts):
        reply = ask(max(deadline - time.monotonic(), 0.1))
        if reply is None:
            return None
        try:
            return claim_reply(reply, robot)
        except ClaimUnseen as exc:
            last = exc
        if i + 1 < attempts:
            sleep(max(min(delay * 2 ** i, deadline - time.monotonic()), 0.0))
    raise ClaimRefused(f"{last} ({attempts} claims over {time.monotonic() - t0:.2f} s). Through a router the robot "
                       "sees this session only by its alive/controller/<zid> token: check that the router forwards "
                       "liveliness tokens and that its access control lets this identity declare it (may = "
                       '["command"]).')


class ClaimTable:
    """The robot's one claim (not thread-safe: the server calls it under its lock)."""

    def __init__(self):
        self.holder: Claimant | None = None
        self.token: bytes | None = None
        self.since = 0.0  # time.monotonic() [s] of the grant
        self.claims_refused = 0

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
            return json.dumps({"granted": False, "retry": True,
                               "error": f"session {zid} has neither a transport to the robot nor "
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
        """Whether a command with this attachment comes from the holder (the firmware counts the others, rejected
        as ``not_claimer``: ``commands_not_claimer`` on ``.../status``)."""
        return self.token is not None and attachment is not None and hmac.compare_digest(attachment, self.token)

    def status(self) -> dict:
        """JSON-ready: who holds the claim and the refused claims."""
        holder = self.holder
        return {"claim_holder": holder.describe() if holder else None, "claims_refused": self.claims_refused}
