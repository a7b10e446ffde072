"""ROS 2 bag I/O: round trips, custom types, remapping, truncation, killed writers."""

from __future__ import annotations

import os
import select
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from bfr_model.io.bag import (
    DEFAULT_TOPICS,
    BagError,
    BagWarning,
    BagWriter,
    find_msg_dirs,
    make_typestore,
    read_bag,
    read_bag_messages,
    write_recording_bag,
)
from bfr_model.recording import Recording
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

REPO = Path(__file__).resolve().parents[1]


def rig_like(n: int = 400) -> Recording:
    t = 4.0 + np.arange(n) * 1.1e-3
    theta = 0.3 * np.sin(3 * t)
    held = (np.arange(n) // 6) * 6
    valid = np.ones(n, bool)
    valid[100:140] = False
    bx, by = 0.01 * np.cos(t[held]), 0.085 + 0.001 * np.sin(t[held])
    return Recording(t=t, theta=theta, theta_dot=0.9 * np.cos(3 * t),
                     torque=np.clip(np.sin(7 * t) / 5, -0.1, 0.1), ball_x=bx, ball_y=by,
                     ball_valid=valid, phi=theta[held] + np.arctan2(bx, by),
                     phi_dot=np.where(valid, 0.5, np.nan),
                     extra={"phi_rig": np.linspace(0, 1, n)},
                     meta={"source": "x.txt", "source_kind": "ntnu_rig_log",
                           "rig_conventions": {"theta_sign": 1}})


def sim_like(n: int = 300) -> Recording:
    t = np.arange(n) * 1e-3
    theta, phi_c = 0.5 * t, 0.1 + 2.0 * t
    ang = phi_c - theta + 0.005
    ball = 0.1 * np.c_[np.sin(ang), np.cos(ang)]
    x = np.c_[theta, phi_c, np.full(n, 0.5), np.full(n, 2.0), np.zeros(n), np.zeros(n)]
    return Recording.from_sim(SimpleNamespace(t=t, x=x, u=np.full(n, 0.003), ball=ball,
                                              kinetic=np.full(n, 1e-3),
                                              potential=np.linspace(0, 1e-3, n), info={}))


def _differences(rec: Recording, back: Recording, **tol: float) -> list[str]:
    """``rec.differences(back)`` but for the fixes' stamps the reader adds: without stamps
    of their own, the fixes are stamped at the sample where they appear (their arrival)."""
    stamp = back.extra.pop("ball_stamp")
    new = rec.new_fix_mask()
    np.testing.assert_allclose(back.fix_times(), rec.t[new], atol=1e-9)
    assert np.all(stamp[rec.ball_valid] <= rec.t[rec.ball_valid] + 1e-9)
    return rec.differences(back, **tol)


def test_ball_observations_placed_at_their_header_stamps(tmp_path: Path) -> None:
    """Fixes stamped at exposure (before they arrive): the reader places them at the stamp
    and keeps it as the fix's time; a fix without a stamp is placed at its receive time."""
    rec = rig_like()
    stamps = rec.t - 0.004  # exposures 4 ms before the samples where the fixes appear
    new = rec.new_fix_mask()
    held = np.maximum.accumulate(np.where(new, np.arange(rec.n), 0))
    rec.extra["ball_stamp"] = np.where(rec.ball_valid, stamps[held], np.nan)
    write_recording_bag(tmp_path / "bag", rec)
    back = read_bag(tmp_path / "bag")
    np.testing.assert_allclose(back.fix_times(), stamps[new], atol=1e-9)
    assert any("header stamp" in n for n in back.meta["notes"])
    assert not any("no header stamp" in n for n in back.meta["notes"])


def test_custom_msg_dirs_found() -> None:
    """The installed share/bfr_interfaces/msg (or the source tree's) holds the definitions."""
    dirs = find_msg_dirs()
    assert dirs and all((d / "BallObservation.msg").is_file() for d in dirs)
    store = make_typestore()
    for name in ("BallObservation", "ControllerState", "SimTruth"):
        assert f"bfr_interfaces/msg/{name}" in store.types


def test_round_trip_rig_like(tmp_path: Path) -> None:
    rec = rig_like()
    write_recording_bag(tmp_path / "bag", rec)
    assert (tmp_path / "bag" / "metadata.yaml").exists()
    assert (tmp_path / "bag" / "bag.mcap").exists()
    back = read_bag(tmp_path / "bag")
    assert _differences(rec, back, rtol=0, atol=1e-9) == []
    assert back.meta["rig_conventions"] == {"theta_sign": 1}
    assert back.meta["original_source"] == "x.txt"
    assert back.meta["bag_complete"] is True
    assert set(back.meta["bag_topics"]) == {"joint_states", "command", "ball", "controller"}


def test_round_trip_simulation_with_truth(tmp_path: Path) -> None:
    rec = sim_like()
    write_recording_bag(tmp_path / "bag", rec)
    back = read_bag(tmp_path / "bag")
    assert _differences(rec, back, rtol=0, atol=1e-9) == []
    assert back.has_truth and "truth" in back.meta["bag_topics"]


def test_remapped_topics_and_slashes(tmp_path: Path) -> None:
    rec = sim_like(50)
    write_recording_bag(tmp_path / "bag", rec, topics={"joint_states": "rig/joint_states",
                                                      "sim_truth": "gt"}, leading_slash=False)
    with pytest.raises(BagError, match=r"no messages on 'other/joint_states'.*'rig/joint_states'"):
        read_bag(tmp_path / "bag", topic_map={"joint_states": "other/joint_states"})
    back = read_bag(tmp_path / "bag", topic_map={"joint_states": "/rig/joint_states",
                                                 "truth": "/gt"})
    assert _differences(rec, back, atol=1e-9) == []
    with pytest.raises(BagError, match="unknown topic role"):
        read_bag(tmp_path / "bag", topic_map={"camera": "x"})


def test_a_rig_recorded_in_a_namespace_is_read_there(tmp_path: Path) -> None:
    """The nodes run with ``-r __ns:=/rig1`` record /rig1/joint_states and so on: read there
    without a --topic per role, and said; two namespaces are a choice the reader refuses to
    make (it had refused the bag: "no messages on 'joint_states'")."""
    rec = sim_like(50)
    spaced = {role: f"/rig1/{name}" for role, name in DEFAULT_TOPICS.items()}
    write_recording_bag(tmp_path / "bag", rec, topics=spaced)
    back = read_bag(tmp_path / "bag")
    assert _differences(rec, back, rtol=0, atol=1e-9) == []
    note = next(n for n in back.meta["notes"] if "namespace" in n)
    assert note.startswith("topics: the bag records the rig in the namespace /rig1: read "
                           "/rig1/joint_states, /rig1/effort_controller/commands"), note
    assert back.meta["bag_topics"]["joint_states"] == "rig1/joint_states"
    # a driver in the namespace, the nodes at the root: each read where it is
    write_recording_bag(tmp_path / "mixed", rec, topics={"joint_states": "/rig1/joint_states"})
    mixed = read_bag(tmp_path / "mixed")
    assert _differences(rec, mixed, rtol=0, atol=1e-9) == []
    note = next(n for n in mixed.meta["notes"] if "namespace" in n)
    assert note == ("topics: the bag records the rig in the namespace /rig1: read "
                    "/rig1/joint_states; at the root: /effort_controller/commands, "
                    "/ball_observation, /sim_truth"), note
    write_recording_bag(tmp_path / "two", rec, topics={"joint_states": "/a/joint_states"})
    write_recording_bag(tmp_path / "two2", rec, topics={"joint_states": "/b/joint_states"})
    both = read_bag_messages(tmp_path / "two")
    two = tmp_path / "merged"
    with BagWriter(two) as w:
        for m in [*both.messages, *read_bag_messages(tmp_path / "two2").messages]:
            if m.topic.endswith("joint_states"):
                w.write(m.topic, m.msgtype, bytes(m.data), m.log_time)
    with pytest.raises(BagError, match=r"2 namespaces hold one: /a, /b; choose one with --topic"):
        read_bag(two)


def test_bag_is_standard_rosbag2_mcap(tmp_path: Path) -> None:
    """Independent readers (rosbags' rosbag2 Reader, mcap's indexed reader) accept it."""

    rec = rig_like(60)
    write_recording_bag(tmp_path / "bag", rec)
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(tmp_path / "bag") as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types["/joint_states"] == "sensor_msgs/msg/JointState"
        assert types["/ball_observation"] == "bfr_interfaces/msg/BallObservation"
        for c in reader.connections:
            if c.msgtype not in store.types:
                store.register(get_types_from_msg(c.msgdef.data, c.msgtype))
        n_js = 0
        for conn, ts, raw in reader.messages():
            msg = store.deserialize_cdr(raw, conn.msgtype)
            if conn.topic == "/joint_states":
                assert msg.name == ["frame_joint"]
                assert msg.position[0] == pytest.approx(rec.theta[n_js])
                assert ts == round(rec.t[n_js] * 1e9)
                n_js += 1
        assert n_js == 60
    with (tmp_path / "bag" / "bag.mcap").open("rb") as fh:
        r = make_reader(fh)
        assert r.get_header().profile == "ros2"
        summary = r.get_summary()
        assert summary is not None
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}


