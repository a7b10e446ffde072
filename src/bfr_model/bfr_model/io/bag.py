"""ROS 2 bags in pure Python (no ``rclpy``): write and read rosbag2 directories.

A bag is a directory holding ``metadata.yaml`` and one ``<name>.mcap`` file (storage
``mcap``, messages CDR-serialised, schemas ``ros2msg``), readable by ``ros2 bag`` (Jazzy)
and Foxglove. Message definitions come from the ``rosbags`` typestore for ROS 2 Jazzy plus
the project's own types, parsed at run time from the ``.msg`` files of ``bfr_interfaces``
(source tree or installed ``share/bfr_interfaces/msg``; see :func:`find_msg_dirs`).

- :class:`BagWriter`: for a recorder node that already holds CDR bytes (from
  ``rclpy.serialization.serialize_message``): ``write(topic, msgtype, cdr, stamp_ns)``.
  Chunks are flushed to disk every ``flush_interval`` seconds and on :meth:`BagWriter.close`
  (call it from the node's shutdown path: a SIGINT'd recorder then loses nothing).
- :func:`write_recording_bag`: a :class:`~bfr_model.recording.Recording` as standard messages.
- :func:`read_bag`: a bag back into a :class:`~bfr_model.recording.Recording`. MCAP files
  without a summary section (writer killed) or cut mid-chunk are read up to the last
  complete chunk, with a warning; sqlite3 bags are read through ``rosbags``.

Topics (defaults, remappable; a leading ``/`` is optional when reading):

==================  ==================================  =================================
role                topic                               type
==================  ==================================  =================================
``joint_states``    ``joint_states``                    ``sensor_msgs/msg/JointState``
``command``         ``effort_controller/commands``      ``std_msgs/msg/Float64MultiArray``
``ball``            ``ball_observation``                ``bfr_interfaces/msg/BallObservation``
``truth``           ``sim_truth``                       ``bfr_interfaces/msg/SimTruth``
``controller``      ``controller_state``                ``bfr_interfaces/msg/ControllerState``
==================  ==================================  =================================
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import os
import signal
import threading
import time
import warnings
import weakref
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
import yaml
from mcap.exceptions import EndOfFile, InvalidMagic
from mcap.reader import make_reader
from mcap.records import (
    Attachment,
    Channel,
    Chunk,
    ChunkIndex,
    Footer,
    Message,
    MessageIndex,
    Metadata,
    Schema,
)
from mcap.stream_reader import MAGIC_SIZE, StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer
from numpy.typing import NDArray
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from bfr_model.io.account import Gates, ReadAccount, covered_seconds, gate_samples
from bfr_model.param_file import ParameterError, share_path
from bfr_model.recording import Recording, RecordingError
from bfr_model.turns import unwrap_turns

__all__ = [
    "DEFAULT_TOPICS",
    "BagError",
    "BagWarning",
    "BagWriter",
    "find_msg_dirs",
    "make_typestore",
    "read_bag",
    "read_bag_messages",
    "write_recording_bag",
]

#: Default topic per role (relative names, as DEVELOPERS.md asks).
DEFAULT_TOPICS: dict[str, str] = {
    "joint_states": "joint_states",
    "command": "effort_controller/commands",
    "ball": "ball_observation",
    "truth": "sim_truth",
    "controller": "controller_state",
}
_TYPES = {
    "joint_states": "sensor_msgs/msg/JointState",
    "command": "std_msgs/msg/Float64MultiArray",
    "ball": "bfr_interfaces/msg/BallObservation",
    "truth": "bfr_interfaces/msg/SimTruth",
    "controller": "bfr_interfaces/msg/ControllerState",
}
#: Name of the frame joint in ``JointState``.
FRAME_JOINT = "frame_joint"
_META_NAME = "bfr_recording"
_EXTRA_ATTACHMENT = "bfr_recording_extra.npz"
_NS = 1_000_000_000


class BagError(RecordingError):
    """A bag cannot be written or read; the message names the file and the problem."""


class BagWarning(UserWarning):
    """A bag was read only in part (e.g. truncated after the writer was killed)."""


# -- message definitions --------------------------------------------------------------------
def find_msg_dirs(extra: list[str | Path] | None = None) -> list[Path]:
    """Directories holding ``bfr_interfaces`` ``.msg`` files, most specific first.

    Searched: ``extra``; ``$BFR_INTERFACES_MSG_DIR`` (``os.pathsep``-separated); the
    installed ``share/bfr_interfaces/msg`` or the source tree's
    (:func:`bfr_model.param_file.share_path`).
    """
    cands: list[Path] = [Path(p) for p in (extra or [])]
    env = os.environ.get("BFR_INTERFACES_MSG_DIR", "")
    cands += [Path(p) for p in env.split(os.pathsep) if p]
    try:
        cands.append(share_path("bfr_interfaces", "msg"))
    except ParameterError:
        pass  # only the standard types then; a bag of bfr_interfaces types says so when read
    out: list[Path] = []
    for c in cands:
        if c.is_dir() and any(c.glob("*.msg")) and c.resolve() not in out:
            out.append(c.resolve())
    return out


_TYPESTORE_CACHE: dict[tuple[str, ...], Any] = {}


def make_typestore(msg_dirs: list[str | Path] | None = None) -> Any:
    """A ``rosbags`` typestore: ROS 2 Jazzy standard types plus the ``.msg`` files found.

    The package name of each ``.msg`` file is the name of the directory above ``msg/``
    (``bfr_interfaces``), so ``BallObservation.msg`` registers
    ``bfr_interfaces/msg/BallObservation``. Cached per directory list.
    """
    dirs = find_msg_dirs(msg_dirs)
    key = tuple(str(d) for d in dirs)
    if key in _TYPESTORE_CACHE:
        return _TYPESTORE_CACHE[key]
    store = get_typestore(Stores.ROS2_JAZZY)
    types: dict[str, Any] = {}
    for d in reversed(dirs):  # earlier directories win
        pkg = d.parent.name
        for f in sorted(d.glob("*.msg")):
            name = f"{pkg}/msg/{f.stem}"
            try:
                types.update(get_types_from_msg(f.read_text(encoding="utf-8"), name))
            except Exception as exc:  # rosbags raises its own parser errors
                raise BagError(f"{f}: cannot parse message definition: {exc}") from exc
    if types:
        store.register({k: v for k, v in types.items() if k not in store.types or
                        k.startswith(tuple(f"{d.parent.name}/" for d in dirs))})
    _TYPESTORE_CACHE[key] = store
    return store


def _register_from_schema(store: Any, msgtype: str, text: str) -> None:
    """Register ``msgtype`` (and dependencies) from a ``ros2msg`` schema if unknown."""
    if msgtype in store.types:
        return

    try:
        types = get_types_from_msg(text, msgtype)
    except Exception as exc:
        raise BagError(f"cannot parse the bag's definition of {msgtype}: {exc}") from exc
    store.register({k: v for k, v in types.items() if k not in store.types})


# -- writer ---------------------------------------------------------------------------------
@dataclass
class _TopicInfo:
    channel_id: int
    msgtype: str
    rihs01: str
    count: int = 0


@dataclass
class _WriterState:
    """Mutable state shared with the finaliser (closing at interpreter exit)."""

    fh: BinaryIO | None
    writer: Any
    closed: bool = False
    topics: dict[str, _TopicInfo] = field(default_factory=dict)
    held: bool = False  # its writes hold a Ctrl-C until whole (_SigintHold)


class _SigintHold:
    """Python's Ctrl-C, held while a bag record is being written (one per process).

    The MCAP writer writes a record in several calls; a Ctrl-C between two of them (Python's
    default SIGINT handler raises wherever the main thread is) left half a chunk in the
    file, and the footer written by :meth:`BagWriter.close` after it made the chunk
    unreadable (measured: "corrupt chunk at byte ~57383"); between the writer's record and
    its count it left a message more in the bag than ``metadata.yaml`` says. While a
    :class:`BagWriter` is open in the main thread of a process whose SIGINT handler is
    Python's own, this handler stands in for it: outside a write it raises
    ``KeyboardInterrupt`` at once, as Python's does; inside one (``depth`` > 0, main thread
    only) it notes the signal, and :class:`_Held` raises it when the write is whole. The
    last writer to close puts Python's handler back if this one is still installed. Where
    another handler is installed (a node's own, for one) nothing changes. Per write: an
    increment and a decrement (a handler swapped per write cost 14-21 us, tripling a write).
    """

    def __init__(self) -> None:
        self.users = 0       # open writers that hold through this handler
        self.depth = 0       # writes in progress in the main thread
        self.caught = False  # a SIGINT came during one

    def __call__(self, signum: int, frame: Any) -> None:
        if self.depth > 0:
            self.caught = True
            return
        raise KeyboardInterrupt

    def attach(self) -> bool:
        """Install for a new writer (main thread only); whether its writes are held."""
        if threading.current_thread() is not threading.main_thread():
            return False
        current = signal.getsignal(signal.SIGINT)
        if current is signal.default_int_handler:
            signal.signal(signal.SIGINT, self)
        elif current is not self:
            return False
        self.users += 1
        return True

    def detach(self) -> None:
        """A holding writer closed: Python's handler back after the last one."""
        self.users -= 1
        if (self.users <= 0 and threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGINT) is self):
            signal.signal(signal.SIGINT, signal.default_int_handler)

    def during(self, held: bool) -> _Held:
        """The context of one write of a writer whose writes are ``held`` (:meth:`attach`)."""
        return _Held(self, held and threading.get_ident() == _MAIN_THREAD)


