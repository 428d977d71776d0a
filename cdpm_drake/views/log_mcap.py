"""A log as a ROS 2 bag in MCAP storage (`cdpm export LOG --mcap`), written without ROS by the
`rosbags` package, for Foxglove and the ROS 2 tools (`ros2 bag info/play FILE.mcap`).

One message per tick on each topic, stamped with the log's `time` from 0 (t = 0 is stamp
0 s 0 ns, 1970-01-01 for tools that show dates; bag and header stamps alike), every frame_id
"base" (the base frame A, m, N):

- /reels/joint_states (sensor_msgs/JointState): name cable_1..cable_m, position the measured
  cable lengths (m), velocity the reel velocity command (m/s), effort the measured tension
  (N: `tension_measured` where it holds numbers, else the dynamic plant's true `tensions`,
  else empty);
- /platform/pose (geometry_msgs/PoseStamped): the controller's estimate `p` (and `rpy` for the
  full pose; else the identity orientation);
- /platform/pose_true: the dynamic plant's `p_true`, `rpy_true` (only in its logs);
- /platform/hand_wrench, /platform/interference_wrench, /platform/desired_wrench
  (geometry_msgs/WrenchStamped): the forces `F_H`, `F_int`, `F_d` (torque zero);
- /cables (visualization_msgs/MarkerArray): per cable i a LINE_LIST marker, id i (1-based),
  from its reel a_i to its attachment p + R b_i at the estimated pose;
- /cables_true: the same at the dynamic plant's true pose (only in its logs): what the
  cables really did.

Message types of ROS 2 Jazzy; each message's definition is stored in the file. No Drake.
"""

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from cdpm_drake.kernels.rotation import rotations_from_rpy

FRAME = "base"
# Keys every export needs; the optional ones (rpy, p_true, rpy_true, tension_measured,
# tensions) add what they hold.
NEEDS = ("time", "lengths", "reel_velocity", "p", "F_H", "F_int", "F_d", "reels",
         "attachments")
WRENCHES = {"/platform/hand_wrench": "F_H", "/platform/interference_wrench": "F_int",
            "/platform/desired_wrench": "F_d"}
CABLE_WIDTH = 0.005  # m, the line width of the cable markers
CABLE_COLOR = (0.1, 0.45, 0.85, 1.0)  # RGBA, the cables at the estimated pose
TRUE_CABLE_COLOR = (0.9, 0.45, 0.1, 1.0)  # and at the true pose
LINE_LIST = 5  # visualization_msgs/Marker's type: a line per pair of points


class McapExportError(ValueError):
    """A log the MCAP export cannot write (a key it needs missing or of the wrong shape)."""


def check_mcap_keys(log: Mapping) -> None:
    """McapExportError naming the first key the export needs that the log lacks or that has
    not one row per tick."""
    missing = [k for k in NEEDS if k not in log]
    if missing:
        raise McapExportError(f"the MCAP export needs log key(s) {missing!r} "
                              f"(docs/LOG_FORMAT.md); the log holds {sorted(log)!r}")
    T = np.shape(log["time"])[0]
    m = np.shape(log["reels"])[0]
    widths = {"lengths": m, "reel_velocity": m, "tension_measured": m, "tensions": m,
              "p": 3, "F_H": 3, "F_int": 3, "F_d": 3, "rpy": 3, "p_true": 3, "rpy_true": 3}
    for key, width in widths.items():
        if key in log and np.shape(log[key]) != (T, width):
            raise McapExportError(f"log key {key!r} has shape {np.shape(log[key])!r}; the "
                                  f"MCAP export needs ({T}, {width}): one row per tick "
                                  f"({T}, as 'time') of {width} values")
    if np.shape(log["attachments"]) != (m, 3) or np.shape(log["reels"]) != (m, 3):
        raise McapExportError(f"log keys 'reels' and 'attachments' must both be ({m}, 3); "
                              f"they are {np.shape(log['reels'])!r} and "
                              f"{np.shape(log['attachments'])!r}")


def stamps_ns(time) -> np.ndarray:
    """The log's times (s) as integer nanoseconds from 0."""
    return np.round(np.asarray(time, dtype=float).reshape(-1) * 1e9).astype(np.int64)


def quaternions_from_rpy(rpy) -> np.ndarray:
    """(N, 4) unit quaternions x, y, z, w of R = Rz(yaw) Ry(pitch) Rx(roll), rows (N, 3) rad."""
    a = 0.5 * np.asarray(rpy, dtype=float).reshape(-1, 3)
    cr, sr = np.cos(a[:, 0]), np.sin(a[:, 0])
    cp, sp = np.cos(a[:, 1]), np.sin(a[:, 1])
    cy, sy = np.cos(a[:, 2]), np.sin(a[:, 2])
    return np.stack([sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy,
                     cr * cp * cy + sr * sp * sy], axis=1)


