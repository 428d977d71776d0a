"""`cdpm export LOG --mcap` (issue 32, "Logs people open"): a ROS 2 bag in MCAP storage,
read back with the `mcap` package's reader (not rosbags, which wrote it), its messages decoded
with the schema stored in the file (mcap_ros2's decoder; rosbags' deserializer where that is
not installed) and compared with the log; the cable markers against the kinematics written
out here from the log's reels, attachments and pose."""

import numpy as np
import pytest

from cdpm_drake.cli import main
from helpers_synthetic_log import synthetic_log

pytest.importorskip("rosbags")
mcap_reader = pytest.importorskip("mcap.reader")

TOPICS = {"/reels/joint_states": "sensor_msgs/msg/JointState",
          "/platform/pose": "geometry_msgs/msg/PoseStamped",
          "/platform/pose_true": "geometry_msgs/msg/PoseStamped",
          "/platform/hand_wrench": "geometry_msgs/msg/WrenchStamped",
          "/platform/interference_wrench": "geometry_msgs/msg/WrenchStamped",
          "/platform/desired_wrench": "geometry_msgs/msg/WrenchStamped",
          "/cables": "visualization_msgs/msg/MarkerArray",
          "/cables_true": "visualization_msgs/msg/MarkerArray"}


def _decoder_factories():
    try:
        from mcap_ros2.decoder import DecoderFactory
    except ImportError:
        return []
    return [DecoderFactory()]


def read_bag(path):
    """(summary, {topic: [(log_time ns, decoded message)]}) of an .mcap file."""
    factories = _decoder_factories()
    with open(path, "rb") as f:
        reader = mcap_reader.make_reader(f, decoder_factories=factories)
        summary = reader.get_summary()
        messages = {}
        if factories:
            for _, channel, message, decoded in reader.iter_decoded_messages():
                messages.setdefault(channel.topic, []).append((message.log_time, decoded))
        else:  # rosbags' own deserializer, by the schema name stored in the file
            from rosbags.typesys import Stores, get_typestore

            store = get_typestore(Stores.ROS2_JAZZY)
            for schema, channel, message in reader.iter_messages():
                messages.setdefault(channel.topic, []).append(
                    (message.log_time, store.deserialize_cdr(message.data, schema.name)))
    return summary, messages


def rotation(roll, pitch, yaw):
    """R = Rz(yaw) Ry(pitch) Rx(roll) (docs/LOG_FORMAT.md), written out as the product."""
    cr, sr, cp, sp, cy, sy = (np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch),
                              np.cos(yaw), np.sin(yaw))
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def quaternion_matrix(q):
    """The rotation of a unit quaternion (x, y, z, w), by the textbook formula."""
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _xyz(v):
    return np.array([v.x, v.y, v.z])


def _full_pose_dynamic_log(duration=0.05):
    """The synthetic log with what a full-pose run on the dynamic plant adds: the estimated
    and true orientation (a few degrees, changing every tick), the true position, the true
    and the measured tensions (different numbers, so that the effort shows which one)."""
    log = synthetic_log(duration=duration)
    T, m = len(log["time"]), 7
    s = np.linspace(0.0, 1.0, T)
    log["rpy"] = np.stack([0.05 * s, -0.03 * s, 0.08 * s], axis=1)
    log["rpy_true"] = log["rpy"] + 0.01
    log["p_true"] = log["p"] + np.array([0.002, -0.001, 0.003])
    log["tensions"] = 20.0 + np.arange(T * m, dtype=float).reshape(T, m) / 10.0
    log["tension_measured"] = log["tensions"] + 0.5
    return log


