"""The whole rig: simulator, camera, controller and recorder in four processes over DDS.

Run by ``bfr rig`` (bfr_tools.rig) exactly as a user runs it, in lock-step so that the
outcome does not depend on the machine's load. The ball must keep rolling for at least 30 s
of simulated time, and the bag must hold the contract's topics at the contract's rates.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from bfr_model.io.bag import read_bag
from bfr_tools.rig import _parser, format_summary, run_rig

DURATION = 32.0

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, Path]:
    log_dir = tmp_path_factory.mktemp("rig")
    args = _parser().parse_args(["--lockstep", "--duration", str(DURATION),
                                 "--log-dir", str(log_dir), "--wall-timeout", "600"])
    summary, _, bag, wall = run_rig(args)
    assert summary is not None and bag is not None
    print(format_summary(summary, wall))
    return summary, bag


def test_ball_keeps_rolling_for_30_s(run: tuple[dict, Path]) -> None:
    s, _ = run
    assert s["duration"] == pytest.approx(DURATION, abs=1e-6)
    assert s["kept_rolling"], s
    assert s["rolling_time"] >= 30.0
    assert s["rolling_from"] < 0.1  # picked up within the first frames
    assert 2.2 < s["mean_phi_dot"] < 2.6  # the orbit's 2.4 rad/s
    assert s["rms_y"] < 0.02 and s["rms_z"] < 0.3
    assert s["final_mode"] == "ROLLING" and "BALL_LOST" not in s["modes"]
    assert s["max_abs_torque"] <= 0.1 + 1e-12
    assert s["camera_valid_fraction"] > 0.99
    assert s["camera_error_mm_median"] < 0.3


def test_bag_holds_the_contract_topics_at_their_rates(run: tuple[dict, Path]) -> None:
    s, bag = run
    assert s["complete"] and not s["warnings"]
    expected = {  # topic: (type, rate in simulated time [Hz])
        "/joint_states": ("sensor_msgs/msg/JointState", 600.0),  # 500 Hz + one per frame
        "/effort_controller/commands": ("std_msgs/msg/Float64MultiArray", 200.0),
        "/ball_observation": ("bfr_interfaces/msg/BallObservation", 200.0),
        "/controller_state": ("bfr_interfaces/msg/ControllerState", 200.0),
        "/sim_truth": ("bfr_interfaces/msg/SimTruth", 200.0),
        "/camera/camera_info": ("sensor_msgs/msg/CameraInfo", 200.0),
    }
    assert set(s["topics"]) == set(expected)
    for topic, (msgtype, rate) in expected.items():
        got = s["topics"][topic]
        assert got["type"] == msgtype
        assert got["rate"] == pytest.approx(rate, rel=0.01), topic
        assert got["count"] >= 0.99 * rate * DURATION, topic
    assert s["loop_rate"] == pytest.approx(200.0, rel=0.01)
    assert s["camera_rate"] == pytest.approx(200.0, rel=0.01)
    # readable by the project's reader (bfr diagnose) and by rosbags (what ros2 bag reads)
    rec = read_bag(bag)
    assert rec.has_truth and rec.duration == pytest.approx(DURATION, abs=0.01)
    assert rec.camera_fix_rate() == pytest.approx(200.0, rel=0.02)
    from rosbags.rosbag2 import Reader  # noqa: PLC0415

    with Reader(bag) as reader:
        assert {c.topic for c in reader.connections} == set(expected)
        assert reader.message_count == sum(d["count"] for d in s["topics"].values())


def test_rig_names_a_node_that_dies_early(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    from bfr_tools.rig import main  # noqa: PLC0415

    status = main(["--duration", "5", "--log-dir", str(tmp_path / "logs"), "--no-record",
                   "-p", "camera:ball.radius:=-1.0", "--wall-timeout", "120"])
    err = capsys.readouterr().err
    assert status == 1
    assert "camera node died (exit status 2)" in err
    assert "ball.radius: must be > 0 m, got -1.0" in err  # the end of its log
    assert (tmp_path / "logs" / "camera.log").exists()
