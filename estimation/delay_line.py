"""A fixed integer delay for vectors, without allocation per sample (time alignment of filters)."""

from __future__ import annotations

import numpy as np

from servotau.errors import EstimationError


class DelayLine:
    """Delays a stream of (n,) vectors by ``delay`` samples; ``delay=0`` passes samples through.

    The first ``delay`` outputs are ``initial`` (zeros by default). :meth:`push` returns a view
    that the next push overwrites: copy it if it must be kept.

    Example::

        line = DelayLine(3, delay=2)
        line.push(x0); line.push(x1)
        line.push(x2)  # -> x0
    """

    def __init__(self, n: int, delay: int, initial: float = 0.0):
        if isinstance(delay, bool) or not isinstance(delay, int | np.integer) or delay < 0:
            raise EstimationError(f"delay={delay!r}: expected an integer >= 0 [samples]")
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
            raise EstimationError(f"n={n!r}: expected an integer >= 1")
        self.n = int(n)
        self.delay = int(delay)
        self._buffer = np.full((self.delay + 1, self.n), float(initial))
        self._rows = [self._buffer[i] for i in range(self.delay + 1)]
        self._head = 0

    def push(self, x: np.ndarray) -> np.ndarray:
        """Store sample ``x`` (n,) and return the sample pushed ``delay`` calls ago (a view)."""
        if self.delay == 0:
            row = self._rows[0]
            np.copyto(row, x)
            return row
        head = self._head + 1
        if head > self.delay:
            head = 0
        np.copyto(self._rows[head], x)
        self._head = head
        oldest = head + 1
        if oldest > self.delay:
            oldest = 0
        return self._rows[oldest]

    def reset(self, initial: float = 0.0) -> None:
        self._buffer.fill(initial)
        self._head = 0