def test_truncated_bag_keeps_complete_chunks(tmp_path: Path) -> None:
    rec = sim_like(2500)
    write_recording_bag(tmp_path / "full", rec)
    data = (tmp_path / "full" / "full.mcap").read_bytes()
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / "cut.mcap").write_bytes(data[: int(len(data) * 0.7)])  # no metadata.yaml either
    with pytest.warns(BagWarning, match=r"cut.mcap: truncated or corrupt.*file ends inside"):
        part = read_bag(cut)
    assert 0 < len(part) < len(rec)
    assert np.allclose(part.t, rec.t[: len(part)], rtol=0, atol=1e-9)
    assert np.allclose(part.phi_true, rec.phi_true[: len(part)])
    assert part.meta["bag_complete"] is False and part.meta["warnings"]
    with pytest.raises(BagError, match=r"cut.mcap: truncated or corrupt"):
        read_bag(cut, strict=True)
    (cut / "cut.mcap").write_bytes(data[:2000])  # inside the first chunk: nothing usable
    with pytest.raises(BagError, match=r"no messages on 'joint_states'.*truncated"), \
            pytest.warns(BagWarning):
        read_bag(cut / "cut.mcap")


@pytest.mark.parametrize(("content", "message"), [
    (b"", "empty file"),
    (b"hello world, not a bag at all", "not an MCAP file"),
])
def test_corrupt_files(tmp_path: Path, content: bytes, message: str) -> None:
    p = tmp_path / "x.mcap"
    p.write_bytes(content)
    with pytest.raises(BagError, match=message):
        read_bag(p)


