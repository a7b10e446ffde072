"""The project's messages (bfr_interfaces): definitions, units, and DDS between processes."""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
import rosutil

if TYPE_CHECKING:
    from conftest import NodeProcesses

MSG_DIR = rosutil.WORKSPACE / "src" / "bfr_interfaces" / "msg"
TYPES = ("BallObservation", "ControllerState", "SimTruth")
ECHO = Path(__file__).with_name("ros_echo.py")


def _msg_classes() -> dict[str, type]:
    import bfr_interfaces.msg as msgs  # noqa: PLC0415 - import errors belong to a test

    return {name: getattr(msgs, name) for name in TYPES}


def test_message_files_are_the_generated_types() -> None:
    assert sorted(p.stem for p in MSG_DIR.glob("*.msg")) == sorted(TYPES)
    assert set(_msg_classes()) == set(TYPES)


@pytest.mark.parametrize("name", TYPES)
def test_every_field_names_its_unit(name: str) -> None:
    """Each field line carries a trailing comment that starts with its unit in brackets."""
    missing = []
    for line in (MSG_DIR / f"{name}.msg").read_text().splitlines():
        code, _, comment = line.partition("#")
        fields = code.split()
        if len(fields) != 2 or "=" in code or fields[0] == "std_msgs/Header":
            continue  # blank, comment-only, constant, or the header (documented above it)
        if not re.match(r"\s*\[[^\]]+\]", comment):
            missing.append(line.strip())
    assert not missing, f"fields without a [unit] comment in {name}.msg: {missing}"


@pytest.mark.parametrize("name", TYPES)
def test_every_message_has_a_header(name: str) -> None:
    cls = _msg_classes()[name]
    assert cls.get_fields_and_field_types()["header"] == "std_msgs/Header"


def test_constants() -> None:
    classes = _msg_classes()
    obs, state = classes["BallObservation"], classes["ControllerState"]
    assert (obs.FOUND, obs.NOT_FOUND, obs.AMBIGUOUS, obs.INVALID_INPUT) == (0, 1, 2, 3)
    assert (state.WAITING, state.ROLLING, state.BALL_LOST, state.FAULT) == (0, 1, 2, 3)


def test_expected_fields() -> None:
    """The fields other packages rely on exist with the documented types."""
    classes = _msg_classes()
    expected = {
        "BallObservation": {
            "status": "uint8", "valid": "boolean", "confidence": "double", "u": "double",
            "v": "double", "radius_px": "double", "x": "double", "y": "double",
            "phi": "double", "theta_used": "double", "processing_time": "double",
        },
        "ControllerState": {
            "mode": "uint8", "theta": "double", "theta_dot": "double", "phi": "double",
            "phi_dot": "double", "y": "double", "y_dot": "double", "z": "double",
            "phase": "double", "torque": "double", "torque_unsaturated": "double",
            "saturated": "boolean", "ball_age": "double",
        },
        "SimTruth": {
            "theta": "double", "phi": "double", "theta_dot": "double", "phi_dot": "double",
            "ball_x": "double", "ball_y": "double", "ball_vx": "double", "ball_vy": "double",
            "ball_spin": "double", "ball_spin_rate": "double", "torque": "double",
            "kinetic": "double", "potential": "double", "energy": "double",
            "work_in": "double", "in_contact": "boolean", "normal_force": "double",
            "slip_velocity": "double",
        },
    }  # fmt: skip
    for name, fields in expected.items():
        actual = classes[name].get_fields_and_field_types()
        for field, kind in fields.items():
            assert actual.get(field) == kind, f"{name}.{field}: {actual.get(field)} != {kind}"


def test_fill_message_sets_every_field() -> None:
    """The test's sample values differ from the defaults in every field."""
    for name, cls in _msg_classes().items():
        differing = rosutil.message_diff(rosutil.fill_message(cls(), seed=3), cls())
        for field in cls.get_fields_and_field_types():
            assert any(d.startswith(f"{field}") for d in differing), f"{name}.{field} not set"
        assert rosutil.fill_message(cls(), seed=3) != rosutil.fill_message(cls(), seed=4)


def test_every_type_round_trips_between_processes(
    ros_harness: rosutil.RosHarness, node_processes: NodeProcesses
) -> None:
    """Publish each type to an echo node in another process and receive it back intact.

    This crosses the process boundary twice (test -> echo -> test) over DDS with the
    configured RMW, so serialization, type support and discovery are all exercised.
    """
    classes = _msg_classes()
    echo = node_processes.start_python(
        str(ECHO), args=[f"bfr_interfaces/msg/{name}" for name in TYPES]
    )
    node = ros_harness.node
    received: dict[str, list[object]] = {name: [] for name in TYPES}
    pubs = {}
    subs = []
    for name, cls in classes.items():
        subs.append(node.create_subscription(cls, f"echo_out/{name}", received[name].append, 10))
        pubs[name] = node.create_publisher(cls, f"echo_in/{name}", 10)
    for name in TYPES:
        ros_harness.wait_for_match(pubs[name], timeout=20.0)
    for sub in subs:
        ros_harness.wait_for_match(sub, timeout=20.0)
    assert echo.alive, echo.output()

    sent = {
        name: rosutil.fill_message(cls(), seed=i)
        for i, (name, cls) in enumerate(classes.items(), start=1)
    }
    # Re-send until the echo has answered: discovery can complete on one side first.
    for _ in range(40):
        for name in TYPES:
            if not received[name]:
                pubs[name].publish(sent[name])
        if ros_harness.spin_until(lambda: all(received.values()), timeout=0.5):
            break
    missing = [name for name in TYPES if not received[name]]
    assert not missing, f"no echo for {missing}; echo output:\n{echo.output()}"
    for name in TYPES:
        diff = rosutil.message_diff(received[name][0], sent[name])
        assert not diff, f"{name} changed in transit: {diff}"
        assert received[name][0] == sent[name]
    assert echo.stop() == 0, echo.output()
