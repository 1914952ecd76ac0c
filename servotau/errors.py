"""One exception hierarchy for servotau.

Every message says what was received and what was expected. Exceptions also inherit from the
matching built-in so that callers can catch either (``except ValueError`` keeps working).
"""


class ServotauError(Exception):
    """Base class of every servotau error."""


class ConfigError(ServotauError, ValueError):
    """A configuration file or value is invalid: the message names the file, the field and the
    expected value."""


class HalError(ServotauError, RuntimeError):
    """The hardware abstraction layer failed: lost robot, malformed frame, protocol mismatch."""


class HalTimeoutError(HalError, TimeoutError):
    """No frame from the robot within the allowed time."""


class EstimationError(ServotauError, ValueError):
    """Invalid input to an estimator (wrong shape, unknown joint, invalid filter settings)."""


class IdentificationError(ServotauError, ValueError):
    """Identification data or settings cannot give a meaningful fit (NaN, too few samples,
    no excitation)."""


class ControlError(ServotauError, ValueError):
    """Invalid controller settings or inputs."""


class SafetyTrip(ServotauError, RuntimeError):
    """A safety check tripped; the robot is held in position."""
