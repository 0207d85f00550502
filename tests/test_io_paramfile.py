"""Parameter files: contract layout, json/yaml/ros2 round trips, KELO layout, one-line errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml

from ropod_sysid.errors import InputError
from ropod_sysid.io.paramfile import (
    ParameterFile,
    read_parameter_file,
    read_truth_parameters,
    write_parameter_file,
)
from ropod_sysid.params import parameter_names
from ropod_sysid.platform import platform_from_dict, ropod_platform

PLATFORM = ropod_platform()


def make_pf(extras=None) -> ParameterFile:
    names = parameter_names(PLATFORM)
    params = {}
    for k, name in enumerate(names):
        params[name] = {"value": 0.1 * k + 1 / 3, "std": 0.01 * (k + 1) if k % 5 else None}
    params["Jzz_wh"]["combination"] = True
    return ParameterFile(
        platform="ropod", parameters=params, rms={"translation": 7.03, "rotation": 1.62},
        condition_number=1234.5, rank=27, samples=48000,
        extras={"friction": "per-wheel", "span_s": [0.0, 12.5], "input_delay_s": 0.01,
                "fixed": ["m_wh"]} if extras is None else extras,
    )


def bad(path) -> str:
    with pytest.raises(InputError) as exc:
        read_parameter_file(path)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(str(path))
    return msg


def strict_json(text: str):
    def refuse(token):
        raise AssertionError(f"non-standard JSON constant {token}")
    return json.loads(text, parse_constant=refuse)


# ------------------------------------------------------------------ layouts and round trips


def test_json_contract_layout(tmp_path):
    pf = make_pf()
    p = tmp_path / "params.json"
    write_parameter_file(pf, p, "json")
    text = p.read_text()
    assert text.startswith('{\n  "platform": "ropod",\n  "parameters": {\n    "m_b": {\n')
    data = strict_json(text)
    assert list(data) == ["platform", "parameters", "rms", "condition_number", "rank",
                          "samples", "friction", "span_s", "input_delay_s", "fixed"]
    assert list(data["parameters"]) == parameter_names(PLATFORM)
    assert data["parameters"]["m_b"] == {"value": 1 / 3, "std": None}
    assert data["parameters"]["Jzz_b"] == {"value": 0.1 + 1 / 3, "std": 0.02}
    assert data["parameters"]["Jzz_wh"]["combination"] is True
    assert data["rms"] == {"translation": 7.03, "rotation": 1.62}
    assert data["condition_number"] == 1234.5
    assert data["rank"] == 27 and data["samples"] == 48000
    assert [f.name for f in tmp_path.iterdir()] == ["params.json"]


@pytest.mark.parametrize("fmt", ["json", "yaml"])
def test_round_trip_json_yaml(tmp_path, fmt):
    pf = make_pf()
    p = tmp_path / f"params.{fmt}"
    write_parameter_file(pf, p, fmt)
    assert read_parameter_file(p) == pf


def test_yaml_is_the_same_mapping(tmp_path):
    pf = make_pf()
    write_parameter_file(pf, tmp_path / "a.json", "json")
    write_parameter_file(pf, tmp_path / "a.yaml", "yaml")
    assert yaml.safe_load((tmp_path / "a.yaml").read_text()) == \
        json.loads((tmp_path / "a.json").read_text())


def test_numpy_values_and_non_finite(tmp_path):
    pf = make_pf(extras={"null_space": np.array([[0.1, 0.2], [0.3, np.nan]]),
                         "span_s": (np.float64(1.5), np.float64(3.0))})
    pf.parameters["m_b"] = {"value": np.float64(35.1), "std": np.float64(np.inf)}
    pf.condition_number = math.inf
    pf.rank = np.int64(27)
    p = tmp_path / "params.json"
    write_parameter_file(pf, p)
    data = strict_json(p.read_text())
    assert data["condition_number"] is None
    assert data["parameters"]["m_b"] == {"value": 35.1, "std": None}
    assert data["null_space"] == [[0.1, 0.2], [0.3, None]]
    back = read_parameter_file(p)
    assert back.condition_number == math.inf
    assert back.parameters["m_b"]["std"] is None
    assert back.extras["span_s"] == [1.5, 3.0]


def test_ros2_layout(tmp_path):
    pf = make_pf()
    p = tmp_path / "ros.yaml"
    write_parameter_file(pf, p, "ros2", PLATFORM)
    data = yaml.safe_load(p.read_text())
    assert list(data) == ["ropod_dynamic_model"]
    params = data["ropod_dynamic_model"]["ros__parameters"]
    kin = params["base_kin_model"]
    expected = ["d_w", "s_w"] + [f"r_wL_SW{i}" for i in range(1, 5)] \
        + [f"r_wR_SW{i}" for i in range(1, 5)] + [f"xpos_SW{i}" for i in range(1, 5)] \
        + [f"ypos_SW{i}" for i in range(1, 5)] + ["unit_names"]
    assert list(kin) == expected
    assert kin["d_w"] == 0.08 and kin["s_w"] == 0.01
    assert kin["r_wL_SW3"] == kin["r_wR_SW3"] == 0.0525
    assert [kin[f"xpos_SW{i}"] for i in range(1, 5)] == [0.21, -0.21, -0.21, 0.21]
    assert [kin[f"ypos_SW{i}"] for i in range(1, 5)] == [0.21, 0.21, -0.21, -0.21]
    assert params["dyn_model"] == pf.values()
    assert params["dyn_model_std"] == {k: v for k, v in pf.stds().items() if v is not None}
    assert params["dyn_model_combination"] == ["Jzz_wh"]
    assert params["rms"] == {"translation": 7.03, "rotation": 1.62}
    assert params["condition_number"] == 1234.5 and params["rank"] == 27
    assert params["platform"] == "ropod" and params["samples"] == 48000


def test_ros2_round_trip_and_node_name(tmp_path):
    pf = make_pf()
    p = tmp_path / "ros.yaml"
    write_parameter_file(pf, p, "ros2", PLATFORM, node_name="base_controller")
    assert list(yaml.safe_load(p.read_text())) == ["base_controller"]
    assert read_parameter_file(p) == pf


def test_ros2_extras_ros_cannot_hold_become_json_text(tmp_path):
    pf = make_pf(extras={"null_space": [[1.0, 0.0], [0.0, 1.0]], "empty": [], "none": None,
                         "nested": {"a": 1, "b": [1, 2.5]}})
    p = tmp_path / "ros.yaml"
    write_parameter_file(pf, p, "ros2", PLATFORM)
    meta = yaml.safe_load(p.read_text())["ropod_dynamic_model"]["ros__parameters"]["metadata"]
    assert meta == {"null_space": "[[1.0, 0.0], [0.0, 1.0]]", "empty": "[]",
                    "nested": {"a": 1, "b": [1.0, 2.5]}}


def test_ros2_dotted_keys_read(tmp_path):
    p = tmp_path / "ros.yaml"
    p.write_text(yaml.safe_dump({"/**": {"ros__parameters": {
        "platform": "ropod", "dyn_model.m_b": 35.0, "dyn_model.fwv": -0.1,
        "dyn_model_std.m_b": 0.5, "rms.translation": 1.0, "rms.rotation": 2.0,
        "condition_number": 10.0, "rank": 2, "samples": 100}}}))
    pf = read_parameter_file(p)
    assert pf.parameters == {"m_b": {"value": 35.0, "std": 0.5},
                             "fwv": {"value": -0.1, "std": None}}
    assert pf.rms == {"translation": 1.0, "rotation": 2.0}


def test_kelo_layout(tmp_path):
    """A ROS 2 parameter file for kelo_tulip's platform_driver: num_wheels first (the driver
    reads it before the geometry), each wheel's ethercat_number from the platform file."""
    pf = make_pf()
    p = tmp_path / "kelo.yaml"
    entries = PLATFORM.to_dict()
    for k, unit in enumerate(entries["units"]):
        unit["ethercat_number"] = 3 + 2 * k
    platform = platform_from_dict(entries, "kelo-platform.yaml")
    write_parameter_file(pf, p, "kelo", platform)
    (node,) = yaml.safe_load(p.read_text()).items()
    assert node[0] == "platform_driver" and list(node[1]) == ["ros__parameters"]
    data = node[1]["ros__parameters"]
    assert list(data) == ["num_wheels", "wheel_distance", "wheel_diameter", "wheel0", "wheel1",
                          "wheel2", "wheel3", "dynamics"]
    assert data["wheel_distance"] == 0.08
    assert data["wheel_diameter"] == pytest.approx(0.105)
    assert data["num_wheels"] == 4
    assert data["wheel2"] == {"ethercat_number": 7, "x": -0.21, "y": -0.21, "a": 0.0}
    assert data["dynamics"] == pf.values()
    assert "KELO driver file" in bad(p)
    with pytest.raises(InputError) as err:
        write_parameter_file(pf, tmp_path / "k2.yaml", "kelo", PLATFORM)
    assert str(err.value) == (f"{PLATFORM.source}: the KELO format needs every unit's "
                              "'ethercat_number' (the drive's EtherCAT slave number); add it to "
                              "units 1, 2, 3, 4")


