"""The camera driver's period from received stamps (bfr_camera.stamps): the Rayleigh
statistic's closed form, the probe's jittered cameras, and 300 random drivers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from bfr_camera.stamps import _resultant, driver_period


def _stamps(rng: np.random.Generator, period: float, n: int, jitter: float,
            drop: float) -> np.ndarray:
    t = np.arange(n) * period + rng.uniform(0.0, 100.0)
    kept = t[rng.random(n) >= drop]
    return np.rint((kept + jitter * rng.standard_normal(kept.size)) * 1e9).astype(np.int64)


def test_the_resultant_at_the_period_is_the_closed_form() -> None:
    """``R(T) = exp(-2 pi^2 sigma^2 / T^2)`` for Gaussian jitter at the period, whatever
    is missed; ``R(T / 2)`` its fourth power; a period the stamps do not repeat with
    (1.5 T) near 0 (20,000 stamps: to 0.01)."""
    rng = np.random.default_rng(1)
    period, sigma = 0.005, 0.0008
    x = _stamps(rng, period, 40000, sigma, 0.5).astype(float) * 1e-9
    x -= x[0]
    r = _resultant(x, np.array([period, period / 2, 1.5 * period]))
    expected = math.exp(-2 * math.pi ** 2 * sigma ** 2 / period ** 2)
    assert r[0] == pytest.approx(expected, abs=0.01)
    assert r[1] == pytest.approx(expected ** 4, abs=0.01)
    assert r[2] < 0.02


@pytest.mark.parametrize(("jitter", "drop", "told"), [
    (0.0, 0.0, True), (1e-3, 0.0, True), (1e-3, 0.06, True), (1e-3, 0.5, True),
    (3e-4, 0.76, True), (0.0, 0.76, True), (2e-3, 0.06, False)])
def test_a_200_hz_driver_seen_through_jitter_and_losses(jitter: float, drop: float,
                                                       told: bool) -> None:
    """A 200 Hz driver whose stamps jitter (host stamps) and some of whose images are lost
    (a busy node, UDP fragments): its period within 0.05 % and the share received within
    2 points. A probe written apart had 1 ms of jitter with 94 % received read as a 3.10 ms
    period and 60 % (the gaps' 10th percentile), 2 ms as 1.60 ms and 30 %. At 2 ms (0.4 of
    a period) the stamps' phase shows no period: said, not guessed."""
    rng = np.random.default_rng(5)
    ns = _stamps(rng, 0.005, 6000, jitter, drop)
    period = driver_period(ns)
    if not told:
        assert period is None
        return
    assert period == pytest.approx(0.005, rel=5e-4)
    t = np.unique(ns)[-2000:]
    share = t.size / ((t[-1] - t[0]) / 1e9 / period + 1.0)
    assert share == pytest.approx(1.0 - drop, abs=0.02)


def test_random_drivers_are_never_given_a_wrong_period() -> None:
    """100 drivers: periods 3-10 ms, jitter 0-0.4 of a period (a third of them none),
    0-90 % of the images lost, 200-6000 frames. No period is off by more than 0.5 %; every
    driver with jitter under 0.15 of its period and under 75 % lost gets one (measured: 76
    told, 24 not, 0 wrong; all 44 of those; over 300 drivers 219, 81, 0 and all 132)."""
    rng = np.random.default_rng(2)
    told = wrong = easy = easy_told = 0
    for _ in range(100):
        period = rng.uniform(0.003, 0.01)
        jitter = rng.uniform(0.0, 0.4) * period * rng.choice([0, 1, 1])
        drop = rng.uniform(0.0, 0.9)
        p = driver_period(_stamps(rng, period, int(rng.integers(200, 6000)), jitter, drop))
        easy_case = jitter < 0.15 * period and drop < 0.75
        easy += easy_case
        if p is not None:
            told += 1
            easy_told += easy_case
            wrong += abs(p / period - 1.0) > 0.005
    assert wrong == 0 and easy_told == easy and told > 60, (told, wrong, easy, easy_told)