def test_bad_paths(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="no such bag"):
        read_bag(tmp_path / "missing")
    (tmp_path / "empty_dir").mkdir()
    with pytest.raises(BagError, match=r"no metadata.yaml and 0 .mcap files"):
        read_bag(tmp_path / "empty_dir")
    d = tmp_path / "badmeta"
    d.mkdir()
    (d / "metadata.yaml").write_text("rosbag2_bagfile_information: {storage_identifier: x}\n")
    with pytest.raises(BagError, match="unsupported storage 'x'"):
        read_bag(d)


def test_writer_errors(tmp_path: Path) -> None:
    with BagWriter(tmp_path / "b") as bag:
        with pytest.raises(BagError, match="unknown message type 'nope/msg/Nope'"):
            bag.write("/x", "nope/msg/Nope", b"\x00\x01\x00\x00", 0)
        store = bag.typestore
        f64 = store.types["std_msgs/msg/Float64"]
        bag.write_message("/x", f64(data=1.5), 10)
        with pytest.raises(BagError, match="already has type 'std_msgs/msg/Float64'"):
            bag.write("/x", "std_msgs/msg/String", b"", 11)
        with pytest.raises(BagError, match="negative timestamp"):
            bag.write_message("/x", f64(data=1.5), -1)
    assert bag.closed and bag.message_count == 1
    bag.close()  # idempotent
    with pytest.raises(BagError, match="exists already"):
        BagWriter(tmp_path / "b")
    with pytest.raises(BagError, match=r"t = -1.0 s < 0"):
        write_recording_bag(tmp_path / "neg", Recording(
            t=[-1.0, 0.0], theta=[0, 0], theta_dot=[0, 0], torque=[0, 0], ball_x=[0, 0],
            ball_y=[0, 0], ball_valid=[False, False], phi=[0, 0]))


CHILD = textwrap.dedent("""
    import os, signal, sys, time
    import numpy as np
    # Python's own Ctrl-C, even where the suite was started with SIGINT ignored (a background
    # job of a non-interactive shell), which a child would inherit
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from bfr_model.io.bag import BagWriter
    mode, path = sys.argv[1], sys.argv[2]
    # "sigint-busy": a chunk per message and no pause, so that the interrupt lands while a
    # record is being written (it had left half a chunk in the file before the footer)
    busy = mode == "sigint-busy"
    bag = BagWriter(path, chunk_size=64 if busy else 4096, flush_interval=None)
    T = bag.typestore.types
    def js(k):
        m = T["sensor_msgs/msg/JointState"](
            header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
                sec=k // 1000, nanosec=(k % 1000) * 1000000), frame_id=""),
            name=["frame_joint"], position=np.array([0.001 * k]),
            velocity=np.array([1.0]), effort=np.array([0.0]))
        return bag.typestore.serialize_cdr(m, "sensor_msgs/msg/JointState")
    n = 0
    if mode == "kill":
        for k in range(500):
            bag.write("/joint_states", "sensor_msgs/msg/JointState", js(k), k * 1000000)
        bag.flush()
        for k in range(500, 520):  # pending in memory: lost by the kill
            bag.write("/joint_states", "sensor_msgs/msg/JointState", js(k), k * 1000000)
        os._exit(0)
    try:
        print("ready", flush=True)
        while True:
            bag.write("/joint_states", "sensor_msgs/msg/JointState", js(n), n * 1000000)
            n += 1
            if not busy:
                time.sleep(0.0005)
    except KeyboardInterrupt:  # the write it came in was completed, or not begun
        bag.close()
        print(n, bag.message_count, flush=True)
""")