def test_every_topic_has_one_message_per_tick_with_the_log_s_values(tmp_path):
    from cdpm_drake.views.log_mcap import write_log_mcap

    log = _full_pose_dynamic_log()
    T, m = len(log["time"]), 7
    path = tmp_path / "log.mcap"
    counts = write_log_mcap(log, path)
    assert counts == dict.fromkeys(TOPICS, T)
    assert [p.name for p in tmp_path.iterdir()] == ["log.mcap"]  # no bag folder left
    summary, messages = read_bag(path)
    # The reader's own statistics: one message per tick on every topic, the types named.
    by_channel = summary.statistics.channel_message_counts
    channels = {c.topic: c for c in summary.channels.values()}
    assert set(channels) == set(TOPICS)
    for topic, msgtype in TOPICS.items():
        assert by_channel[channels[topic].id] == T, topic
        assert summary.schemas[channels[topic].schema_id].name == msgtype
        assert channels[topic].message_encoding == "cdr"
    assert summary.statistics.message_start_time == 0
    assert {c.compression for c in summary.chunk_indexes} == {"zstd"}  # chunks compressed
    # The rosbag2 metadata is inside the file (ros2 bag reads it from there).
    assert "rosbag2" in {i.name for i in summary.metadata_indexes}
    # Stamps: the log's time from 0, in ns, bag and header alike.
    stamps = np.round(log["time"] * 1e9).astype(np.int64)
    for topic in TOPICS:
        assert [t for t, _ in messages[topic]] == stamps.tolist(), topic
    for k in (0, T // 2, T - 1):
        joints = messages["/reels/joint_states"][k][1]
        assert list(joints.name) == [f"cable_{i}" for i in range(1, m + 1)]
        assert joints.header.frame_id == "base"
        assert joints.header.stamp.sec * 10**9 + joints.header.stamp.nanosec == stamps[k]
        np.testing.assert_array_equal(joints.position, log["lengths"][k])
        np.testing.assert_array_equal(joints.velocity, log["reel_velocity"][k])
        np.testing.assert_array_equal(joints.effort, log["tension_measured"][k])
        for topic, (pk, rk) in {"/platform/pose": ("p", "rpy"),
                                "/platform/pose_true": ("p_true", "rpy_true")}.items():
            pose = messages[topic][k][1].pose
            np.testing.assert_array_equal(_xyz(pose.position), log[pk][k])
            q = [pose.orientation.x, pose.orientation.y, pose.orientation.z,
                 pose.orientation.w]
            np.testing.assert_allclose(quaternion_matrix(q), rotation(*log[rk][k]),
                                       atol=1e-12)
        for topic, key in {"/platform/hand_wrench": "F_H",
                           "/platform/interference_wrench": "F_int",
                           "/platform/desired_wrench": "F_d"}.items():
            wrench = messages[topic][k][1]
            assert wrench.header.frame_id == "base"
            np.testing.assert_array_equal(_xyz(wrench.wrench.force), log[key][k])
            np.testing.assert_array_equal(_xyz(wrench.wrench.torque), np.zeros(3))
        # The cables at the estimated and at the true pose: reel a_i to p + R b_i.
        for topic, (pk, rk) in {"/cables": ("p", "rpy"),
                                "/cables_true": ("p_true", "rpy_true")}.items():
            markers = messages[topic][k][1].markers
            assert [mk.id for mk in markers] == list(range(1, m + 1))
            R = rotation(*log[rk][k])
            for mk in markers:
                i = mk.id - 1
                assert mk.type == 5 and mk.action == 0  # LINE_LIST, ADD
                assert mk.header.frame_id == "base" and mk.ns == topic[1:]
                assert len(mk.points) == 2 and mk.scale.x > 0 and mk.color.a == 1.0
                np.testing.assert_allclose(_xyz(mk.points[0]), log["reels"][i], atol=1e-12)
                np.testing.assert_allclose(_xyz(mk.points[1]),
                                           log[pk][k] + R @ log["attachments"][i],
                                           atol=1e-12)


def test_joint_effort_falls_back_on_the_true_tensions_then_on_none(tmp_path):
    from cdpm_drake.views.log_mcap import write_log_mcap

    log = _full_pose_dynamic_log(duration=0.01)
    log["tension_measured"][:] = np.nan  # the kinematic plant's: no sensor
    write_log_mcap(log, tmp_path / "a.mcap")
    _, messages = read_bag(tmp_path / "a.mcap")
    np.testing.assert_array_equal(messages["/reels/joint_states"][2][1].effort,
                                  log["tensions"][2])
    plain = synthetic_log(duration=0.01)  # the kinematic plant: no tensions at all
    counts = write_log_mcap(plain, tmp_path / "b.mcap")
    assert "/platform/pose_true" not in counts and "/cables_true" not in counts
    _, messages = read_bag(tmp_path / "b.mcap")
    assert len(messages["/reels/joint_states"][0][1].effort) == 0
    # Without rpy the pose is the translating platform's: identity orientation, and the
    # markers end at p + b_i.
    pose = messages["/platform/pose"][1][1].pose
    assert (pose.orientation.x, pose.orientation.y, pose.orientation.z,
            pose.orientation.w) == (0.0, 0.0, 0.0, 1.0)
    end = messages["/cables"][1][1].markers[6].points[1]
    np.testing.assert_allclose(_xyz(end), plain["p"][1] + plain["attachments"][6], atol=1e-12)


def test_cdpm_export_mcap_of_a_run(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["simulate", "exp2_interaction", "--duration", "0.02", "--out", str(run),
                 "--no-progress", "--scenario-text", "{plant: !DynamicReels {}}"]) == 0
    capsys.readouterr()
    assert main(["export", str(run), "--mcap"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"mcap: {run / 'log.mcap'} (a ROS 2 bag, 8 topics, 11 messages each")
    summary, messages = read_bag(run / "log.mcap")
    with np.load(run / "log.npz") as data:
        log = {k: data[k] for k in data.files}
    assert set(summary.statistics.channel_message_counts.values()) == {11}
    k = 7
    np.testing.assert_array_equal(_xyz(messages["/platform/pose_true"][k][1].pose.position),
                                  log["p_true"][k])
    np.testing.assert_array_equal(
        _xyz(messages["/platform/desired_wrench"][k][1].wrench.force), log["F_d"][k])
    joints = messages["/reels/joint_states"][k][1]
    np.testing.assert_array_equal(joints.position, log["lengths"][k])
    # The rule of docs/viewing.md: the measured tension where the log holds numbers there
    # (issue 31's sensor), else the plant's true one.
    measured = log.get("tension_measured")
    effort = (measured if measured is not None and np.isfinite(measured).any()
              else log["tensions"])
    np.testing.assert_array_equal(joints.effort, effort[k])
    # The true cable of cable 5 ends where the plant's true pose puts its attachment.
    end = messages["/cables_true"][k][1].markers[4].points[1]
    np.testing.assert_allclose(
        _xyz(end), log["p_true"][k] + rotation(*log["rpy_true"][k]) @ log["attachments"][4],
        atol=1e-12)
    # Elsewhere with --out; an unwritable --out is bad usage naming the option.
    assert main(["export", str(run), "--mcap", "--out", str(tmp_path / "o" / "b.mcap")]) == 0
    assert (tmp_path / "o" / "b.mcap").is_file()
    capsys.readouterr()
    (tmp_path / "FILE").write_text("")
    assert main(["export", str(run), "--mcap", "--out", str(tmp_path / "FILE" / "b.mcap")]) == 2
    assert "--out's folder" in capsys.readouterr().err


def test_a_log_missing_a_key_the_bag_needs_is_refused_by_name(tmp_path, capsys):
    log = synthetic_log(duration=0.01)
    del log["reel_velocity"]
    np.savez(tmp_path / "log.npz", **log)
    # load_log itself requires reel_velocity (LOG_KEYS): the refusal names it either way.
    assert main(["export", str(tmp_path), "--mcap", "--out", str(tmp_path / "o" / "x.mcap")]) == 1
    err = capsys.readouterr().err
    assert "'reel_velocity'" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()
    # A per-tick key of the wrong length: named, with the rows expected.
    from cdpm_drake.views.log_mcap import McapExportError, check_mcap_keys

    log = synthetic_log(duration=0.01)
    log["F_int"] = log["F_int"][:-1]
    with pytest.raises(McapExportError, match=r"'F_int' has shape \(5, 3\).*\(6, 3\)"):
        check_mcap_keys(log)


def test_without_rosbags_the_error_names_the_install_command(tmp_path, capsys, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "rosbags" else real(name, *a))
    log = synthetic_log(duration=0.01)
    np.savez(tmp_path / "log.npz", **log)
    assert main(["export", str(tmp_path), "--mcap"]) == 1
    err = capsys.readouterr().err
    assert "rosbags" in err and "pip install 'cdpm_drake[export]'" in err
    assert not (tmp_path / "log.mcap").exists()
