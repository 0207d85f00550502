"""ROS 1 bags, rosbag2 recordings (sqlite3 and MCAP storage) and ROS 1 MCAP files: written here
with ``rosbags`` and ``mcap`` as other tools write them, read back bit-identically to the log."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.writer import Writer as McapWriter
from rosbags.rosbag1 import Writer as Bag1Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Bag2Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from ropod_sysid.cli.main import main
from ropod_sysid.errors import InputError
from ropod_sysid.fit import FitOptions, fit_files
from ropod_sysid.io import read_log
from ropod_sysid.io.mcapwrite import CONTRACT_MSGDEF, CONTRACT_ROS2_SCHEMA, CONTRACT_TOPIC
from ropod_sysid.platform import save_platform

from .swivel_arrays import C, D, P

T0_NS = 1_700_000_000_000_000_000  # wall-clock receive times of the recording


def store():
    ts = get_typestore(Stores.EMPTY)
    ts.register(get_types_from_msg(CONTRACT_MSGDEF, CONTRACT_ROS2_SCHEMA))
    return ts


def messages(log, ts):
    msg = ts.types[CONTRACT_ROS2_SCHEMA]
    d, p, c = D(log), P(log), C(log)
    for k in range(log.n_samples):
        yield T0_NS + int(round(log.t[k] * 1e9)), msg(
            t=float(log.t[k]), units=list(log.units), delta=d[k].copy(), phi_l=p[k, :, 0].copy(),
            phi_r=p[k, :, 1].copy(), cur_l=c[k, :, 0].copy(), cur_r=c[k, :, 1].copy(),
            pose=np.zeros(0))


def write_recording(kind: str, path: Path, log) -> Path:
    ts = store()
    if kind == "ros1":
        with Bag1Writer(path) as w:
            conn = w.add_connection(CONTRACT_TOPIC, CONTRACT_ROS2_SCHEMA, typestore=ts)
            for t, m in messages(log, ts):
                w.write(conn, t, ts.serialize_ros1(m, CONTRACT_ROS2_SCHEMA))
    elif kind == "ros1-mcap":
        with open(path, "wb") as f:
            w = McapWriter(f)
            w.start(profile="ros1")
            sid = w.register_schema("ropod_sysid_msgs/LogSample", "ros1msg",
                                    CONTRACT_MSGDEF.encode())
            cid = w.register_channel(CONTRACT_TOPIC, "ros1", sid)
            for k, (t, m) in enumerate(messages(log, ts)):
                w.add_message(cid, t, ts.serialize_ros1(m, CONTRACT_ROS2_SCHEMA), t, k)
            w.finish()
    else:
        plugin = StoragePlugin.SQLITE3 if kind == "rosbag2-sqlite3" else StoragePlugin.MCAP
        with Bag2Writer(path, version=9, storage_plugin=plugin) as w:
            conn = w.add_connection(CONTRACT_TOPIC, CONTRACT_ROS2_SCHEMA, typestore=ts)
            for t, m in messages(log, ts):
                w.write(conn, t, ts.serialize_cdr(m, CONTRACT_ROS2_SCHEMA))
    return path


KINDS = {"ros1": "run.bag", "rosbag2-sqlite3": "run_sqlite", "rosbag2-mcap": "run_mcap",
         "ros1-mcap": "run_ros1.mcap"}


@pytest.mark.parametrize("kind", KINDS)
def test_recordings_read_bit_identically(tmp_path, off_square, runs_off_square, kind) -> None:
    log = runs_off_square[0].log
    path = write_recording(kind, tmp_path / KINDS[kind], log)
    back = read_log(path, off_square)
    for name in ("t", "angles", "currents"):
        assert np.array_equal(getattr(back, name), getattr(log, name)), name
    assert back.pose is None and back.units == log.units


def test_fit_of_a_rosbag2_recording_equals_the_csv_fit(tmp_path, off_square,
                                                      runs_off_square) -> None:
    from ropod_sysid.io import write_log

    logs = [r.log for r in runs_off_square[:2]]
    bags = [write_recording("rosbag2-sqlite3", tmp_path / f"b{k}", lg)
            for k, lg in enumerate(logs)]
    csvs = []
    for k, lg in enumerate(logs):
        csvs.append(tmp_path / f"c{k}.csv")
        write_log(lg, csvs[-1])
    a = fit_files(bags, off_square, FitOptions())
    b = fit_files(csvs, off_square, FitOptions())
    np.testing.assert_array_equal(a.solution.values, b.solution.values)


def test_cli_reads_recordings_and_refuses_to_write_bags(tmp_path, off_square,
                                                       runs_off_square) -> None:
    save_platform(off_square, tmp_path / "p.yaml")
    bag = write_recording("rosbag2-mcap", tmp_path / "rec", runs_off_square[0].log)
    runner = CliRunner()
    r = runner.invoke(main, ["inspect", str(bag), "--platform", str(tmp_path / "p.yaml")])
    assert r.exit_code == 0 and f"samples    {runs_off_square[0].log.n_samples}" in r.output
    r = runner.invoke(main, ["convert", str(bag), str(tmp_path / "out.csv"), "--platform",
                             str(tmp_path / "p.yaml"), "--quiet"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(main, ["convert", str(tmp_path / "out.csv"), str(tmp_path / "x.bag"),
                             "--platform", str(tmp_path / "p.yaml")])
    assert r.exit_code == 2 and r.output.strip() == (
        f"error: {tmp_path / 'x.bag'}: ropod-sysid reads ROS bags but does not write them; "
        "give a .mcap name (ROS 2 tools replay it) or .csv")
    assert not (tmp_path / "x.bag").exists()
    (tmp_path / "plain").mkdir()
    r = runner.invoke(main, ["inspect", str(tmp_path / "plain"), "--platform",
                             str(tmp_path / "p.yaml")])
    assert r.exit_code == 2 and r.output.strip() == (
        f"error: {tmp_path / 'plain'}: is a directory without a rosbag2 metadata.yaml; give a "
        "log file (.csv, .csv.gz, .mcap, .bag) or a rosbag2 recording")


def test_damaged_and_empty_recordings_are_one_line_errors(tmp_path, off_square,
                                                         runs_off_square) -> None:
    bag = write_recording("ros1", tmp_path / "run.bag", runs_off_square[0].log)
    data = bag.read_bytes()
    (tmp_path / "cut.bag").write_bytes(data[: len(data) // 3])
    with pytest.raises(InputError) as err:
        read_log(tmp_path / "cut.bag", off_square)
    assert str(err.value).startswith(f"{tmp_path / 'cut.bag'}: ") and "\n" not in str(err.value)
    (tmp_path / "junk.bag").write_bytes(b"not a bag at all")
    with pytest.raises(InputError, match=r"junk.bag: cannot read the recording .*is it a ROS 1 "
                                         "bag or a rosbag2 directory"):
        read_log(tmp_path / "junk.bag", off_square)


def test_shipped_message_definition_is_the_one_written(tmp_path, off_square,
                                                     runs_off_square) -> None:
    """msg/ropod_sysid_msgs holds the writer's message, and a written ROS 2 MCAP file carries
    it, wall-clock log times and the publisher's QoS for ros2 bag play."""
    import dataclasses

    import yaml
    from mcap.reader import make_reader

    from ropod_sysid.io.mcapwrite import write_mcap_log

    shipped = Path(__file__).resolve().parents[1] / "msg" / "ropod_sysid_msgs" / "msg"
    assert (shipped / "LogSample.msg").read_text() == CONTRACT_MSGDEF
    log = runs_off_square[0].log
    wall = dataclasses.replace(log, t=log.t + 1.7e9)
    write_mcap_log(wall, tmp_path / "run.mcap", "ros2")
    with open(tmp_path / "run.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        (channel,) = summary.channels.values()
        first = next(reader.iter_messages())[2]
    assert summary.schemas[channel.schema_id].data.decode() == CONTRACT_MSGDEF
    qos = yaml.safe_load(channel.metadata["offered_qos_profiles"])
    assert qos[0]["reliability"] == 1 and qos[0]["depth"] == 10
    assert first.log_time == round(wall.t[0] * 1e9)  # the date is kept


KELO_DRIVE = """uint16  status1
uint16  status2
uint64  sensor_ts
uint64  setpoint_ts
float32 encoder_1
float32 velocity_1
float32 current_1_d
float32 current_1_q
float32 encoder_2
float32 velocity_2
float32 current_2_d
float32 current_2_q
float32 encoder_pivot
float32 velocity_pivot
float32 voltage_bus
"""  # (kelo_tulip's KeloDriveInput has more fields; these are the ones the reader uses)
KELO_DRIVES = ("std_msgs/Header header\nkelo_tulip/KeloDriveInput[] wheels\n" + "=" * 80
               + "\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
               + "=" * 80 + "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
               + "=" * 80 + "\nMSG: kelo_tulip/KeloDriveInput\n" + KELO_DRIVE)


def test_kelo_drive_messages_read_like_the_smart_wheel_layout(tmp_path) -> None:
    """The KELO driver's KeloDrivesInput (a wheels[] array after a header, float32 fields) in
    a ROS 2 MCAP file and in a rosbag2 recording: read with the platform's per-unit motor
    mapping, signs and pivot offsets, like the smart-wheel layout."""
    from mcap_ros2._dynamic import serialize_dynamic

    from ropod_sysid.io.mcapwrite import new_writer
    from ropod_sysid.io.smartwheel import raw_frames
    from ropod_sysid.params import thesis_fixed_masses
    from ropod_sysid.platform import load_platform
    from ropod_sysid.simulate import simulate

    from .conftest import four_variants

    pf = load_platform(Path(__file__).resolve().parents[1] / "datasets" / "smartwheel"
                       / "platform.yaml")  # swapped motors, a flipped sign, pivot offsets
    (run,) = simulate(pf, thesis_fixed_masses(pf.unit_names), four_variants(2.0)[:1],
                      rate=100.0)
    fields, recv = raw_frames(run.log, pf)
    name = "kelo_tulip/msg/KeloDrivesInput"
    encode = serialize_dynamic(name, KELO_DRIVES)[name]
    names = [ln.split()[1] for ln in KELO_DRIVE.splitlines() if ln.strip()]
    msgs = []
    for k in range(len(recv)):
        wheels = [{f: (int(fields[f][k, i]) if f in ("status1", "status2", "sensor_ts",
                                                     "setpoint_ts") else float(fields[f][k, i]))
                   for f in names} for i in range(pf.n_units)]
        msgs.append((int(recv[k]), encode({"header": {"stamp": {"sec": 0, "nanosec": 0},
                                                      "frame_id": ""}, "wheels": wheels})))
    with open(tmp_path / "kelo.mcap", "wb") as f:
        w = new_writer(f, profile="ros2")
        sid = w.register_schema(name, "ros2msg", KELO_DRIVES.encode())
        cid = w.register_channel("/kelo_drives", "cdr", sid)
        for k, (t, payload) in enumerate(msgs):
            w.add_message(cid, t, payload, t, k)
        w.finish()
    ts = get_typestore(Stores.ROS2_HUMBLE)
    ts.register(get_types_from_msg(KELO_DRIVE, "kelo_tulip/msg/KeloDriveInput"))
    ts.register(get_types_from_msg("std_msgs/Header header\nkelo_tulip/KeloDriveInput[] wheels",
                                   name))
    with Bag2Writer(tmp_path / "kelo_bag", version=9) as w:
        conn = w.add_connection("/kelo_drives", name, typestore=ts)
        for t, payload in msgs:
            w.write(conn, t, payload)
    for path in (tmp_path / "kelo.mcap", tmp_path / "kelo_bag"):
        back = read_log(path, pf)
        assert back.n_samples == run.log.n_samples
        np.testing.assert_allclose(P(back) - P(back)[0], P(run.log) - P(run.log)[0],
                                   atol=1e-4 * np.abs(P(run.log)).max())  # float32 angles
        np.testing.assert_allclose(np.cos(D(back)), np.cos(D(run.log)), atol=1e-6)
        np.testing.assert_allclose(C(back), C(run.log), rtol=1e-6, atol=1e-6)


JOINT_STATE = ("std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
               "float64[] effort\n" + "=" * 80 + "\nMSG: std_msgs/Header\n"
               "builtin_interfaces/Time stamp\nstring frame_id\n" + "=" * 80
               + "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n")


def test_any_robots_joint_states_through_the_platform_files_mapping(tmp_path) -> None:
    """sensor_msgs/JointState of a 5DPO robot (joints named by the robot, in its own order,
    with a joint the platform does not use; effort as torque): read through the platform
    file's joint_state mapping, in MCAP and rosbag2, and refused without it in one line."""
    import yaml
    from mcap_ros2._dynamic import serialize_dynamic

    from ropod_sysid.io.mcapwrite import new_writer
    from ropod_sysid.params import typical_parameters
    from ropod_sysid.platform import load_platform, platform_from_dict
    from ropod_sysid.simulate import Controller, simulate

    from .conftest import four_variants
    from .test_omni import PLATFORM

    data = yaml.safe_load(PLATFORM.read_text())
    data["joint_state"] = {"channels": {
        **{f"phi_{u}": {"joint": f"wheel_{u}_joint", "field": "position"} for u in "0123"},
        **{f"cur_{u}": {"joint": f"wheel_{u}_joint", "field": "effort", "effort_is_torque": True}
           for u in "0123"}}}
    pf = platform_from_dict(data, "5dpo-js.yaml")
    assert platform_from_dict(pf.to_dict(), "again").joint_state == pf.joint_state
    (run,) = simulate(pf, typical_parameters(pf, 2.34, 0.0228), four_variants(2.0)[:1],
                      rate=100.0, controller=Controller(0.02, 0.4, 0.6))
    log = run.log
    tau = log.currents * pf.torque_constants()
    names = ["lidar_tilt", "wheel_2_joint", "wheel_0_joint", "wheel_3_joint", "wheel_1_joint"]
    order = [None, 2, 0, 3, 1]
    name = "sensor_msgs/msg/JointState"
    encode = serialize_dynamic(name, JOINT_STATE)[name]
    t0 = 1_700_000_000
    msgs = []
    for k in range(log.n_samples):
        sec = t0 + int(np.floor(log.t[k]))
        nsec = int(round((log.t[k] - np.floor(log.t[k])) * 1e9))
        pos = [0.1 if j is None else float(log.angles[k, j]) for j in order]
        eff = [0.0 if j is None else float(tau[k, j]) for j in order]
        msgs.append((sec * 10**9 + nsec, encode({
            "header": {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": ""},
            "name": names, "position": pos, "velocity": [0.0] * 5, "effort": eff})))
    with open(tmp_path / "js.mcap", "wb") as f:
        w = new_writer(f, profile="ros2")
        sid = w.register_schema(name, "ros2msg", JOINT_STATE.encode())
        cid = w.register_channel("/joint_states", "cdr", sid)
        for k, (t, payload) in enumerate(msgs):
            w.add_message(cid, t, payload, t, k)
        w.finish()
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Bag2Writer(tmp_path / "js_bag", version=9) as w:
        conn = w.add_connection("/joint_states", name, typestore=ts)
        for t, payload in msgs:
            w.write(conn, t, payload)
    for path in (tmp_path / "js.mcap", tmp_path / "js_bag"):
        back = read_log(path, pf)
        np.testing.assert_array_equal(back.angles, log.angles)
        np.testing.assert_allclose(back.currents, log.currents, rtol=1e-14, atol=1e-17)
        np.testing.assert_allclose(back.t - t0, log.t, atol=5e-7)  # (float64 at 1.7e9 s)
    with pytest.raises(InputError) as err:
        read_log(tmp_path / "js.mcap", load_platform(PLATFORM))
    assert str(err.value) == (f"{tmp_path / 'js.mcap'}: the log is sensor_msgs/msg/JointState "
                              "on /joint_states; map its joints to the unit channels in the "
                              "platform file's 'joint_state' (see docs/file-formats.md)")
    data["joint_state"]["channels"].pop("cur_3")
    with pytest.raises(InputError, match=r"^p.yaml: 'joint_state'.channels lacks cur_3; map "
                                         "every column of the log$"):
        platform_from_dict(data, "p.yaml")
