"""What one servo (the first look, or a look of the search) knows of the wall ahead (pure: no clock, no I/O).

Each frame pair may read the wall's distance (with a gap in view, its mask kept out), a rough distance (without
one: a safety bound only), the wall's turn against the heading, and the far surface seen through the opening.
:class:`WallTrack` keeps them as places in the world along the initial heading, so that the distance ahead
follows the vehicle's own motion between readings, and answers two questions a step:

- the wall's distance: the median of the readings, each carried along a turned wall to where the vehicle is
  (:func:`companion.servo.wall_forward_at`), once ``min_measurements`` are there;
- how near the wall can be straight ahead (``ahead``): that distance, or the latest rough readings' median.

A look of the search also has a ``prior``: the nearest the wall's face can be, from earlier looks
(:func:`companion.search.search_wall_bound`).  A reading beyond it plus ``slack_m`` is not believed, and the
distance ahead is never taken beyond it, unless the look's own latest readings agree
(:func:`companion.servo.wall_readings_agree`): then they are the wall.  A look that sees no opening has only
rough readings; when its latest ones agree and lie within the ``ceiling`` (the furthest the wall can be there,
:func:`companion.search.search_wall_ceiling`) plus ``slack_m``, they too are the wall ahead (measured, hard world
seeds 67 and 68: bounds allowing for a 25° turn held looks 1.5 m across 0.2-2.5 m short of the wall, where they
saw nothing and refused).
"""

from __future__ import annotations

import numpy as np

from companion.servo import wall_forward_at, wall_readings_agree

READING_RANGE_M = (0.3, 10.0)   # a wall reading outside this is no reading
FAR_LIMIT_M = 20.0              # ... nor a far surface beyond this
TURN_WINDOW = 5                 # the wall's turn is the median of this many latest readings ...
TURN_MIN_READINGS = 3           # ... once there are this many


def wall_ahead_words(ahead: float, basis: str | None) -> str:
    """How near the wall is straight ahead, in words that say what the number rests on (``basis``, from
    :meth:`WallTrack.view`): a bound from earlier looks is the nearest the wall can be, not where it is
    (measured, hard world seed 89: a look refused "with the wall 0.13 m ahead" from 1.09 m before it)."""
    if basis == "bound":
        return f"possibly as near as {ahead:.2f} m ahead (the bound earlier looks put on it; not measured here)"
    if basis == "rough":
        return f"about {ahead:.2f} m ahead (read without an opening in view)"
    return f"{ahead:.2f} m ahead"


class WallTrack:
    def __init__(self, prior: float | None = None, min_measurements: int = 3, slack_m: float = 0.3,
                 agree_m: float = 0.05, agree_per_m: float = 0.05, ceiling: float | None = None) -> None:
        self.prior, self.ceiling = prior, ceiling
        self.min_measurements = min_measurements
        self.slack_m, self.agree_m, self.agree_per_m = slack_m, agree_m, agree_per_m
        self.readings: list[tuple[float, float]] = []  # (forward coordinate of the wall, across coordinate
                                                       # measured from), one per reading
        self.rough: list[tuple[float, float]] = []   # ... and from frames without a gap too
        self.far: list[float] = []     # ... and the far surface's, seen through the opening
        self.turns: list[float] = []   # how far the wall is turned against the heading (rad)

    def add(self, here: float, across: float, measured: float | None, rough: float | None,
            turn: float | None) -> float | None:
        """One frame pair's readings, taken from ``here`` (forward coordinate) of the wall at ``across`` (right;
        straight ahead of the pair's first frame, see :func:`companion.look.see_frame`): the wall's
        distance with a gap in view, the rough one read without a gap (None: the distance reading, if any, is the
        rough one too), and the wall's turn (each None when not read).  Returns the distance reading kept (None
        when out of range)."""
        lo, hi = READING_RANGE_M
        if measured is not None and not lo <= measured <= hi:
            measured = None
        if measured is not None:
            self.readings.append((here + measured, across))
        rough = measured if rough is None else rough
        if rough is not None and lo <= rough <= hi:
            self.rough.append((here + rough, across))
        if turn is not None:
            self.turns.append(turn)
        return measured

    def add_far(self, here: float, far: float, measured: float | None) -> None:
        """The far surface seen through the opening, ``far`` metres from ``here``: kept when beyond this pair's
        own wall reading ``measured`` (if any) and within :data:`FAR_LIMIT_M`."""
        if (measured is None or far > measured) and far <= FAR_LIMIT_M:
            self.far.append(here + far)

    @property
    def turn(self) -> float | None:
        """The wall's turn against the heading (rad), once enough readings agree on a median."""
        return float(np.median(self.turns[-TURN_WINDOW:])) if len(self.turns) >= TURN_MIN_READINGS else None

    def own(self, here: float, across: float) -> bool:
        """Whether a look's own latest readings agree (see the module docstring); always False without a prior."""
        return self.prior is not None and wall_readings_agree(
            self.readings, across, self.turn, here, self.min_measurements, self.agree_m, self.agree_per_m)

    def rough_own(self, here: float, across: float) -> float | None:
        """The wall's forward coordinate by a look's own latest rough readings, when they agree and lie within the
        ceiling plus ``slack_m`` (None otherwise, and without a prior and a ceiling)."""
        if self.prior is None or self.ceiling is None or not wall_readings_agree(
                self.rough, across, self.turn, here, self.min_measurements, self.agree_m, self.agree_per_m):
            return None
        forward = wall_forward_at(self.rough[-self.min_measurements:], across, self.turn)
        return forward if forward <= self.ceiling + self.slack_m else None

    def view(self, here: float, across: float) -> tuple[float | None, float | None, str | None]:
        """(distance, ahead, basis) from ``here`` at ``across``: the wall's distance (None before
        ``min_measurements`` readings), the nearest it can be straight ahead (None before any bound is known), and
        what ``ahead`` rests on: "measured" (the wall's distance), "rough" (the latest readings taken without a gap
        in view) or "bound" (the nearest the wall can be by earlier looks, not measured by this one); None with
        ``ahead``."""
        own = self.own(here, across)
        distance, basis = None, None
        if len(self.readings) >= self.min_measurements:
            distance, basis = wall_forward_at(self.readings, across, self.turn) - here, "measured"
            if self.prior is not None and not own and distance > self.prior - here + self.slack_m:
                # a look's reading well beyond where earlier looks put the wall is not the wall (measured: by a
                # wall's end, readings of 1.6-3.3 m for a wall 0.7 m ahead walked a vehicle into it)
                distance, basis = self.prior - here, "bound"
        ahead = distance
        if ahead is None and len(self.rough) >= self.min_measurements:
            ahead = float(np.median([forward for forward, _ in self.rough[-self.min_measurements:]])) - here
            basis = "rough"
        if self.prior is not None and not own:
            rough = self.rough_own(here, across)
            bound, bound_basis = (self.prior, "bound") if rough is None or self.prior >= rough else (rough, "rough")
            if ahead is None or bound - here < ahead:
                ahead, basis = bound - here, bound_basis
        return distance, ahead, basis

    def fallback_distance(self, here: float) -> float | None:
        """With fewer readings than ``min_measurements``, still better than nothing: their plain median."""
        return float(np.median([forward for forward, _ in self.readings])) - here if self.readings else None

    def far_distance(self, here: float) -> float | None:
        return float(np.median(self.far)) - here if self.far else None
