"""A float field of a frozen dataclass measured when first read, then kept.

:class:`~domplane_ros.core.verification.PlaneVerification` keeps its peak score this way: its
two probes are a fifth of a verification's time, and a warm pair's lock is ranked against
nothing, so the score is measured only where something reads it (docs/speed.md, round 12).

Nothing here imports ROS.
"""

from __future__ import annotations

from typing import Any, Callable


class Later:
    """A float measured when first read (the peak score), then kept; pickled as the float."""

    __slots__ = ('_measure', '_value')

    def __init__(self, measure: Callable[[], float]) -> None:
        """Keep the measurement, not run yet."""
        self._measure: Callable[[], float] | None = measure
        self._value = 0.0

    def value(self) -> float:
        """Return the value, measured on the first call (its working arrays then let go).

        Safe to call from several threads: the measurement is read once into a local, so a
        thread that finds it gone takes the value another thread stored (two threads reading
        at the same moment may both measure; the value is the same).
        """
        measure = self._measure
        if measure is not None:
            self._value = float(measure())
            self._measure = None
        return self._value

    def __reduce__(self) -> tuple[Any, tuple[float]]:
        """Pickle as the plain float."""
        return float, (self.value(),)


class MeasuredWhenRead:
    """A float field of a frozen dataclass that may hold a :class:`Later` (default 0.0).

    Reading the field (and so ``==``, ``hash``, ``repr``, ``dataclasses.replace`` and
    ``asdict``) measures it; the instance's ``__dict__`` holds the :class:`Later` until then.
    """

    def __set_name__(self, owner: type, name: str) -> None:
        # Kept under the field's own name: ``__dict__`` holds the fields, as without it.
        self._slot = name

    def __get__(self, instance: Any, owner: type | None = None) -> float:
        if instance is None:
            return 0.0  # the dataclass default
        try:
            value = instance.__dict__[self._slot]
        except KeyError:
            raise AttributeError(self._slot) from None
        return value.value() if isinstance(value, Later) else value

    def __set__(self, instance: Any, value: float | Later) -> None:
        instance.__dict__[self._slot] = value