def cable_segments(log: Mapping, p_key: str = "p", rpy_key: str = "rpy") -> np.ndarray:
    """(T, m, 2, 3): per tick and cable, its reel a_i and its attachment p + R b_i (m) at the
    pose of `p_key` and `rpy_key` (the controller's estimate by default; R the identity
    where the log has no `rpy_key`)."""
    p = np.asarray(log[p_key], dtype=float)
    b = np.asarray(log["attachments"], dtype=float)
    a = np.asarray(log["reels"], dtype=float)
    if rpy_key in log:
        ends = p[:, None, :] + np.einsum("tij,mj->tmi", rotations_from_rpy(log[rpy_key]), b)
    else:
        ends = p[:, None, :] + b[None, :, :]
    return np.stack([np.broadcast_to(a, ends.shape), ends], axis=2)


def joint_efforts(log: Mapping):
    """(T, m) tensions (N) for the joint states' effort, and the key they came from; (None,
    None) when the log has none. `tension_measured` all NaN (no sensor) falls back on the
    dynamic plant's true `tensions`."""
    measured = log.get("tension_measured")
    if measured is not None and np.isfinite(np.asarray(measured, dtype=float)).any():
        return np.asarray(measured, dtype=float), "tension_measured"
    if "tensions" in log:
        return np.asarray(log["tensions"], dtype=float), "tensions"
    return None, None


class _Messages:
    """Message objects of a rosbags typestore, built with every field at its zero value."""

    def __init__(self):
        from rosbags.typesys import Stores, get_typestore

        self.store = get_typestore(Stores.ROS2_JAZZY)
        self._defaults = {}

    def new(self, typename: str, **fields):
        """A `typename` message: `fields` as given, every other field zero or empty (values
        shared between messages: they are serialized, never changed)."""
        defaults = self._defaults.get(typename)
        if defaults is None:
            _, defs = self.store.fielddefs[typename]
            defaults = {name: self._zero(kind.name, desc) for name, (kind, desc) in defs}
            self._defaults[typename] = defaults
        return self.store.types[typename](**{**defaults, **fields})

    def _zero(self, kind: str, desc):
        if kind == "NAME":
            return self.new(desc)
        if kind == "BASE":
            base = desc[0]
            return "" if base == "string" else False if base == "bool" else (
                0.0 if base.startswith("float") else 0)
        # A sequence (kind SEQUENCE) is empty; a fixed array (ARRAY) holds desc[1] zeros.
        (sub_kind, sub), n = desc
        n = n if kind == "ARRAY" else 0
        if sub_kind.name == "BASE" and sub[0] != "string":
            return np.zeros(n, dtype=_NUMPY[sub[0]])
        return [self._zero(sub_kind.name, sub) for _ in range(n)]

    def serialize(self, message) -> bytes:
        return self.store.serialize_cdr(message, message.__msgtype__)


_NUMPY = {"float64": np.float64, "float32": np.float32, "uint8": np.uint8, "int8": np.int8,
          "uint16": np.uint16, "int16": np.int16, "uint32": np.uint32, "int32": np.int32,
          "uint64": np.uint64, "int64": np.int64, "byte": np.uint8, "char": np.uint8,
          "octet": np.uint8, "bool": np.bool_}


def topics(log: Mapping) -> dict:
    """{topic: message type} the export writes for this log."""
    out = {"/reels/joint_states": "sensor_msgs/msg/JointState",
           "/platform/pose": "geometry_msgs/msg/PoseStamped"}
    if "p_true" in log:
        out["/platform/pose_true"] = "geometry_msgs/msg/PoseStamped"
    out.update({t: "geometry_msgs/msg/WrenchStamped" for t in WRENCHES})
    out["/cables"] = "visualization_msgs/msg/MarkerArray"
    if "p_true" in log:
        out["/cables_true"] = "visualization_msgs/msg/MarkerArray"
    return out