@pytest.mark.parametrize("fmt", ["ros2", "kelo"])
def test_ros2_kelo_need_platform(tmp_path, fmt):
    with pytest.raises(InputError, match=f"the {fmt} format includes the platform geometry"):
        write_parameter_file(make_pf(), tmp_path / "x.yaml", fmt)
    assert not list(tmp_path.iterdir())


def test_unknown_format(tmp_path):
    with pytest.raises(InputError, match="unknown parameter file format 'toml'"):
        write_parameter_file(make_pf(), tmp_path / "x.toml", "toml")


def test_extras_may_not_shadow_contract_keys(tmp_path):
    with pytest.raises(ValueError, match="rank"):
        write_parameter_file(make_pf(extras={"rank": 3}), tmp_path / "x.json")


# ------------------------------------------------------------------ bad parameter files


def write_json(tmp_path, data, name="params.json"):
    p = tmp_path / name
    p.write_text(json.dumps(data))
    return p


def contract(**changes):
    data = make_pf().to_dict()
    data.update(changes)
    return data


def test_missing_file(tmp_path):
    p = tmp_path / "nope.json"
    assert bad(p) == f"{p}: no such parameter file; check the path"


def test_empty_file(tmp_path):
    p = tmp_path / "params.yaml"
    p.write_text("  \n")
    assert bad(p) == f"{p}: the file is empty; expected a JSON or YAML mapping"


