"""Work spread over apex decisions: a computation advanced a fixed number of stride evaluations
at a time (the adaptive controller's identification and re-design, `bound_env.control.adaptive`).

A robot has one stride (about 0.39 s) between two apex decisions, and a decision must be short.
`Slices` runs a computation (a plain function, e.g. a fit and a design) in slices: each call of
``advance()`` lets it evaluate at most ``budget`` strides and then returns, with the
computation paused just before the batch of strides that would exceed the slice; the next
``advance()`` continues it there. Every stride map the computation uses is a `MeteredMap`,
whose ``run`` asks the slice for its rows first.

The computation runs on a helper thread, but never beside the caller: ``advance`` hands it the
turn and waits until it hands the turn back (paused or finished), so exactly one of the two
runs at any moment, in the same order every time; the results are those of the computation run
in one go, bit for bit (tested). A batch larger than the budget cannot be asked for (the
callers split theirs: `bound_env.control.identify.PlantIdentifier.chunk`); ``budget`` 0 runs
the whole computation in the first ``advance``.
"""

from __future__ import annotations

import threading

import numpy as np

HANDOFF_TIMEOUT = 600.0  # [s] a hand-off between the caller and the work takes far less


class Cancelled(Exception):
    """Raised inside a computation whose `Slices` was cancelled (it ends its thread)."""


class Slices:
    """``fn(slices)`` run ``budget`` stride evaluations per ``advance()`` (module docstring);
    ``fn`` wraps its stride maps with ``slices.meter(map)``. After the call that returns True,
    ``result`` holds its return value (or ``error`` its exception)."""

    def __init__(self, fn, budget: int):
        self.fn, self.budget = fn, int(budget)
        self.spent = 0  # stride evaluations in the current slice
        self.total = 0  # ... in all slices
        self.slices = 0
        self.done = False
        self.result = None
        self.error: BaseException | None = None
        self._turn = "caller"
        self._cancelled = False
        self._cv = threading.Condition()
        self._thread: threading.Thread | None = None

    def meter(self, stride_map) -> MeteredMap:
        return MeteredMap(stride_map, self)

    # -- the caller's side -------------------------------------------------------------------------
    def advance(self) -> bool:
        """Run the next slice (at most ``budget`` stride evaluations); True once finished."""
        if self.done:
            return True
        self.spent = 0
        self.slices += 1
        if self.budget <= 0:  # unbounded: in this call, on the caller's thread
            try:
                self.result = self.fn(self)
            except Exception as e:  # noqa: BLE001  (handed to the caller)
                self.error = e
            self.done = True
            return True
        with self._cv:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, daemon=True)
                self._turn = "work"
                self._thread.start()
            else:
                self._turn = "work"
                self._cv.notify_all()
            self._wait("caller")
        return self.done

    def cancel(self) -> None:
        """End a paused computation (its thread exits); nothing if it has not started or ended."""
        with self._cv:
            if self._thread is None or self.done:
                return
            self._cancelled = True
            self._turn = "work"
            self._cv.notify_all()
            self._wait("caller")

    def _wait(self, turn: str) -> None:
        """Wait (holding the condition) until it is ``turn``'s turn; a RuntimeError rather
        than a hang if the other side never hands it back."""
        if not self._cv.wait_for(lambda: self._turn == turn, timeout=HANDOFF_TIMEOUT):
            raise RuntimeError(f"anytime work: no hand-off to the {turn} in {HANDOFF_TIMEOUT} s")

    # -- the computation's side --------------------------------------------------------------------
    def take(self, n: int) -> None:
        """Before a batch of ``n`` strides: pause first if it would exceed the slice."""
        if self._cancelled:
            raise Cancelled
        if self.budget > 0:
            if n > self.budget:
                raise ValueError(f"a batch of {n} strides exceeds the budget of {self.budget}")
            if self.spent + n > self.budget:
                with self._cv:
                    self._turn = "caller"
                    self._cv.notify_all()
                    while self._turn != "work":
                        self._cv.wait()
                if self._cancelled:
                    raise Cancelled
        self.spent += n
        self.total += n

    def _run(self) -> None:
        with self._cv:
            while self._turn != "work":
                self._cv.wait()
        try:
            self.result = self.fn(self)
        except Cancelled:
            pass
        except Exception as e:  # noqa: BLE001  (handed to the caller)
            self.error = e
        with self._cv:
            self.done = True
            self._turn = "caller"
            self._cv.notify_all()


class MeteredMap:
    """A stride map whose ``run`` takes its rows from a `Slices` first; the rest is the map's."""

    def __init__(self, stride_map, slices: Slices):
        self._map, self._slices = stride_map, slices

    def run(self, Z, *args, **kwargs):
        self._slices.take(np.atleast_2d(np.asarray(Z)).shape[0])
        return self._map.run(Z, *args, **kwargs)

    def __getattr__(self, name):
        return getattr(self._map, name)