def child_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO / "src" / "bfr_model"),
                                         env.get("PYTHONPATH", "")])
    return env


def test_killed_writer_keeps_flushed_messages(tmp_path: Path) -> None:
    subprocess.run([sys.executable, "-c", CHILD, "kill", str(tmp_path / "k")], check=True,
                   env=child_env(), timeout=60)
    assert not (tmp_path / "k" / "metadata.yaml").exists()
    with pytest.warns(BagWarning):
        rec = read_bag(tmp_path / "k")
    assert 500 <= len(rec) < 520
    assert np.allclose(rec.theta, 0.001 * np.arange(len(rec)))
    assert rec.meta["bag_complete"] is False


@pytest.mark.parametrize(("mode", "trials"), [("sigint", 1), ("sigint-busy", 2)])
def test_sigint_recorder_loses_nothing(mode: str, trials: int, tmp_path: Path) -> None:
    """Ctrl-C into a writing loop: every message written is in the closed, complete bag.

    ``sigint-busy`` writes a chunk per message without pause, so the interrupt nearly always
    lands inside a record's writes: without the writer's deferral the first bag of every run
    (2 of 2) was corrupt or held a message more than the writer counted."""
    paths = [tmp_path / f"s{k}" for k in range(trials)]  # side by side
    procs = [subprocess.Popen([sys.executable, "-c", CHILD, mode, str(path)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env=child_env())
             for path in paths]
    outs = []
    try:
        for proc in procs:
            assert proc.stdout is not None  # "ready" within a minute, or the test fails
            assert select.select([proc.stdout], [], [], 60.0)[0], "the writer never started"
            assert proc.stdout.readline().strip() == "ready"
            time.sleep(0.3)
            proc.send_signal(signal.SIGINT)
            out, err = proc.communicate(timeout=30)
            assert proc.returncode == 0, err[-2000:]
            outs.append(out)
    finally:  # a writer that did not stop must not go on writing beside the suite
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    for path, out in zip(paths, outs, strict=True):
        returned, written = (int(v) for v in out.split())
        assert written > 10 and written in (returned, returned + 1)
        rec = read_bag(path, strict=True)  # complete: footer and metadata.yaml
        assert len(rec) == written
        assert np.allclose(rec.theta, 0.001 * np.arange(written))
        assert (path / "metadata.yaml").exists()


def test_a_ctrl_c_during_a_write_is_held_to_its_end(tmp_path: Path) -> None:
    """In this process, with Python's own SIGINT handler: an open writer's stands in for it;
    a real SIGINT during a write is raised at the write's end (also after the write's own
    error, which it replaces), at once outside a write; the last writer to close puts
    Python's handler back; where another handler is installed nothing is held or changed."""
    from bfr_model.io import bag as bag_mod  # noqa: PLC0415

    hold = bag_mod._HOLD
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        a, b = BagWriter(tmp_path / "a"), BagWriter(tmp_path / "b")
        assert signal.getsignal(signal.SIGINT) is hold and a._state.held and b._state.held
        went_on = []
        with pytest.raises(KeyboardInterrupt):
            with hold.during(True):
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.01)  # the handler has run by now
                went_on.append(True)
        assert went_on and hold.depth == 0 and not hold.caught
        with pytest.raises(KeyboardInterrupt) as err:
            with hold.during(True):
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.01)
                raise OSError("disk full")
        assert isinstance(err.value.__context__, OSError)
        with pytest.raises(KeyboardInterrupt):  # outside a write: at once
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)
        a.write("/joint_states", "sensor_msgs/msg/JointState", _joint_state_cdr(a), 0)
        a.close()
        assert signal.getsignal(signal.SIGINT) is hold  # b still open
        b.close()
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        assert len(read_bag(tmp_path / "a", strict=True)) == 1

        def own(signum: int, frame: object) -> None:
            del signum, frame

        signal.signal(signal.SIGINT, own)
        c = BagWriter(tmp_path / "c")
        assert not c._state.held and signal.getsignal(signal.SIGINT) is own
        c.close()
        assert signal.getsignal(signal.SIGINT) is own
    finally:
        signal.signal(signal.SIGINT, before)


