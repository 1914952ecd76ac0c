"""Errors of the hardware abstraction layer.

All derive from :class:`servotau.errors.HalError` (itself a ``RuntimeError``); each also inherits
from the matching built-in so that callers can catch either.
"""

from __future__ import annotations

from servotau.errors import HalError, HalTimeoutError


class MalformedMessage(HalError, ValueError):
    """A wire message failed validation (magic, type, lengths, finite values); never applied."""


class ProtocolVersionMismatch(MalformedMessage):
    """A wire message or a peer speaks another protocol version."""


class RobotLost(HalError, ConnectionError):
    """The robot process disappeared (its liveliness token vanished): the controller must stop."""


class ClaimRefused(HalError, PermissionError):
    """The robot is claimed by another controller (one at a time): the message names the holder."""


class ClaimUnseen(ClaimRefused):
    """The robot refused a claim because it could not see the claiming session yet (through a router, the session's
    liveliness token may arrive after the claim): worth a retry (hal/robot/claim.py ``claim_with_retry``)."""


class RobotServoOff(HalError):
    """The robot's servos are off (latched) at connect: an operator must reset it first."""


class EndOfLog(HalError, EOFError):
    """A replayed log has no more frames."""


__all__ = ["ClaimRefused", "ClaimUnseen", "EndOfLog", "HalError", "HalTimeoutError", "MalformedMessage",
           "ProtocolVersionMismatch", "RobotLost", "RobotServoOff"]