class _Held:
    """One write under :class:`_SigintHold`.

    A SIGINT that came during it is raised at its end, also after an exception of the write,
    which it then replaces (the exception its context): a Ctrl-C is never lost.
    """

    __slots__ = ("hold", "on")

    def __init__(self, hold: _SigintHold, on: bool) -> None:
        self.hold, self.on = hold, on

    def __enter__(self) -> None:
        if self.on:
            self.hold.depth += 1

    def __exit__(self, *exc: object) -> None:
        if self.on:
            hold = self.hold
            hold.depth -= 1
            if hold.depth == 0 and hold.caught:
                hold.caught = False
                raise KeyboardInterrupt


_MAIN_THREAD = threading.main_thread().ident
_HOLD = _SigintHold()


def _finalize(state: _WriterState) -> None:  # pragma: no cover - interpreter exit path
    if not state.closed and state.writer is not None:
        try:
            state.writer.finish()
            if state.fh is not None:
                state.fh.close()
        except Exception:  # noqa: BLE001 - best effort at exit
            pass
        state.closed = True
        if state.held:
            state.held = False
            _HOLD.detach()


class BagWriter:
    """Write a rosbag2 directory with MCAP storage from CDR-serialised messages.

    Parameters
    ----------
    path : str or Path
        Bag directory to create (must not exist). The MCAP file is ``<path>/<name>.mcap``.
    msg_dirs : list of path, optional
        Extra directories of ``.msg`` files (see :func:`find_msg_dirs`).
    chunk_size : int
        Bytes per MCAP chunk before it is written out [B].
    flush_interval : float or None
        Also write the pending chunk when this much wall time passed since the last flush
        [s] (bounds what a ``kill -9`` loses); None disables it.
    custom_data : dict, optional
        String key/values for ``metadata.yaml``'s ``custom_data``.

    Examples
    --------
    In a recorder node (``cdr = rclpy.serialization.serialize_message(msg)``)::

        with BagWriter("run1") as bag:
            bag.write("joint_states", "sensor_msgs/msg/JointState", cdr, stamp_ns)
    """

    def __init__(self, path: str | Path, *, msg_dirs: list[str | Path] | None = None,
                 chunk_size: int = 256 * 1024, flush_interval: float | None = 1.0,
                 custom_data: dict[str, str] | None = None) -> None:

        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path}: exists already; a bag is written to a new directory")
        self.typestore = make_typestore(msg_dirs)
        self.mcap_path = self.path / f"{self.path.name}.mcap"
        try:
            self.path.mkdir(parents=True)
            fh = self.mcap_path.open("xb")
        except OSError as exc:
            raise BagError(f"{self.path}: cannot create bag: {exc}") from exc
        writer = Writer(fh, chunk_size=chunk_size, compression=CompressionType.NONE)
        writer.start(profile="ros2", library="bfr_model.io.bag")
        self._state = _WriterState(fh=fh, writer=writer, held=_HOLD.attach())
        self._schemas: dict[str, int] = {}
        self._flush_interval = flush_interval
        self._last_flush = time.monotonic()
        self._t_min: int | None = None
        self._t_max: int | None = None
        self._count = 0
        self.custom_data = dict(custom_data or {})
        self._metadata_records: list[tuple[str, dict[str, str]]] = []
        self._attachments: list[tuple[str, str, bytes]] = []
        self._finalizer = weakref.finalize(self, _finalize, self._state)

    # context manager
    def __enter__(self) -> BagWriter:
        """Return self."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close (flush everything and write the summary and metadata.yaml)."""
        self.close()

    @property
    def closed(self) -> bool:
        """True after :meth:`close`."""
        return self._state.closed

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return self._count

    def _schema_id(self, msgtype: str) -> int:
        if msgtype not in self._schemas:
            if msgtype not in self.typestore.types:
                raise BagError(
                    f"{self.path}: unknown message type {msgtype!r}: not a ROS 2 Jazzy "
                    f"standard type and not found in the .msg directories "
                    f"{[str(d) for d in find_msg_dirs()]}")
            text, _ = self.typestore.generate_msgdef(msgtype, ros_version=2)
            self._schemas[msgtype] = self._state.writer.register_schema(
                name=msgtype, encoding="ros2msg", data=text.encode("utf-8"))
        return self._schemas[msgtype]

    def add_topic(self, topic: str, msgtype: str) -> None:
        """Declare a topic (optional: :meth:`write` declares on first use).

        Raises
        ------
        BagError
            If the topic exists with another type, or the type is unknown.
        """
        with _HOLD.during(self._state.held):
            self._add_topic(topic, msgtype)

    def _add_topic(self, topic: str, msgtype: str) -> None:
        if self.closed:
            raise BagError(f"{self.path}: bag is closed")
        info = self._state.topics.get(topic)
        if info is not None:
            if info.msgtype != msgtype:
                raise BagError(f"{self.path}: topic {topic!r} already has type "
                               f"{info.msgtype!r}, cannot write {msgtype!r}")
            return
        sid = self._schema_id(msgtype)
        cid = self._state.writer.register_channel(
            topic=topic, message_encoding="cdr", schema_id=sid,
            metadata={"offered_qos_profiles": "[]"})
        self._state.topics[topic] = _TopicInfo(cid, msgtype, self.typestore.hash_rihs01(msgtype))

    def write(self, topic: str, msgtype: str, data: bytes | bytearray | memoryview,
              timestamp_ns: int) -> None:
        """Write one CDR-serialised message.

        Parameters
        ----------
        topic : str
            Topic name (as recorded, e.g. ``/joint_states``).
        msgtype : str
            Full type name, e.g. ``sensor_msgs/msg/JointState``.
        data : bytes
            CDR bytes including the 4-byte encapsulation header (what
            ``rclpy.serialization.serialize_message`` returns).
        timestamp_ns : int
            Receive (log) time [ns], non-negative.
        """
        ts = int(timestamp_ns)
        if ts < 0:
            raise BagError(f"{self.path}: negative timestamp {ts} ns on {topic!r}")
        with _HOLD.during(self._state.held):  # records are written whole (_SigintHold)
            self._add_topic(topic, msgtype)
            info = self._state.topics[topic]
            self._state.writer.add_message(channel_id=info.channel_id, log_time=ts,
                                           data=bytes(data), publish_time=ts,
                                           sequence=info.count)
            info.count += 1
            self._count += 1
            self._t_min = ts if self._t_min is None else min(self._t_min, ts)
            self._t_max = ts if self._t_max is None else max(self._t_max, ts)
            if self._flush_interval is not None and \
                    time.monotonic() - self._last_flush >= self._flush_interval:
                self._flush()

    def write_message(self, topic: str, msg: Any, timestamp_ns: int) -> None:
        """Serialise a ``rosbags`` message object with the typestore and write it."""
        msgtype = msg.__msgtype__
        self.write(topic, msgtype, self.typestore.serialize_cdr(msg, msgtype), timestamp_ns)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Queue an MCAP metadata record (written on close)."""
        self._metadata_records.append((name, {str(k): str(v) for k, v in data.items()}))

    def add_attachment(self, name: str, media_type: str, data: bytes) -> None:
        """Queue an MCAP attachment (written on close)."""
        self._attachments.append((name, media_type, bytes(data)))

    def flush(self) -> None:
        """Write the pending chunk and flush the file (data survives a later kill)."""
        with _HOLD.during(self._state.held):
            self._flush()

    def _flush(self) -> None:
        if self.closed:
            return
        self._state.writer.flush()
        if self._state.fh is not None:
            self._state.fh.flush()
            try:
                os.fsync(self._state.fh.fileno())
            except OSError:  # pragma: no cover - e.g. on special files
                pass
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Flush, write the MCAP summary and ``metadata.yaml``; idempotent."""
        with _HOLD.during(self._state.held):
            self._close()

    def _close(self) -> None:
        if self.closed:
            return
        w = self._state.writer
        w.flush()
        now = self._t_max or 0
        for name, data in self._metadata_records:
            w.add_metadata(name, data)
        for name, media_type, data in self._attachments:
            w.add_attachment(create_time=0, log_time=now, name=name, media_type=media_type,
                             data=data)
        w.finish()
        assert self._state.fh is not None
        self._state.fh.close()
        self._state.closed = True
        self._finalizer.detach()
        self._write_metadata_yaml()
        if self._state.held:  # the last holding writer puts Python's handler back
            self._state.held = False
            _HOLD.detach()

    def _write_metadata_yaml(self) -> None:
        start = self._t_min or 0
        duration = (self._t_max - self._t_min) if self._t_min is not None else 0  # type: ignore[operator]
        info = {
            "version": 9,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": int(duration)},
            "starting_time": {"nanoseconds_since_epoch": int(start)},
            "message_count": int(self._count),
            "topics_with_message_count": [
                {"topic_metadata": {"name": topic, "type": t.msgtype,
                                    "serialization_format": "cdr",
                                    "offered_qos_profiles": [],
                                    "type_description_hash": t.rihs01},
                 "message_count": int(t.count)}
                for topic, t in self._state.topics.items()],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.mcap_path.name],
            "files": [{"path": self.mcap_path.name,
                       "starting_time": {"nanoseconds_since_epoch": int(start)},
                       "duration": {"nanoseconds": int(duration)},
                       "message_count": int(self._count)}],
            "custom_data": self.custom_data or None,
            "ros_distro": "jazzy",
        }
        tmp = self.path / "metadata.yaml.tmp"
        tmp.write_text(yaml.safe_dump({"rosbag2_bagfile_information": info},
                                      default_flow_style=False, sort_keys=False),
                       encoding="utf-8")
        tmp.replace(self.path / "metadata.yaml")


