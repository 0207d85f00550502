"""The platform file: validation with one-line errors naming the key; round trip."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from ropod_sysid.errors import InputError
from ropod_sysid.platform import load_platform, ropod_platform, save_platform

CONTRACT = """\
name: ropod
wheel_radius: 0.0525      # R_w
wheel_distance: 0.08      # d_w, between the two wheels of one unit
caster_offset: 0.01       # s_w, pivot axis to wheel axle
hub_com_offset: -0.005    # Delta_x, kinematic centre to unit centre of mass
torque_constant: 0.28     # k_t, wheel torque per motor current [Nm/A], gearing included
friction_tanh_gain: 10.0  # alpha in tanh(alpha * rate) of the Coulomb term
units:                    # one entry per smart-wheel unit
  - {name: "1", pivot: [0.21, 0.21]}
  - {name: "2", pivot: [-0.21, 0.21]}
  - {name: "3", pivot: [-0.21, -0.21]}
  - {name: "4", pivot: [0.21, -0.21]}
"""


def test_contract_example_loads(tmp_path):
    p = tmp_path / "ropod.yaml"
    p.write_text(CONTRACT)
    pf = load_platform(p)
    assert pf == ropod_platform()
    assert pf.unit_names == ["1", "2", "3", "4"]
    np.testing.assert_allclose(pf.positions, [[0.21, 0.21], [-0.21, 0.21], [-0.21, -0.21],
                                           [0.21, -0.21]])
    assert [u.s_cm for u in pf.units] == pytest.approx([0.015] * 4)
    save_platform(pf, tmp_path / "again.yaml")
    assert load_platform(tmp_path / "again.yaml") == pf


@pytest.mark.parametrize("edit, message", [
    (lambda d: d.pop("wheel_radius"), "missing key 'wheel_radius'"),
    (lambda d: d.update(wheel_radius=0), "'wheel_radius' must be > 0"),
    (lambda d: d.update(wheel_distance=-0.1), "'wheel_distance' must be > 0"),
    (lambda d: d.update(caster_offset=0), "'caster_offset' must be nonzero"),
    (lambda d: d.update(torque_constant=0), "'torque_constant' must be > 0"),
    (lambda d: d.update(torque_constant="a lot"), "'torque_constant' must be a number"),
    (lambda d: d.update(units=d["units"][:1]), "at least two needed"),
    (lambda d: d["units"][1].update(name="1"), "'units[1].name' '1' is used twice"),
    (lambda d: d["units"][2].update(name="front left"), "'units[2].name'"),
    (lambda d: d["units"][0].update(pivot=[0.1]), "'units[0].pivot' must be two"),
    (lambda d: d["units"][0].update(type="mecanum"),
     "'units[0].type' is 'mecanum'; known unit types: swivel, omni, steered"),
    (lambda d: d["units"][3].update(sign_left=2), "'units[3].sign_left' must be 1 or -1"),
])
def test_bad_platform_files(tmp_path, edit, message):
    data = yaml.safe_load(CONTRACT)
    edit(data)
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(data))
    with pytest.raises(InputError) as exc:
        load_platform(p)
    text = str(exc.value)
    assert message in text and str(p) in text and "\n" not in text


def test_missing_key_names_the_file_formats_doc(tmp_path):
    data = yaml.safe_load(CONTRACT)
    del data["torque_constant"]
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(data))
    with pytest.raises(InputError) as exc:
        load_platform(p)
    assert str(exc.value) == (f"{p}: missing key 'torque_constant'; add it (SI units, see "
                              "docs/file-formats.md)")


def test_not_yaml_and_missing_file(tmp_path):
    p = tmp_path / "broken.yaml"
    p.write_text("units: [\n")
    with pytest.raises(InputError, match="is not valid YAML"):
        load_platform(p)
    with pytest.raises(InputError, match="no such platform file"):
        load_platform(tmp_path / "absent.yaml")
    p.write_text("!!python/object/apply:os.system ['echo unsafe']\n")
    with pytest.raises(InputError):  # never loaded unsafely
        load_platform(p)


def test_written_files_get_ordinary_permissions(tmp_path):
    import os
    import stat

    save_platform(ropod_platform(), tmp_path / "p.yaml")
    umask = os.umask(0)
    os.umask(umask)
    mode = stat.S_IMODE((tmp_path / "p.yaml").stat().st_mode)
    assert mode == 0o666 & ~umask
    assert [p.name for p in tmp_path.iterdir()] == ["p.yaml"]  # no temporary left behind