def write_log_mcap(log: Mapping, path) -> dict:
    """Write the log to `path` (a new .mcap file, a ROS 2 bag whose metadata it holds);
    returns {topic: messages written}. Needs rosbags (ImportError naming the extra without
    it)."""
    import shutil
    import tempfile

    try:
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
    except ImportError:
        raise ImportError("writing an MCAP bag needs the rosbags package: pip install "
                          "'cdpm_drake[export]'") from None

    check_mcap_keys(log)
    path = Path(path)
    M = _Messages()
    new = M.new
    stamps = stamps_ns(log["time"])
    T, m = len(stamps), np.shape(log["reels"])[0]
    names = [f"cable_{i}" for i in range(1, m + 1)]
    lengths = np.asarray(log["lengths"], dtype=float)
    speeds = np.asarray(log["reel_velocity"], dtype=float)
    efforts, _ = joint_efforts(log)
    poses = {"/platform/pose": ("p", "rpy")}
    if "p_true" in log:
        poses["/platform/pose_true"] = ("p_true", "rpy_true")
    pose_data = {}
    for topic, (pk, rk) in poses.items():
        q = (quaternions_from_rpy(log[rk]) if rk in log
             else np.tile([0.0, 0.0, 0.0, 1.0], (T, 1)))
        pose_data[topic] = (np.asarray(log[pk], dtype=float), q)
    forces = {t: np.asarray(log[k], dtype=float) for t, k in WRENCHES.items()}
    cables = {"/cables": (cable_segments(log), _color(new, CABLE_COLOR))}
    if "p_true" in log:
        cables["/cables_true"] = (cable_segments(log, "p_true", "rpy_true"),
                                  _color(new, TRUE_CABLE_COLOR))
    scale = new("geometry_msgs/msg/Vector3", x=CABLE_WIDTH)
    identity = new("geometry_msgs/msg/Pose",
                   orientation=new("geometry_msgs/msg/Quaternion", w=1.0))
    counts = dict.fromkeys(topics(log), 0)

    # rosbags writes a bag folder (DIR/DIR.mcap and metadata.yaml); the .mcap holds the
    # same metadata, so it alone is the bag handed over.
    with tempfile.TemporaryDirectory(dir=path.parent, prefix=".cdpm_export_") as tmp:
        bag = Path(tmp) / "bag"
        writer = Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP)
        # zstd chunks, as `ros2 bag record --storage-preset-profile zstd_fast` writes them:
        # exp2's 30 s in 7.5 MB instead of 42 MB; Foxglove and the mcap readers decompress them.
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        with writer:
            conns = {t: writer.add_connection(t, ty, typestore=M.store)
                     for t, ty in topics(log).items()}
            for k in range(T):
                ns = int(stamps[k])
                header = new("std_msgs/msg/Header", frame_id=FRAME,
                             stamp=new("builtin_interfaces/msg/Time", sec=ns // 10**9,
                                       nanosec=ns % 10**9))
                msgs = [("/reels/joint_states", new(
                    "sensor_msgs/msg/JointState", header=header, name=names,
                    position=lengths[k].copy(), velocity=speeds[k].copy(),
                    effort=(efforts[k].copy() if efforts is not None else np.zeros(0))))]
                for topic, (pos, q) in pose_data.items():
                    msgs.append((topic, new("geometry_msgs/msg/PoseStamped", header=header,
                                            pose=new("geometry_msgs/msg/Pose",
                                                     position=_point(new, pos[k]),
                                                     orientation=_quaternion(new, q[k])))))
                for topic, f in forces.items():
                    msgs.append((topic, new("geometry_msgs/msg/WrenchStamped", header=header,
                                            wrench=new("geometry_msgs/msg/Wrench",
                                                       force=_vector(new, f[k])))))
                for topic, (segments, color) in cables.items():
                    markers = [new("visualization_msgs/msg/Marker", header=header,
                                   ns=topic[1:], id=i + 1, type=LINE_LIST, action=0,
                                   pose=identity, scale=scale, color=color,
                                   points=[_point(new, segments[k, i, 0]),
                                           _point(new, segments[k, i, 1])])
                               for i in range(m)]
                    msgs.append((topic, new("visualization_msgs/msg/MarkerArray",
                                            markers=markers)))
                for topic, msg in msgs:
                    writer.write(conns[topic], ns, M.serialize(msg))
                    counts[topic] += 1
        shutil.move(str(bag / "bag.mcap"), str(path))
    return counts


def _color(new, rgba):
    return new("std_msgs/msg/ColorRGBA", r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def _point(new, v):
    return new("geometry_msgs/msg/Point", x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _vector(new, v):
    return new("geometry_msgs/msg/Vector3", x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _quaternion(new, q):
    return new("geometry_msgs/msg/Quaternion", x=float(q[0]), y=float(q[1]), z=float(q[2]),
               w=float(q[3]))