# -- Recording -> bag -----------------------------------------------------------------------
def _resolve_topics(topics: dict[str, str] | None) -> dict[str, str]:
    out = dict(DEFAULT_TOPICS)
    by_default_name = {v: k for k, v in DEFAULT_TOPICS.items()}
    for key, value in (topics or {}).items():
        k = key.lstrip("/")
        role = k if k in DEFAULT_TOPICS else by_default_name.get(k)
        if role is None:
            raise BagError(f"unknown topic role {key!r}; roles: {sorted(DEFAULT_TOPICS)} "
                           f"(or their default topic names)")
        out[role] = value
    return out


def _stamp(store: Any, ns: int) -> Any:
    time_t = store.types["builtin_interfaces/msg/Time"]
    return time_t(sec=int(ns // _NS), nanosec=int(ns % _NS))


def write_recording_bag(path: str | Path, recording: Recording,
                        topics: dict[str, str] | None = None, *,
                        msg_dirs: list[str | Path] | None = None,
                        leading_slash: bool = True) -> Path:
    """Write a recording as a ROS 2 bag of standard and ``bfr_interfaces`` messages.

    Written per sample ``k`` (log time = header stamp = ``t[k]``):

    - ``joint_states``: ``JointState`` with ``name = ['frame_joint']``, ``position =
      [theta]``, ``velocity = [theta_dot]``, ``effort = [torque]``;
    - ``command``: ``Float64MultiArray`` with ``data = [torque]``;
    - ``ball``: ``BallObservation`` (frame ``world``) whenever the held fix or its validity
      changes: ``x, y, phi``, ``theta_used = phi - atan2(x, y)``, ``status`` FOUND or
      NOT_FOUND; pixel fields NaN; its header stamp is the fix's own time
      (``extra["ball_stamp"]``, e.g. the exposure) when the recording has one, else ``t[k]``
      (the log time is ``t[k]``, its arrival);
    - ``truth`` (simulation only): ``SimTruth`` with the ground-truth state, ball centre,
      torque and energies (unknown fields NaN);
    - ``controller`` (when ``phi_dot`` exists): ``ControllerState`` carrying ``phi_dot``.

    ``recording.meta`` is stored as MCAP metadata ``bfr_recording`` (JSON) and the
    ``extra`` arrays as the attachment ``bfr_recording_extra.npz``.

    Parameters
    ----------
    path : str or Path
        Bag directory to create.
    recording : Recording
        The data; ``t`` must be >= 0 (ROS time).
    topics : dict, optional
        Topic per role (keys: roles or default topic names), see the module table.
    msg_dirs : list of path, optional
        Extra ``.msg`` directories.
    leading_slash : bool
        Record names fully qualified (``/joint_states``), as ``ros2 bag record`` does.

    Returns
    -------
    Path
        The bag directory.
    """
    rec = recording
    if rec.t[0] < 0:
        raise BagError(f"{path}: recording starts at t = {rec.t[0]} s < 0; ROS time cannot be "
                       f"negative (slice or shift the recording first)")
    names = _resolve_topics(topics)
    if leading_slash:
        names = {k: v if v.startswith("/") else "/" + v for k, v in names.items()}
    ns = np.round(rec.t * _NS).astype(np.int64)
    with BagWriter(path, msg_dirs=msg_dirs, flush_interval=None) as bag:
        store = bag.typestore
        T = store.types
        header_t, js_t = T["std_msgs/msg/Header"], T["sensor_msgs/msg/JointState"]
        arr_t, layout_t = T["std_msgs/msg/Float64MultiArray"], T["std_msgs/msg/MultiArrayLayout"]
        ball_t = T[_TYPES["ball"]]
        ser = store.serialize_cdr
        n = len(rec)
        ball_change = np.ones(n, bool)
        if n > 1:
            same = ((rec.ball_valid[1:] == rec.ball_valid[:-1])
                    & _eq_nan(rec.ball_x[1:], rec.ball_x[:-1])
                    & _eq_nan(rec.ball_y[1:], rec.ball_y[:-1])
                    & _eq_nan(rec.phi[1:], rec.phi[:-1]))
            ball_change[1:] = ~same
        truth = rec.has_truth
        nan = float("nan")
        fix_stamp = rec.extra.get("ball_stamp")
        for k in range(n):
            stamp = _stamp(store, int(ns[k]))
            ts = int(ns[k])
            msg = js_t(header=header_t(stamp=stamp, frame_id=""), name=[FRAME_JOINT],
                       position=np.array([rec.theta[k]]), velocity=np.array([rec.theta_dot[k]]),
                       effort=np.array([rec.torque[k]]))
            bag.write(names["joint_states"], js_t.__msgtype__, ser(msg, js_t.__msgtype__), ts)
            cmd = arr_t(layout=layout_t(dim=[], data_offset=0), data=np.array([rec.torque[k]]))
            bag.write(names["command"], arr_t.__msgtype__, ser(cmd, arr_t.__msgtype__), ts)
            if ball_change[k]:
                valid = bool(rec.ball_valid[k])
                x, y, ph = (float(rec.ball_x[k]), float(rec.ball_y[k]), float(rec.phi[k]))
                own = (fix_stamp[k] if fix_stamp is not None and np.isfinite(fix_stamp[k])
                       else rec.t[k])
                obs = ball_t(header=header_t(stamp=_stamp(store, round(own * _NS)),
                                             frame_id="world"),
                             status=ball_t.FOUND if valid else ball_t.NOT_FOUND, valid=valid,
                             confidence=1.0 if valid else 0.0, u=nan, v=nan, radius_px=nan,
                             x=x if valid else nan, y=y if valid else nan,
                             phi=ph if valid else nan,
                             theta_used=ph - float(np.arctan2(x, y)) if valid else nan,
                             processing_time=nan)
                bag.write(names["ball"], _TYPES["ball"], ser(obs, _TYPES["ball"]), ts)
            if truth:
                bag.write(names["truth"], _TYPES["truth"],
                          ser(_truth_msg(T, rec, k, stamp), _TYPES["truth"]), ts)
            if rec.phi_dot is not None:
                bag.write(names["controller"], _TYPES["controller"],
                          ser(_controller_msg(T, rec, k, stamp), _TYPES["controller"]), ts)
        bag.add_metadata(_META_NAME, {"meta": json.dumps(_jsonable(rec.meta), default=str)})
        if rec.extra:
            buf = io.BytesIO()
            np.savez(buf, **rec.extra)
            bag.add_attachment(_EXTRA_ATTACHMENT, "application/x-npz", buf.getvalue())
        bag.custom_data["bfr_source_kind"] = str(rec.meta.get("source_kind", ""))
    return Path(path)


def _first(seq: Any) -> float:
    return float(seq[0]) if len(seq) else float("nan")


def _eq_nan(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.bool_]:
    return (a == b) | (np.isnan(a) & np.isnan(b))


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return str(value)
    return value


def _opt(arr: NDArray[np.float64] | None, k: int, default: float = float("nan")) -> float:
    return float(arr[k]) if arr is not None else default


def _truth_msg(T: Any, rec: Recording, k: int, stamp: Any) -> Any:
    nan = float("nan")
    return T[_TYPES["truth"]](
        header=T["std_msgs/msg/Header"](stamp=stamp, frame_id="world"),
        theta=_opt(rec.theta_true, k, float(rec.theta[k])), phi=_opt(rec.phi_true, k),
        theta_dot=_opt(rec.theta_dot_true, k, float(rec.theta_dot[k])),
        phi_dot=_opt(rec.phi_dot_true, k), ball_x=_opt(rec.ball_x_true, k),
        ball_y=_opt(rec.ball_y_true, k), ball_vx=nan, ball_vy=nan, ball_spin=nan,
        ball_spin_rate=nan, torque=float(rec.torque[k]), kinetic=_opt(rec.kinetic, k),
        potential=_opt(rec.potential, k), energy=_opt(rec.energy, k), work_in=nan,
        in_contact=True, normal_force=nan, slip_velocity=nan)


def _controller_msg(T: Any, rec: Recording, k: int, stamp: Any) -> Any:
    nan = float("nan")
    cs = T[_TYPES["controller"]]
    valid = bool(rec.ball_valid[k])
    return cs(header=T["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
              mode=cs.ROLLING if valid else cs.WAITING, theta=float(rec.theta[k]),
              theta_dot=float(rec.theta_dot[k]), phi=float(rec.phi[k]),
              phi_dot=_opt(rec.phi_dot, k), y=nan, y_dot=nan, z=nan, phase=nan,
              torque=float(rec.torque[k]), torque_unsaturated=nan, saturated=False,
              ball_age=nan)


# -- reading --------------------------------------------------------------------------------
@dataclass
class RawMessage:
    """One serialised message read from a bag."""

    topic: str
    msgtype: str
    log_time: int
    data: bytes
    sequence: int = -1


@dataclass
class BagContents:
    """Raw messages of a bag plus its definitions, metadata and problems.

    ``lost`` counts the messages known to be in the bag but not readable, per topic and
    cause (``corrupt``: a chunk failing its CRC or unparseable; ``truncated``: past the end
    of what could be read); ``lost_exact`` is False when a count is estimated from the
    bytes lost (a bag cut without its summary or metadata.yaml). ``span_ns`` is the log-time
    span of all messages the bag held, when an index says it.
    """

    path: Path
    storage: str
    messages: list[RawMessage]
    schemas: dict[str, str]
    metadata: dict[str, dict[str, str]]
    attachments: dict[str, bytes]
    warnings: list[str]
    complete: bool
    lost: dict[str, dict[str, int]] = field(default_factory=dict)
    lost_exact: bool = True
    span_ns: int | None = None


def _locate(path: Path) -> tuple[str, Path, dict[str, Any] | None]:
    """Storage kind, storage file (or bag dir for sqlite3) and parsed metadata.yaml."""
    if not path.exists():
        raise BagError(f"{path}: no such bag (directory or file)")
    if path.is_file():
        if path.suffix == ".mcap":
            return "mcap", path, None
        if path.suffix == ".db3":
            return "sqlite3", path.parent, None
        raise BagError(f"{path}: not a bag (expected a directory, .mcap or .db3)")
    meta = None
    mfile = path / "metadata.yaml"
    if mfile.exists():
        try:
            meta = yaml.safe_load(mfile.read_text(encoding="utf-8"))
            info = meta["rosbag2_bagfile_information"]
            storage = str(info.get("storage_identifier", ""))
            files = [path / str(f) for f in info.get("relative_file_paths", [])]
        except (yaml.YAMLError, KeyError, TypeError, AttributeError, UnicodeDecodeError) as exc:
            raise BagError(f"{mfile}: unreadable metadata.yaml: {exc}") from exc
        if storage == "sqlite3":
            return "sqlite3", path, meta
        if storage == "mcap":
            if len(files) != 1:
                raise BagError(f"{path}: expected one storage file, metadata.yaml lists "
                               f"{[f.name for f in files]}")
            if not files[0].exists():
                raise BagError(f"{files[0]}: storage file listed in metadata.yaml is missing")
            return "mcap", files[0], meta
        raise BagError(f"{mfile}: unsupported storage {storage!r} (mcap or sqlite3)")
    mcaps, dbs = sorted(path.glob("*.mcap")), sorted(path.glob("*.db3"))
    if len(mcaps) == 1:
        return "mcap", mcaps[0], None
    if dbs:
        raise BagError(f"{path}: sqlite3 bag without metadata.yaml (run `ros2 bag reindex`)")
    raise BagError(f"{path}: no metadata.yaml and {len(mcaps)} .mcap files (need exactly one)")


def _summary(fh: BinaryIO) -> tuple[Any, list[ChunkIndex]] | None:
    """The MCAP summary's statistics and chunk indexes, None when it cannot be read."""
    try:
        fh.seek(0)
        summary = make_reader(fh, validate_crcs=True).get_summary()
    except Exception:  # noqa: BLE001 - no footer, bad magic, a damaged summary: none then
        return None
    if summary is None or summary.statistics is None:
        return None
    return summary.statistics, sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


@dataclass(kw_only=True)
class _McapWalk:
    """State of a walk over the records of an MCAP file, chunk by chunk (mutable).

    Attributes
    ----------
    schemas, channels : dict
        Records by id.
    pending : list of Message
        Messages of intact chunks (and unchunked ones), in file order.
    metadata, attachments : dict
        Metadata and attachment records by name.
    corrupt : dict of int to int
        Messages per channel id in chunks that failed their CRC or could not be parsed
        (counted from the message index records after each chunk).
    failures : list of str
        What went wrong where.
    footer : bool
        The footer was reached.
    stopped_at : int or None
        Byte offset where the framing broke (the walk resumes at the next indexed chunk).
    end_of_file : bool
        The walk stopped because the file ended inside a record.
    """

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    pending: list[Message] = field(default_factory=list)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)
    corrupt: dict[int, int] = field(default_factory=dict)
    failures: list[str] = field(default_factory=list)
    footer: bool = False
    stopped_at: int | None = None
    end_of_file: bool = False
    bad_chunk: bool = False

    def record(self, rec: Any, where: int) -> None:
        """Take one top-level record."""
        if isinstance(rec, Chunk):
            self.bad_chunk = False
            try:
                inner = breakup_chunk(rec, validate_crc=True)
            except Exception as exc:  # noqa: BLE001 - CRC, decompression, struct errors
                self.bad_chunk = True
                self.failures.append(f"corrupt chunk at byte ~{where} ({type(exc).__name__}: "
                                     f"{exc}); skipped")
                return
            for r in inner:
                self.record(r, where)
            return
        if isinstance(rec, MessageIndex):
            if self.bad_chunk:
                self.corrupt[rec.channel_id] = (self.corrupt.get(rec.channel_id, 0)
                                                + len(rec.records))
            return
        self.bad_chunk = False
        if isinstance(rec, Schema):
            self.schemas[rec.id] = rec
        elif isinstance(rec, Channel):
            self.channels[rec.id] = rec
        elif isinstance(rec, Message):
            self.pending.append(rec)
        elif isinstance(rec, Metadata):
            self.metadata[rec.name] = dict(rec.metadata)
        elif isinstance(rec, Attachment):
            self.attachments[rec.name] = bytes(rec.data)
        elif isinstance(rec, Footer):
            self.footer = True

    def walk(self, fh: BinaryIO, start: int, size: int) -> None:
        """Read records from byte ``start`` until the footer or the first broken frame."""
        fh.seek(start)
        reader = StreamReader(fh, skip_magic=start > 0, emit_chunks=True, validate_crcs=False,
                              record_size_limit=size)
        where = start
        try:
            for rec in reader.records:
                self.record(rec, where)
                where = fh.tell()
        except InvalidMagic as exc:
            if self.footer:
                self.failures.append(f"bad magic at the end ({exc})")
            else:
                raise
        except Exception as exc:  # noqa: BLE001 - EndOfFile, struct, limits, bad opcodes
            if where >= size and isinstance(exc, (EndOfFile, EOFError)):
                self.failures.append(f"no footer (the writer did not finish): read to the "
                                     f"last intact chunk, all {size} bytes; what followed it "
                                     f"is unknown")
                return
            self.stopped_at = where
            self.end_of_file = (isinstance(exc, (EndOfFile, EOFError))
                                or _record_past_end(fh, where, size))
            what = ("file ends inside a record (truncated)" if self.end_of_file
                    else f"{type(exc).__name__}: {exc}")
            self.failures.append(f"truncated or corrupt at byte ~{where} of {size} ({what})")


#: An MCAP record's header: an opcode byte and a little-endian uint64 length.
_RECORD_HEAD = 9


def _record_past_end(fh: BinaryIO, where: int, size: int) -> bool:
    """Whether the record at byte ``where`` declares more bytes than the file holds.

    A file cut inside a record: the reader may fail on the short record's fields (a struct
    error) before it notices the end of the file, so the record's own header decides
    (``where`` 0 is the magic's start: the first record follows it).
    """
    start = where if where > 0 else MAGIC_SIZE
    if size - start < _RECORD_HEAD:
        return True
    fh.seek(start)
    head = fh.read(_RECORD_HEAD)
    length = int.from_bytes(head[1:], "little")
    return start + _RECORD_HEAD + length > size


def _yaml_counts(meta: dict[str, Any] | None) -> dict[str, int] | None:
    """Messages per topic listed in metadata.yaml (None without one)."""
    if not meta:
        return None
    try:
        topics = meta["rosbag2_bagfile_information"]["topics_with_message_count"]
        return {str(t["topic_metadata"]["name"]): int(t["message_count"]) for t in topics}
    except (KeyError, TypeError, ValueError):
        return None


def _read_mcap(path: Path, yaml_meta: dict[str, Any] | None = None) -> BagContents:
    """Read an MCAP file chunk by chunk, skipping what is damaged and counting it.

    A chunk failing its CRC is skipped and its messages counted from the message index
    records that follow it. Where the framing breaks (a damaged record length, the end of
    a cut file), the walk resumes at the next chunk of the summary's index when the file
    has one. Messages the bag held but that could not be read are counted per topic from
    the summary's statistics, else metadata.yaml, else estimated from the bytes not read.
    """
    size = path.stat().st_size
    if size == 0:
        raise BagError(f"{path}: empty file (0 bytes)")
    walk = _McapWalk()
    with path.open("rb") as fh:
        summary = _summary(fh)
        try:
            walk.walk(fh, 0, size)
        except InvalidMagic as exc:
            raise BagError(f"{path}: not an MCAP file ({exc})") from exc
        read_to = walk.stopped_at if walk.stopped_at is not None else size
        while walk.stopped_at is not None and summary is not None:
            after = [c.chunk_start_offset for c in summary[1]
                     if c.chunk_start_offset > walk.stopped_at]
            if not after:
                break
            walk.failures.append(f"resumed at the next indexed chunk, byte {after[0]}")
            walk.stopped_at = None
            walk.walk(fh, after[0], size)
    msgs: list[RawMessage] = []
    for m in walk.pending:
        ch = walk.channels.get(m.channel_id)
        if ch is None:
            walk.failures.append(f"message on unknown channel {m.channel_id} skipped")
            continue
        sc = walk.schemas.get(ch.schema_id)
        msgs.append(RawMessage(topic=ch.topic, msgtype=sc.name if sc else "",
                               log_time=int(m.log_time), data=bytes(m.data),
                               sequence=int(m.sequence)))
    read: dict[str, int] = {}
    for m in msgs:
        read[m.topic] = read.get(m.topic, 0) + 1
    corrupt = {walk.channels[c].topic if c in walk.channels else f"channel {c}": k
               for c, k in walk.corrupt.items()}
    lost, exact, span = _lost_messages(walk, summary, _yaml_counts(yaml_meta), read, corrupt,
                                       read_to, size)
    warns = [f"{path}: {f}" for f in walk.failures]
    if not walk.footer and not walk.failures:
        warns.append(f"{path}: no footer (writer did not finish); read to the last intact "
                     f"chunk (all {size} bytes)")
    defs = {sc.name: sc.data.decode("utf-8", errors="replace") for sc in walk.schemas.values()
            if sc.encoding == "ros2msg"}
    return BagContents(path=path, storage="mcap", messages=msgs, schemas=defs,
                       metadata=walk.metadata, attachments=walk.attachments, warnings=warns,
                       complete=walk.footer and not warns, lost=lost, lost_exact=exact,
                       span_ns=span)


def _lost_messages(walk: _McapWalk, summary: Any, yaml_counts: dict[str, int] | None,
                   read: dict[str, int], corrupt: dict[str, int], read_to: int,
                   size: int) -> tuple[dict[str, dict[str, int]], bool, int | None]:
    """Messages lost per topic and cause, whether the counts are exact, the bag's span."""
    tail = "truncated" if walk.end_of_file else "corrupt"
    known: dict[str, int] | None = None
    span = None
    if summary is not None:
        stats = summary[0]
        known = {walk.channels[c].topic: k for c, k in stats.channel_message_counts.items()
                 if c in walk.channels}
        span = int(stats.message_end_time - stats.message_start_time)
    elif yaml_counts is not None:
        known = yaml_counts
    lost: dict[str, dict[str, int]] = {}
    for topic, k in corrupt.items():
        lost.setdefault(topic, {})["corrupt"] = k
    if known is not None:
        for topic, total in known.items():
            rest = total - read.get(topic, 0) - corrupt.get(topic, 0)
            if rest > 0:
                lost.setdefault(topic, {})[tail] = lost.get(topic, {}).get(tail, 0) + rest
        return lost, True, span
    exact = walk.footer  # without footer nor index nothing says what followed the cut
    if read_to < size and read:
        exact = False
        frac = (size - read_to) / max(read_to, 1)
        for topic, k in read.items():
            est = math.ceil(k * frac)
            if est:
                lost.setdefault(topic, {})[tail] = lost.get(topic, {}).get(tail, 0) + est
    return lost, exact, span


def _read_sqlite(path: Path) -> BagContents:

    msgs: list[RawMessage] = []
    defs: dict[str, str] = {}
    try:
        with Reader(path) as reader:
            for conn in reader.connections:
                if conn.msgdef and conn.msgdef.data:
                    defs[conn.msgtype] = conn.msgdef.data
            for conn, ts, raw in reader.messages():
                msgs.append(RawMessage(conn.topic, conn.msgtype, int(ts), bytes(raw)))
    except Exception as exc:  # rosbags raises ReaderError and sqlite3 errors
        raise BagError(f"{path}: cannot read sqlite3 bag: {exc}") from exc
    return BagContents(path=path, storage="sqlite3", messages=msgs, schemas=defs,
                       metadata={}, attachments={}, warnings=[], complete=True)


def read_bag_messages(path: str | Path) -> BagContents:
    """All raw messages of a bag (directory, ``.mcap`` or ``.db3``), tolerant of damage.

    Raises
    ------
    BagError
        If the path is not a bag or nothing can be read.
    """
    p = Path(path)
    storage, target, meta = _locate(p)
    return _read_mcap(target, meta) if storage == "mcap" else _read_sqlite(target)


def _zoh(src_ns: NDArray[np.int64], values: NDArray[Any], at_ns: NDArray[np.int64],
         fill: Any) -> tuple[NDArray[Any], NDArray[np.bool_]]:
    """Zero-order hold of ``values`` (at sorted ``src_ns``) onto ``at_ns``."""
    values = np.asarray(values)
    idx = np.searchsorted(src_ns, at_ns, side="right") - 1
    have = idx >= 0
    out = np.full(at_ns.shape + values.shape[1:], fill, dtype=np.float64)
    if len(values):
        out[have] = values[idx[have]]
    return out, have


def _hold(src_ns: NDArray[np.int64], values: Any,
          at_ns: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Zero-order hold (NaN before the first) of ``values`` stamped ``src_ns`` in any order.

    Samples are sorted by stamp (stable: of equal stamps the last one is held).
    """
    order = np.argsort(src_ns, kind="stable")
    return _zoh(src_ns[order], np.asarray(values)[order], at_ns, np.nan)


def _header_ns(msgs: list[Any]) -> NDArray[np.int64]:
    """Header stamps of decoded messages [ns]."""
    return np.array([m.header.stamp.sec * _NS + m.header.stamp.nanosec for m in msgs],
                    dtype=np.int64)


def _log_ns(msgs: list[RawMessage], offset: int) -> NDArray[np.int64]:
    """Receive (log) times of raw messages mapped to the header clock [ns]."""
    return np.array([m.log_time for m in msgs], dtype=np.int64) - offset


def _warn_or_raise(problems: list[str], strict: bool) -> None:
    """Raise :class:`BagError` for a partly read bag when ``strict``, else warn.

    The warnings point at the caller of :func:`read_bag` (``stacklevel=3``).
    """
    if not problems:
        return
    if strict:
        raise BagError("; ".join(problems))
    for w in problems:
        warnings.warn(w, BagWarning, stacklevel=3)


def _bag_typestore(contents: BagContents, msg_dirs: list[str | Path] | None) -> Any:
    """A typestore for this bag alone: its embedded definitions first, then ``msg_dirs``.

    The ROS 2 Jazzy standard types, then every type whose definition the bag embeds (what
    its messages were serialised with), then the ``.msg`` files found for types the bag
    does not define. A fresh store per bag: one bag's definitions never leak into another.
    """
    store = get_typestore(Stores.ROS2_JAZZY)
    for msgtype, text in contents.schemas.items():
        _register_from_schema(store, msgtype, text)
    shared = make_typestore(msg_dirs)
    missing = {k: v for k, v in shared.fielddefs.items() if k not in store.fielddefs}
    if missing:
        store.register(missing)
    return store


def _in_namespace(contents: BagContents, names: dict[str, str]
                  ) -> tuple[dict[str, str], str | None]:
    """The roles' topics read in the bag's namespace when it has them only there.

    A rig run in a namespace (``-r __ns:=/rig1``) records ``/rig1/joint_states`` and so on.
    When ``joint_states`` is at its default name, no message is on it, and exactly one
    namespace holds a ``JointState`` topic of that name, each role still at its default name
    is read in that namespace if the bag has it there, and where it was otherwise (a driver
    in the namespace, the nodes at the root); a note names what was read where. Several such
    namespaces raise :class:`BagError` naming them (choose with ``--topic``).
    """
    js = names["joint_states"]
    seen = {m.topic.lstrip("/"): m.msgtype for m in contents.messages}
    if js in seen or js != DEFAULT_TOPICS["joint_states"]:
        return names, None
    spaces = sorted(t[:-len(js) - 1] for t, ty in seen.items()
                    if t.endswith("/" + js) and ty == _TYPES["joint_states"])
    if not spaces:
        return names, None
    if len(spaces) > 1:
        raise BagError(f"{contents.path}: no {js!r}, but {len(spaces)} namespaces hold one: "
                       f"{', '.join('/' + n for n in spaces)}; choose one with --topic "
                       f"joint_states=/{spaces[0]}/{js} (and the other roles likewise)")
    ns = spaces[0]
    moved = {r: (f"{ns}/{t}" if t == DEFAULT_TOPICS[r] and f"{ns}/{t}" in seen else t)
             for r, t in names.items()}
    there = [f"/{t}" for r, t in moved.items() if t != names[r]]
    root = [f"/{t}" for r, t in moved.items() if t == names[r] and t in seen]
    return moved, (f"topics: the bag records the rig in the namespace /{ns}: read "
                   f"{', '.join(there)}" + (f"; at the root: {', '.join(root)}" if root else ""))


def _messages_by_role(contents: BagContents,
                      names: dict[str, str]) -> dict[str, list[RawMessage]]:
    """The bag's messages per role (``names``: topic per role, without leading ``/``).

    Raises
    ------
    BagError
        A topic of a role carries another type than the topic contract's (one line naming
        the topic, the type found and the type expected), or no message on the
        ``joint_states`` topic (the time base).
    """
    by_role: dict[str, list[RawMessage]] = {r: [] for r in names}
    role_of = {v: k for k, v in names.items()}
    for m in contents.messages:
        role = role_of.get(m.topic.lstrip("/"))
        if role is None:
            continue
        if m.msgtype != _TYPES[role]:
            raise BagError(f"{contents.path}: topic {m.topic!r} carries {m.msgtype or '?'!r}, "
                           f"expected {_TYPES[role]!r} (role {role!r}; remap with --topic "
                           f"{role}=TOPIC if another topic has it)")
        by_role[role].append(m)
    if not by_role["joint_states"]:
        topics = sorted({m.topic for m in contents.messages})
        why = f" ({'; '.join(contents.warnings)})" if contents.warnings else ""
        raise BagError(f"{contents.path}: no messages on {names['joint_states']!r} (the time "
                       f"base); topics in the bag: {topics}{why}")
    return by_role


@dataclass(frozen=True, kw_only=True)
class _Decoder:
    """Deserialise the raw messages of one bag; a failure names the bag, type and topic."""

    store: Any
    path: Path

    def __call__(self, m: RawMessage) -> Any:
        """The decoded message."""
        try:
            return self.store.deserialize_cdr(m.data, m.msgtype)
        except Exception as exc:
            raise BagError(f"{self.path}: cannot decode a {m.msgtype} message on "
                           f"{m.topic!r} at {m.log_time} ns: {exc}") from exc

    def all(self, msgs: list[RawMessage], notes: list[str]) -> tuple[list[Any], list[int]]:
        """The messages that decode (and their indices); the others counted in ``notes``."""
        out: list[Any] = []
        idx: list[int] = []
        first = None
        for i, m in enumerate(msgs):
            try:
                out.append(self.store.deserialize_cdr(m.data, m.msgtype))
                idx.append(i)
            except Exception as exc:  # noqa: BLE001 - any decoding failure is a corrupt message
                first = first or f"{m.log_time} ns ({type(exc).__name__})"
        if len(out) < len(msgs):
            notes.append(f"{msgs[0].topic}: {len(msgs) - len(out)} message(s) do not decode "
                         f"(corrupt), first at {first}: skipped")
        return out, idx


@dataclass(frozen=True, kw_only=True)
class _JointStates:
    """The ``joint_states`` time base of a bag and the frame joint's values on it.

    Attributes
    ----------
    stamp : ndarray of int
        Header stamps [ns], sorted, of the samples the gates kept.
    offset : int
        Median of log time minus header stamp [ns]: maps log times to the header clock.
    theta, theta_dot, effort : ndarray
        Position [rad], velocity [rad/s] and effort [N m] of the frame joint.
    sequence : ndarray of int
        Each kept sample's sequence number on its topic (-1 when unknown).
    account : dict
        ``present``, ``dropped`` (by cause), ``first`` (stamp [ns] per cause) and ``actions``.
    """

    stamp: NDArray[np.int64]
    offset: int
    theta: NDArray[np.float64]
    theta_dot: NDArray[np.float64]
    effort: NDArray[np.float64]
    sequence: NDArray[np.int64]
    account: dict[str, Any]


def _joint_value(seq: Any, j: int) -> float:
    """Entry ``j`` of a ``JointState`` array (NaN if it is shorter)."""
    return float(seq[j]) if len(seq) > j else float("nan")


def _read_joint_states(msgs: list[RawMessage], decode: _Decoder, notes: list[str],
                       gates: Gates | None) -> _JointStates:
    """Decode ``joint_states``: the time base and the frame joint (index 0 if not named).

    Messages are sorted by header stamp (a bag logs them in arrival order; reordering
    loses nothing), then the physical gates drop what no hardware makes
    (:func:`bfr_model.io.account.gate_samples`). A missing velocity is replaced by the
    numerical derivative of the position.

    Raises
    ------
    BagError
        No message decodes, or none passes the gates.
    """
    js, idx = decode.all(msgs, notes)
    corrupt = len(msgs) - len(js)
    if not js:
        raise BagError(f"{decode.path}: no {msgs[0].topic!r} message decodes ({len(msgs)} "
                       f"present)")
    raw = [msgs[i] for i in idx]
    stamp = _header_ns(js)
    order = np.argsort(stamp, kind="stable")
    actions: list[str] = []
    if not np.all(order == np.arange(order.size)):
        actions.append(f"joint_states: {int(np.count_nonzero(np.diff(stamp) < 0))} message(s) "
                       f"logged before an earlier stamp: sorted by header stamp (nothing lost)")
    js, raw, stamp = [js[i] for i in order], [raw[i] for i in order], stamp[order]
    first = js[0].name
    j = first.index(FRAME_JOINT) if FRAME_JOINT in first else 0
    if FRAME_JOINT not in first:
        notes.append(f"joint_states: no {FRAME_JOINT!r} joint; used index 0 ({first[:1]})")
    theta = np.array([_joint_value(s.position, j) for s in js])
    theta_dot = np.array([_joint_value(s.velocity, j) for s in js])
    if np.isnan(theta_dot).all():
        ts_s = stamp / _NS
        # of the accumulating angle (a wrap is no motion; the gates unwrap theta too)
        theta_dot = (np.gradient(unwrap_turns(theta)[0], ts_s) if len(js) > 1
                     else np.zeros(len(js)))
        notes.append("theta_dot: joint_states without velocity; numerical derivative used")
    effort = np.array([_joint_value(s.effort, j) for s in js])
    g = gate_samples(stamp.astype(np.float64) / _NS, theta, theta_dot,
                     np.nan_to_num(effort, nan=0.0), gates=gates)
    keep = g.keep
    if not keep.any():
        raise BagError(f"{decode.path}: no joint_states sample passes the checks "
                       f"({g.dropped})")
    offset = int(np.median(_log_ns(raw, 0)[keep] - stamp[keep]))
    dropped = dict(g.dropped)
    if corrupt:
        dropped["corrupt"] = dropped.get("corrupt", 0) + corrupt
    actions += g.actions(lambda i: f"stamp {stamp[i] / _NS:.6f} s")
    seq = np.array([m.sequence for m in raw], dtype=np.int64)
    return _JointStates(stamp=stamp[keep], offset=offset, theta=g.theta[keep],
                        theta_dot=theta_dot[keep], effort=effort[keep], sequence=seq[keep],
                        account={"present": len(msgs), "dropped": dropped, "actions": actions,
                                 "span": float(stamp[-1] - stamp[0]) / _NS})


def _torque(js: _JointStates, cmds: list[RawMessage], decode: _Decoder,
            notes: list[str]) -> NDArray[np.float64]:
    """The latest command at each sample; joint effort before it, 0 where neither is known."""
    torque = js.effort.copy()
    if cmds:
        dec, idx = decode.all(cmds, notes)
        cmds = [cmds[i] for i in idx]
        held, have = _hold(_log_ns(cmds, js.offset),
                           np.array([_first(c.data) for c in dec]), js.stamp)
        torque = np.where(have, held, js.effort)
        if not have.all():
            notes.append(f"torque: joint_states effort used for {int((~have).sum())} sample(s) "
                         f"before the first command")
    else:
        notes.append("torque: no command topic; joint_states effort used")
    if np.isnan(torque).any():
        torque = np.nan_to_num(torque, nan=0.0)
        notes.append("torque: unknown samples set to 0")
    return torque


@dataclass(frozen=True, kw_only=True)
class _BallFields:
    """The held ball observation at each sample (NaN where not valid).

    Attributes
    ----------
    x, y : ndarray
        Ball centre in the world frame [m].
    phi : ndarray
        Ball-centre angle [rad].
    valid : ndarray of bool
        A valid observation with finite ``x, y`` is held.
    """

    x: NDArray[np.float64]
    y: NDArray[np.float64]
    phi: NDArray[np.float64]
    valid: NDArray[np.bool_]
    stamp_ns: NDArray[np.float64]   # the held observation's own time [ns] (NaN before one)


def _ball_fields(js: _JointStates, obs_msgs: list[RawMessage], decode: _Decoder,
                 notes: list[str]) -> _BallFields:
    """Hold the latest ball observation, placed at its header stamp, at each sample.

    An observation's header stamp is the time of the image it was measured in (the topic
    contract: the exposure); an observation without one (a zero stamp) is placed at its
    receive (log) time mapped to the header clock, and the notes say how many. A valid
    observation without ``phi`` gets ``theta + atan2(x, y)``.
    """
    n = js.stamp.size
    if not obs_msgs:
        return _BallFields(x=np.full(n, np.nan), y=np.full(n, np.nan), phi=np.full(n, np.nan),
                           valid=np.zeros(n, bool), stamp_ns=np.full(n, np.nan))
    obs, idx = decode.all(obs_msgs, notes)
    obs_msgs = [obs_msgs[i] for i in idx]
    if not obs:
        return _BallFields(x=np.full(n, np.nan), y=np.full(n, np.nan), phi=np.full(n, np.nan),
                           valid=np.zeros(n, bool), stamp_ns=np.full(n, np.nan))
    vals = np.array([[b.x, b.y, b.phi, 1.0 if b.valid else 0.0] for b in obs])
    placed = _header_ns(obs)
    unstamped = placed <= 0
    if unstamped.any():
        placed = np.where(unstamped, _log_ns(obs_msgs, js.offset), placed)
        notes.append(f"ball: {int(unstamped.sum())} of {len(obs)} observation(s) carry no "
                     "header stamp: placed at their receive time (on the header clock)")
    notes.append(f"ball: {int((~unstamped).sum())} observation(s) placed at their header "
                 "stamp (the image's time)")
    sel, have = _hold(placed, np.column_stack([vals, placed.astype(np.float64)]), js.stamp)
    valid = have & (sel[:, 3] > 0) & np.isfinite(sel[:, 0]) & np.isfinite(sel[:, 1])
    ball_x = np.where(valid, sel[:, 0], np.nan)
    ball_y = np.where(valid, sel[:, 1], np.nan)
    phi = np.where(valid, sel[:, 2], np.nan)
    bad_phi = valid & ~np.isfinite(phi)
    if bad_phi.any():
        phi[bad_phi] = js.theta[bad_phi] + np.arctan2(ball_x[bad_phi], ball_y[bad_phi])
        notes.append("ball: phi missing in some observations; theta + atan2(x, y) used")
    return _BallFields(x=ball_x, y=ball_y, phi=phi, valid=valid,
                       stamp_ns=np.where(have, sel[:, 4], np.nan))


#: ``Recording`` field per ``SimTruth`` field read from the ``truth`` topic.
_TRUTH_FIELDS = {"theta_true": "theta", "theta_dot_true": "theta_dot", "phi_true": "phi",
                 "phi_dot_true": "phi_dot", "ball_x_true": "ball_x", "ball_y_true": "ball_y",
                 "kinetic": "kinetic", "potential": "potential", "energy": "energy"}


def _optional_fields(js: _JointStates, by_role: dict[str, list[RawMessage]],
                     decode: _Decoder) -> dict[str, NDArray[np.float64]]:
    """Optional recording fields held by header stamp: ``phi_dot`` and the ground truth.

    ``phi_dot`` comes from the ``controller`` topic; a truth field is kept unless all NaN.
    """
    out: dict[str, NDArray[np.float64]] = {}
    if by_role["controller"]:
        cs, _ = decode.all(by_role["controller"], [])
        held, have = _hold(_header_ns(cs), np.array([c.phi_dot for c in cs]), js.stamp)
        out["phi_dot"] = np.where(have, held, np.nan)
    if by_role["truth"]:
        tr, _ = decode.all(by_role["truth"], [])
    if by_role["truth"] and tr:
        table = np.array([[getattr(s, f) for f in _TRUTH_FIELDS.values()] for s in tr])
        held, have = _hold(_header_ns(tr), table, js.stamp)
        for c, name in enumerate(_TRUTH_FIELDS):
            col = np.where(have, held[:, c], np.nan)
            if not np.all(np.isnan(col)):
                out[name] = col
    return out


def _time_axis(stamp: NDArray[np.int64], time_origin: str) -> tuple[NDArray[np.float64], int]:
    """Sample times [s] from the stamps and the origin subtracted [ns] (see :func:`read_bag`).

    Raises
    ------
    BagError
        An unknown ``time_origin``.
    """
    origin = 0
    if time_origin == "first" or (time_origin == "auto" and stamp[0] > 10**8 * _NS):
        origin = int(stamp[0])
    elif time_origin not in ("auto", "absolute", "first"):
        raise BagError(f"time_origin must be 'auto', 'absolute' or 'first', got {time_origin!r}")
    t = (stamp - origin) // _NS + ((stamp - origin) % _NS) / _NS
    return t, origin


def _bag_meta(contents: BagContents, source: Path, names: dict[str, str],
              by_role: dict[str, list[RawMessage]], origin: int,
              notes: list[str]) -> dict[str, Any]:
    """``Recording.meta``: the stored ``bfr_recording`` metadata updated with this read.

    Provenance, storage, topics, time origin, and the bag's warnings and ``notes`` appended
    to those stored. Stored metadata that is not a JSON object is ignored, and said.
    """
    meta: dict[str, Any] = {}
    if _META_NAME in contents.metadata:
        try:
            stored = json.loads(contents.metadata[_META_NAME].get("meta", "{}"))
        except json.JSONDecodeError:
            stored = None
            notes.append("bag: bfr_recording metadata is not valid JSON; ignored")
        if isinstance(stored, dict):
            meta = stored
        elif stored is not None:
            notes.append(f"bag: bfr_recording metadata is a JSON {type(stored).__name__}, not "
                         f"an object; ignored")
    for key in ("notes", "warnings", "conversions"):
        if not isinstance(meta.get(key, []), list):
            meta[key] = [str(meta[key])]
    original_source = meta.get("source")
    meta["source"] = str(source)
    meta["source_kind"] = "bag" if not meta.get("source_kind") else meta["source_kind"]
    if original_source is not None and original_source != str(source):
        meta["original_source"] = original_source
    meta["bag_storage"] = contents.storage
    meta["bag_complete"] = contents.complete
    meta["bag_topics"] = {r: names[r] for r in names if by_role[r]}
    meta["time_origin_ns"] = origin
    meta["warnings"] = [*meta.get("warnings", []), *contents.warnings]
    meta["notes"] = [*meta.get("notes", []), *notes]
    return meta


def _extra_arrays(contents: BagContents, js: _JointStates,
                  notes: list[str]) -> dict[str, np.ndarray]:
    """The ``extra`` arrays of the bag's attachment, on the samples kept.

    The attachment holds one value per sample written; ``joint_states`` message ``k``
    (its sequence number) is sample ``k``, so the arrays follow the samples kept whatever
    was dropped. An array that does not fit is left out, and said.
    """
    extra: dict[str, np.ndarray] = {}
    if _EXTRA_ATTACHMENT not in contents.attachments:
        return extra
    try:
        npz = np.load(io.BytesIO(contents.attachments[_EXTRA_ATTACHMENT]))
    except Exception as exc:  # noqa: BLE001 - a damaged attachment
        notes.append(f"bag: extra arrays attachment unreadable ({type(exc).__name__}); ignored")
        return extra
    seq = js.sequence
    with npz:
        for k in npz.files:
            arr = npz[k]
            if arr.ndim == 1 and seq.size and seq.min() >= 0 and seq.max() < arr.shape[0]:
                extra[k] = arr[seq]
            else:
                notes.append(f"bag: extra array {k!r} (shape {arr.shape}) does not match the "
                             f"{seq.size} samples kept; left out")
    return extra


def _account(contents: BagContents, names: dict[str, str], js: _JointStates,
             ball_off: int, t: NDArray[np.float64]) -> ReadAccount:
    """The read's account on the time base (``joint_states`` samples)."""
    topic_lost: dict[str, int] = {}
    for topic, by_cause in contents.lost.items():
        if topic.lstrip("/") == names["joint_states"]:
            for cause, k in by_cause.items():
                topic_lost[cause] = topic_lost.get(cause, 0) + k
    dropped = dict(js.account["dropped"])
    for cause, k in topic_lost.items():
        dropped[cause] = dropped.get(cause, 0) + k
    others = [f"{topic}: {k} {cause}" for topic, by_cause in contents.lost.items()
              if topic.lstrip("/") != names["joint_states"] for cause, k in by_cause.items()]
    actions = list(js.account["actions"])
    actions += [w.replace(f"{contents.path}: ", "") for w in contents.warnings]
    if others:
        actions.append("messages of other topics lost: " + ", ".join(others))
    span = contents.span_ns / _NS if contents.span_ns is not None else js.account["span"]
    used = covered_seconds(t)
    present = max(span, used) if contents.lost_exact else float("nan")
    return ReadAccount(source=str(contents.path), kind="bag",
                       samples_present=js.account["present"] + sum(topic_lost.values()),
                       samples_used=int(t.size), seconds_present=present,
                       seconds_used=used, dropped=dropped,
                       degraded={"ball_off_frame": ball_off}, actions=actions,
                       exact=contents.lost_exact)


def read_bag(path: str | Path, topic_map: dict[str, str] | None = None, *,
             strict: bool = False, msg_dirs: list[str | Path] | None = None,
             time_origin: str = "auto", gates: Gates | None = None) -> Recording:
    """Read a bag into a :class:`Recording` (our conventions: the bag's messages are).

    The time base is the ``joint_states`` header stamps (sorted; the physical gates of
    :func:`bfr_model.io.account.gate_samples` drop repeated stamps and values no hardware
    makes). ``torque`` is the latest ``command`` at or before each sample (``effort`` of
    the joint state before the first command, or when there is no command topic). Ball
    fields hold the latest ``ball`` observation placed at its header stamp (the image's
    time; its receive time only for an observation without a stamp, and ``meta["notes"]``
    says so), and ``extra["ball_stamp"]`` is the held observation's stamp [s] on the axis of
    ``t``; ``phi_dot`` comes from the ``controller`` topic and ground truth from ``truth``
    when present. Log times are mapped to the header clock by the median offset between
    the two on ``joint_states``.

    The MCAP file is read chunk by chunk: a chunk failing its CRC is skipped, a file cut
    short (a recorder killed: no footer, no metadata.yaml) is read to its last intact
    chunk; what could not be read is counted per topic and cause in
    ``meta["read_account"]`` (:class:`~bfr_model.io.account.ReadAccount`).

    Parameters
    ----------
    path : str or Path
        Bag directory, ``.mcap`` or ``.db3`` file.
    topic_map : dict, optional
        Topic per role, keys being roles (``joint_states``, ``command``, ``ball``,
        ``truth``, ``controller``) or their default topic names; leading ``/`` optional.
    strict : bool
        Raise :class:`BagError` when the bag is truncated or corrupt instead of returning
        what was readable (with a :class:`BagWarning` and ``meta["warnings"]``).
    msg_dirs : list of path, optional
        Extra ``.msg`` directories (definitions embedded in the bag are used first).
    time_origin : {"auto", "absolute", "first"}
        ``"absolute"`` keeps stamps as seconds; ``"first"`` subtracts the first
        ``joint_states`` stamp; ``"auto"`` does the latter only for wall-clock stamps
        (> 1e8 s), recording the origin in ``meta["time_origin_ns"]``.
    gates : Gates, optional
        Bounds of the physical gates (default: from rig.yaml).

    Raises
    ------
    BagError
        Not a bag, a topic of another type than the contract's, no usable ``joint_states``
        messages, or (``strict``) a damaged file. The message names the file.
    """
    if time_origin not in ("auto", "absolute", "first"):
        raise BagError(f"time_origin must be 'auto', 'absolute' or 'first', got {time_origin!r}")
    p = Path(path)
    names = {k: v.lstrip("/") for k, v in _resolve_topics(topic_map).items()}
    gates = gates if gates is not None else Gates.from_params()
    contents = read_bag_messages(p)
    _warn_or_raise(contents.warnings, strict)
    names, in_ns = _in_namespace(contents, names)
    by_role = _messages_by_role(contents, names)
    decode = _Decoder(store=_bag_typestore(contents, msg_dirs), path=contents.path)
    notes: list[str] = [in_ns] if in_ns else []
    js = _read_joint_states(by_role["joint_states"], decode, notes, gates)
    torque = _torque(js, by_role["command"], decode, notes)
    ball = _ball_fields(js, by_role["ball"], decode, notes)
    with np.errstate(over="ignore", invalid="ignore"):
        off = ball.valid & (np.hypot(ball.x, ball.y) > gates.max_ball_radius)
    if off.any():
        ball = dataclasses.replace(ball, valid=ball.valid & ~off,
                                   x=np.where(off, np.nan, ball.x),
                                   y=np.where(off, np.nan, ball.y),
                                   phi=np.where(off, np.nan, ball.phi))
    optional = _optional_fields(js, by_role, decode)
    t, origin = _time_axis(js.stamp, time_origin)
    meta = _bag_meta(contents, p, names, by_role, origin, notes)
    extra = _extra_arrays(contents, js, meta["notes"])
    if by_role["ball"]:
        extra["ball_stamp"] = (ball.stamp_ns - origin) / _NS
    try:
        rec = Recording(t=t, theta=js.theta, theta_dot=js.theta_dot, torque=torque,
                        ball_x=ball.x, ball_y=ball.y, ball_valid=ball.valid, phi=ball.phi,
                        extra=extra, meta=meta, **optional)
    except RecordingError as exc:
        raise BagError(f"{contents.path}: {exc}") from exc
    rec.meta["sample_rate"] = rec.sample_rate()
    rec.meta["camera_fix_rate"] = rec.camera_fix_rate()
    rec.meta["read_account"] = _account(contents, names, js, int(off.sum()), t).to_json()
    return rec
