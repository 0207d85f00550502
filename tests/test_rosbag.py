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
from ropod_sysid.io.mcaplog import CONTRACT_MSGDEF, CONTRACT_ROS2_SCHEMA, CONTRACT_TOPIC
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

    from ropod_sysid.io.mcaplog import write_mcap_log

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