def test_invalid_json(tmp_path):
    p = tmp_path / "params.json"
    p.write_text('{\n  "platform": "ropod",\n  "rank": \n}')
    assert bad(p) == f"{p}: line 4: not valid JSON (Expecting value); fix the syntax"


def test_invalid_yaml(tmp_path):
    p = tmp_path / "params.yaml"
    p.write_text("platform: ropod\nrms: [1, 2\nrank: 3\n")
    assert bad(p).startswith(f"{p}: line ")
    assert bad(p).endswith("not valid YAML; fix the syntax")


def test_not_a_mapping(tmp_path):
    p = tmp_path / "params.yaml"
    p.write_text("- 1\n- 2\n")
    assert bad(p) == f"{p}: expected a mapping at the top level, got list"


def test_missing_key(tmp_path):
    data = contract()
    del data["rms"]
    p = write_json(tmp_path, data)
    assert bad(p) == (f"{p}: missing key 'rms'; a parameter file has platform, parameters, rms, "
                      "condition_number, rank, samples")


def test_value_not_a_number(tmp_path):
    data = contract()
    data["parameters"]["fwc_2R"]["value"] = "abc"
    p = write_json(tmp_path, data)
    assert bad(p) == f"{p}: key 'parameters.fwc_2R.value' must be a number, got 'abc'"


def test_std_not_a_number(tmp_path):
    data = contract()
    data["parameters"]["m_b"]["std"] = [1]
    assert "key 'parameters.m_b.std' must be a number, got [1]" in bad(write_json(tmp_path, data))


def test_entry_not_a_mapping(tmp_path):
    data = contract()
    data["parameters"]["m_b"] = 35.1
    assert "key 'parameters.m_b' must be a mapping with 'value' and 'std'" in \
        bad(write_json(tmp_path, data))


def test_rank_not_whole(tmp_path):
    p = write_json(tmp_path, contract(rank=2.5))
    assert bad(p) == f"{p}: key 'rank' must be a whole number, got 2.5"


