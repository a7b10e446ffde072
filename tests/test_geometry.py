"""Geometry of the contour and of the ball-centre curve, and the parameter file."""

from __future__ import annotations

import math

import numpy as np
import pytest
from bfr_model.geometry import OffsetCurve, contour_kernel
from bfr_model.params import (
    ParameterError,
    RigParams,
    load_params,
    params_from_dict,
    params_to_dict,
    params_to_ros_yaml,
)
from scipy.integrate import quad

NOMINAL = load_params()


@pytest.fixture(scope="module")
def curve() -> OffsetCurve:
    return OffsetCurve.from_params(NOMINAL.replace(**{
        "frame.contour.harmonic_orders": [3], "frame.contour.harmonic_cos": [1e-3],
        "frame.contour.harmonic_sin": [-5e-4], "track.bump_phi": [1.0],
        "track.bump_height": [3e-4], "track.bump_width": [0.08]}))


@pytest.mark.parametrize("orders", [[2.0, 1.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0], [2.0, 16.0, 9.0],
                                    [2.0, 2.5, 3.0]])
def test_contour_harmonics_and_their_derivatives_are_the_series(orders: list[float]) -> None:
    """rho and its four derivatives against the series written out term by term: the
    angle-addition recurrence (integer orders, in any order) and the direct path (a
    non-integer order) agree with ``d^n/dphi^n (a cos k phi + b sin k phi)`` to 1e-15 m."""
    rng = np.random.default_rng(3)
    o = np.array(orders)
    a, b = 1e-3 * rng.standard_normal(o.size), 1e-3 * rng.standard_normal(o.size)
    phi = np.linspace(-7.0, 7.0, 401)
    none = np.zeros(0)
    got = contour_kernel(phi, 0.1, o, a, b, none, none, none)
    want = [np.full_like(phi, 0.1), 0 * phi, 0 * phi, 0 * phi, 0 * phi]
    for k, ak, bk in zip(o, a, b, strict=True):
        for n in range(5):  # the n-th derivative advances the phase by n pi / 2
            want[n] += k ** n * (ak * np.cos(k * phi + n * np.pi / 2)
                                 + bk * np.sin(k * phi + n * np.pi / 2))
    for n in range(5):
        scale = max(float(np.max(o)) ** n, 1.0) * 1e-3
        np.testing.assert_allclose(got[n], want[n], rtol=0, atol=1e-12 * scale)
    scalar = contour_kernel(float(phi[7]), 0.1, o, a, b, none, none, none)
    np.testing.assert_allclose(scalar, [g[7] for g in got], rtol=1e-15, atol=1e-18)


@pytest.mark.parametrize("changes", [
    {"frame.contour.harmonic_orders": (3, 5), "frame.contour.harmonic_cos": (1e-3, 0.0),
     "frame.contour.harmonic_sin": (0.0, -2e-4)},
    {"frame.contour.harmonic_orders": (3, 5), "frame.contour.harmonic_cos": (1e-3, 0.0),
     "frame.contour.harmonic_sin": (0.0, 0.0)},                # an all-zero harmonic
    {"frame.contour.harmonic_orders": (3.0,), "frame.contour.harmonic_cos": (1e-3,),
     "frame.contour.harmonic_sin": (0,)},                      # a float order, an int
    {"track.bump_phi": (1.0, 2.0), "track.bump_height": (2e-4, 0.0),
     "track.bump_width": (0.1, 0.1)},                          # a bump of zero height
    {"frame.contour.harmonic_orders": [3], "frame.contour.harmonic_cos": [1e-3],
     "frame.contour.harmonic_sin": [0.0], "ball.mass": 3e-3},  # lists
])
def test_replace_with_tuples_is_the_parameter_file_s_replace(changes: dict) -> None:
    """Tuples set directly (the fits' fast path) give exactly what the parameter file's
    dictionary gives: zero entries dropped, orders integers, amplitudes floats."""
    got = NOMINAL.replace(**changes)
    d = params_to_dict(NOMINAL)
    for key, value in changes.items():
        node = d
        *groups, name = key.split(".")
        for g in groups:
            node = node[g]
        node[name] = list(value) if isinstance(value, tuple) else value
    want = params_from_dict(d)
    assert got == want
    c = got.frame.contour
    assert all(type(k) is int for k in c.harmonic_orders)
    assert all(type(v) is float for v in (*c.harmonic_cos, *c.harmonic_sin))
    assert 0.0 not in got.track.bump_height


def test_offset_curve_is_at_rolling_radius_along_the_normal(curve: OffsetCurve) -> None:
    phi = np.linspace(0, 2 * np.pi, 1001)
    d = curve.point(phi) - curve.contour_point(phi)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), curve.arrays.rolling_radius,
                               rtol=1e-13)
    n = curve.normal(phi)
    np.testing.assert_allclose(d, curve.arrays.rolling_radius * n, atol=1e-15)
    # the normal points outward (away from the axis, on this star-shaped frame)
    assert np.all(np.einsum("ij,ij->i", n, curve.contour_point(phi)) > 0)


def test_derivatives_match_finite_differences(curve: OffsetCurve) -> None:
    phi = np.linspace(0.05, 6.2, 37)
    _, p1, p2, p3 = curve.derivatives(phi)
    h = 1e-5
    pp, pm = curve.point(phi + h), curve.point(phi - h)
    np.testing.assert_allclose(p1, (pp - pm) / (2 * h), atol=1e-8)
    _, p1p, p2p, _ = curve.derivatives(phi + h)
    _, p1m, p2m, _ = curve.derivatives(phi - h)
    np.testing.assert_allclose(p2, (p1p - p1m) / (2 * h), atol=1e-7)
    np.testing.assert_allclose(p3, (p2p - p2m) / (2 * h), atol=2e-6)
    np.testing.assert_allclose(curve.speed(phi), np.linalg.norm(p1, axis=-1), rtol=1e-13)