def _joint_state_cdr(bag: BagWriter) -> bytes:
    T = bag.typestore.types
    m = T["sensor_msgs/msg/JointState"](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=0,
                                                                               nanosec=0),
                                        frame_id=""),
        name=["frame_joint"], position=np.array([0.0]), velocity=np.array([1.0]),
        effort=np.array([0.0]))
    return bag.typestore.serialize_cdr(m, "sensor_msgs/msg/JointState")


def test_sqlite3_bag(tmp_path: Path) -> None:

    store = make_typestore()
    T = store.types
    with Writer(tmp_path / "sq", version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        c1 = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
        c2 = w.add_connection("/effort_controller/commands", "std_msgs/msg/Float64MultiArray",
                              typestore=store)
        for k in range(20):
            stamp = T["builtin_interfaces/msg/Time"](sec=1, nanosec=k * 1000000)
            js = T["sensor_msgs/msg/JointState"](
                header=T["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
                name=["frame_joint"], position=np.array([0.1 * k]), velocity=np.array([2.0]),
                effort=np.array([]))
            w.write(c1, 1_000_000_000 + k * 1_000_000,
                    store.serialize_cdr(js, "sensor_msgs/msg/JointState"))
            cmd = T["std_msgs/msg/Float64MultiArray"](
                layout=T["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0),
                data=np.array([0.01 * k]))
            w.write(c2, 1_000_000_000 + k * 1_000_000,
                    store.serialize_cdr(cmd, "std_msgs/msg/Float64MultiArray"))
    rec = read_bag(tmp_path / "sq")
    assert rec.meta["bag_storage"] == "sqlite3"
    assert np.allclose(rec.t, 1.0 + 0.001 * np.arange(20))
    assert np.allclose(rec.torque, 0.01 * np.arange(20))
    assert not rec.ball_valid.any()


def test_custom_type_from_other_msg_dir_read_without_it(tmp_path: Path) -> None:
    """Definitions travel in the bag: reading needs no .msg files."""
    pkg = tmp_path / "bfr_test_msgs" / "msg"
    pkg.mkdir(parents=True)
    (pkg / "Probe.msg").write_text("std_msgs/Header header\nfloat64 value  # [m]\n")
    with BagWriter(tmp_path / "b", msg_dirs=[pkg]) as bag:
        T = bag.typestore.types
        probe = T["bfr_test_msgs/msg/Probe"](header=T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=5), frame_id="w"), value=2.5)
        bag.write_message("/probe", probe, 5)
    contents = read_bag_messages(tmp_path / "b")
    assert "bfr_test_msgs/msg/Probe" in contents.schemas

    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(contents.schemas["bfr_test_msgs/msg/Probe"],
                                      "bfr_test_msgs/msg/Probe"))
    msg = store.deserialize_cdr(contents.messages[0].data, "bfr_test_msgs/msg/Probe")
    assert msg.value == 2.5 and msg.header.frame_id == "w"


def test_rclpy_serialised_bytes(tmp_path: Path) -> None:
    """A recorder node hands rclpy's CDR bytes to BagWriter; read_bag decodes them."""
    rclpy_ser = pytest.importorskip("rclpy.serialization", reason="rclpy not installed")
    sensor_msgs = pytest.importorskip("sensor_msgs.msg", reason="sensor_msgs not installed")
    with BagWriter(tmp_path / "r") as bag:
        for k in range(5):
            m = sensor_msgs.JointState()
            m.header.stamp.sec, m.header.stamp.nanosec = 2, k * 1000
            m.name = ["frame_joint"]
            m.position, m.velocity, m.effort = [0.5 * k], [1.0], [0.01]
            bag.write("/joint_states", "sensor_msgs/msg/JointState",
                      rclpy_ser.serialize_message(m), 2_000_000_000 + k * 1000)
    rec = read_bag(tmp_path / "r")
    assert np.allclose(rec.theta, 0.5 * np.arange(5))
    assert np.allclose(rec.torque, 0.01)


def test_cleanup_unused(tmp_path: Path) -> None:
    """Writing into an existing directory is refused before anything is created."""
    (tmp_path / "exists").mkdir()
    with pytest.raises(BagError, match="exists already"):
        write_recording_bag(tmp_path / "exists", sim_like(5))
    shutil.rmtree(tmp_path / "exists")