def test_combination_not_bool(tmp_path):
    data = contract()
    data["parameters"]["m_b"]["combination"] = "yes"
    assert "key 'parameters.m_b.combination' must be true or false" in \
        bad(write_json(tmp_path, data))


def test_rms_missing_rotation(tmp_path):
    p = write_json(tmp_path, contract(rms={"translation": 1.0}))
    assert bad(p) == f"{p}: missing key 'rms.rotation'"


def test_ros2_bad_value(tmp_path):
    pf = make_pf()
    p = tmp_path / "ros.yaml"
    write_parameter_file(pf, p, "ros2", PLATFORM)
    data = yaml.safe_load(p.read_text())
    data["ropod_dynamic_model"]["ros__parameters"]["dyn_model"]["m_b"] = "heavy"
    p.write_text(yaml.safe_dump(data))
    assert bad(p) == (f"{p}: key 'ropod_dynamic_model.ros__parameters.dyn_model.m_b' must be a "
                      "number, got 'heavy'")
    del data["ropod_dynamic_model"]["ros__parameters"]["rank"]
    p.write_text(yaml.safe_dump(data))
    assert "missing key 'ropod_dynamic_model.ros__parameters.rank'" in bad(p)


# ------------------------------------------------------------------ truth parameters


def test_truth_flat_json(tmp_path):
    p = write_json(tmp_path, {"m_b": 35.1, "Jzz_b": 3, "fwv": -0.05, "fpc_3": 0.02,
                              "platform": "ropod"}, "truth.json")
    assert read_truth_parameters(p, PLATFORM) == {"m_b": 35.1, "Jzz_b": 3.0, "fwv": -0.05,
                                               "fpc_3": 0.02}


def test_truth_flat_yaml_exponent_without_dot(tmp_path):
    p = tmp_path / "truth.yaml"
    p.write_text("m_b: 35.1\nJrot_w: 1e-3\nfwc_1L: -2E-1\n")
    assert read_truth_parameters(p, PLATFORM) == {"m_b": 35.1, "Jrot_w": 0.001, "fwc_1L": -0.2}


@pytest.mark.parametrize("fmt", ["json", "yaml", "ros2"])
def test_truth_from_parameter_file(tmp_path, fmt):
    pf = make_pf()
    p = tmp_path / f"p.{fmt}"
    write_parameter_file(pf, p, fmt, PLATFORM)
    assert read_truth_parameters(p, PLATFORM) == pf.values()


def test_truth_non_number(tmp_path):
    p = write_json(tmp_path, {"m_b": 35.1, "Jzz_b": "3.8 kg m2"}, "truth.json")
    with pytest.raises(InputError) as exc:
        read_truth_parameters(p, PLATFORM)
    assert str(exc.value) == f"{p}: key 'Jzz_b' must be a number, got '3.8 kg m2'"
    p = write_json(tmp_path, {"m_b": None}, "truth.json")
    with pytest.raises(InputError, match="key 'm_b' must be a number, got None"):
        read_truth_parameters(p, PLATFORM)
    p = write_json(tmp_path, {"parameters": {"m_b": {"value": True}}}, "truth.json")
    with pytest.raises(InputError, match=r"key 'parameters.m_b.value' must be a number"):
        read_truth_parameters(p, PLATFORM)


def test_truth_unknown_name(tmp_path):
    p = write_json(tmp_path, {"m_b": 35.1, "fwv_5L": 0.1}, "truth.json")
    with pytest.raises(InputError) as exc:
        read_truth_parameters(p, PLATFORM)
    msg = str(exc.value)
    assert msg.startswith(f"{p}: unknown parameter 'fwv_5L'; known names are m_b, Jzz_b")
    assert "for units 1, 2, 3, 4" in msg


def test_truth_not_finite(tmp_path):
    p = tmp_path / "truth.yaml"
    p.write_text("m_b: .inf\n")
    with pytest.raises(InputError, match="key 'm_b' must be a finite number"):
        read_truth_parameters(p, PLATFORM)


def test_truth_missing_file(tmp_path):
    with pytest.raises(InputError, match="no such parameter file"):
        read_truth_parameters(tmp_path / "truth.json", PLATFORM)