def test_curvature_of_offset_curve(curve: OffsetCurve) -> None:
    """Offset of a curve by R: 1/kappa_p = 1/kappa_delta + R (same centres of curvature)."""
    phi = np.linspace(0, 2 * np.pi, 200)
    k_d = curve.contour_curvature(phi)
    k_p = curve.curvature(phi)
    np.testing.assert_allclose(1 / k_p, 1 / k_d + curve.arrays.rolling_radius, rtol=1e-10)


def test_waist_is_concave_wing_convex() -> None:
    c = OffsetCurve.from_params(NOMINAL)
    assert float(c.contour_curvature(0.0)) < 0.0  # waist: a valley
    assert float(c.contour_curvature(np.pi / 2)) > 0.0  # wing tip: a hill


def test_ball_angle_inverse(curve: OffsetCurve) -> None:
    phi = np.linspace(-7.0, 7.0, 301)
    psi = curve.ball_angle(phi)
    np.testing.assert_allclose(curve.phi_from_ball_angle(psi), phi, atol=1e-12)
    p = curve.point(phi)
    np.testing.assert_allclose(np.mod(psi, 2 * np.pi),
                               np.mod(np.arctan2(p[:, 0], p[:, 1]), 2 * np.pi), atol=1e-12)


def test_arc_length(curve: OffsetCurve) -> None:
    for a, b in [(0.0, 1.3), (0.4, 5.9)]:
        ref = quad(lambda x: float(curve.speed(x)), a, b, epsabs=1e-14, limit=200)[0]
        assert float(curve.arc_length(b) - curve.arc_length(a)) == pytest.approx(ref, rel=1e-10)
    per = curve.perimeter()
    assert float(curve.arc_length(2 * np.pi + 0.3) - curve.arc_length(0.3)) == pytest.approx(per)


def test_parameter_file_round_trip(tmp_path) -> None:  # noqa: ANN001
    p = NOMINAL.replace(**{"joint.coulomb_friction": 2e-3, "track.bump_phi": [0.5],
                           "track.bump_height": [1e-4], "track.bump_width": [0.1]})
    f = tmp_path / "p.yaml"
    f.write_text(params_to_ros_yaml(p, header="test"))
    assert load_params(f) == p
    assert load_params() == RigParams()  # the shipped file is the seed's nominal set


@pytest.mark.parametrize(("text", "needle"), [
    ("/**:\n  ros__parameters:\n    ball:\n      mass: -1.0\n", "ball.mass"),
    ("/**:\n  ros__parameters:\n    ball:\n      masss: 1.0\n", "masss"),
    ("/**:\n  ros__parameters:\n    ball:\n      plate_distance: 0.04\n", "plate_distance"),
    ("/**:\n  ros__parameters:\n    track:\n      bump_phi: [0.0]\n      bump_height: [0.003]\n"
     "      bump_width: [0.005]\n", "cusp"),
    ("just a string", "not a ROS 2 parameter file"),
    ("/**:\n  ros__parameters:\n    ball: {mass: .nan}\n", "finite"),
])
def test_bad_parameter_files_name_the_problem(tmp_path, text: str, needle: str) -> None:  # noqa: ANN001
    f = tmp_path / "bad.yaml"
    f.write_text(text)
    with pytest.raises(ParameterError, match=needle):
        load_params(f)


def test_missing_parameter_file_is_a_clear_error(tmp_path) -> None:  # noqa: ANN001
    with pytest.raises(ParameterError, match="cannot read"):
        load_params(tmp_path / "nope.yaml")


def test_rolling_radius_formula() -> None:
    b = NOMINAL.ball
    assert b.rolling_radius == pytest.approx(math.sqrt(0.0166**2 - 0.0255**2 / 4))


def test_speed_floor_is_a_lower_bound_that_finds_every_cusp() -> None:
    """The cheap check (params.check_rigid) against the dense grid on random curves.

    Curves near and past a cusp: random harmonics up to k = 8 and bumps whose sharpness
    ranges across the rolling radius. The floor never exceeds the minimum on a grid 64 times
    finer than its own (it is either a bound or the 8192-node grid's minimum, the check it
    replaced) and says "cusp" exactly when that 8192-node check does.
    """
    rng = np.random.default_rng(7)
    base = OffsetCurve.from_params(NOMINAL).arrays
    agree = 0
    for _ in range(300):
        k = rng.integers(0, 4)
        nb = rng.integers(0, 3)
        w = np.exp(rng.uniform(np.log(0.005), np.log(0.3), nb))
        h = rng.uniform(0.0, 1.5, nb) * w * w / base.rolling_radius  # around the cusp limit
        arrays = type(base)(
            rho0=base.rho0, orders=np.concatenate([base.orders, rng.integers(1, 9, k)]),
            ccos=np.concatenate([base.ccos, rng.normal(0.0, 3e-3, k)]),
            csin=np.concatenate([base.csin, rng.normal(0.0, 3e-3, k)]),
            bump_phi=rng.uniform(0.0, 2.0 * np.pi, nb), bump_h=h, bump_w=w,
            rolling_radius=base.rolling_radius)
        c = OffsetCurve(arrays)
        floor, dense, fine = c.speed_floor(), c.min_speed(), c.min_speed(1 << 16)
        assert floor <= dense + 1e-15
        assert floor <= fine or floor == dense
        assert (floor > 0.0) == (dense > 0.0), (floor, dense, w, h)
        agree += 1
    assert agree == 300
