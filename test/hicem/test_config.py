"""HICEM parameters: the shipped file loads; missing or wrong values are named by their dotted key."""
import copy

import pytest

from locem_bridge.hicem.config import DEFAULT_PARAMS_FILE, HicemParams, flatten, load_params
from locem_bridge.hicem.errors import ConfigError

RAW = load_params(DEFAULT_PARAMS_FILE).raw


def test_shipped_parameters_and_blackboard_entries():
    p = HicemParams(copy.deepcopy(RAW))
    assert p.resume_policy["TAPE_LINE"] == "RESUME_TAPE_LINE" and p.hdict_synchronous == "FULL"
    bb = p.blackboard_entries()
    assert bb["cfg.taping.speed"] == RAW["taping"]["speed"]
    # the robot facts of the shipped robot file, derived with the tuning: today's numbers
    assert bb["robot.tools"] == ["taping_tool", "spray_gun", "sander"]
    assert (bb["robot.work.taping.base_standoff"], bb["robot.work.spray.base_standoff"],
            bb["robot.work.sand.base_standoff"]) == (1.05, 1.30, 1.00)
    assert bb["robot.work.spray.section_width"] == bb["robot.work.sand.section_width"] == 0.60
    assert (bb["robot.work.spray.lane_spacing"], bb["robot.work.sand.lane_spacing"]) == (0.15, 0.18)
    assert bb["robot.work.spray.tool_standoff"] == 0.30
    assert bb["robot.work.taping.z_range"] == [0.10, 2.00] and bb["robot.work.taping.segment_length"] == 1.20
    assert bb["robot.work.spray"]["tool"] == "spray_gun"
    assert bb["cfg.site.locations"]["home"] == bb["cfg.site.locations.home"]
    assert flatten({"a": {"b": 1}}) == {"cfg.a": {"b": 1}, "cfg.a.b": 1}


@pytest.mark.parametrize("path,value,msg", [
    (("hhlc", "tick_period_s"), "fast", "hhlc.tick_period_s: must be a finite number, got 'fast'"),
    (("hhlc", "tick_period_s"), -0.1, "hhlc.tick_period_s: -0.1 must be > 0"),
    (("datastore", "hdict_synchronous"), "OFF", "datastore.hdict_synchronous: 'OFF' is not allowed (allowed: FULL, NORMAL)"),
    (("hhlc", "resume_policy"), {"TAPE_LINE": ""}, "resume_policy.TAPE_LINE"),
    (("health", "modules"), [{"name": "x", "timeout": 1}], "unknown keys"),
    (("datastore", "prune"), [{"collection": "x", "age": 1}], "allowed keys"),
    (("spray", "lane_ratio"), 1.5, "spray.lane_ratio: 1.5 is out of range (allowed: > 0 and <= 1)"),
    (("sand", "lane_overrun"), 0.4, "sand.lane_overrun: 0.4 m leaves no strip within the sander's lateral reach"),
    (("sand", "lane_overrun"), "far", "sand.lane_overrun: must be a finite number, found 'far'"),
])
def test_bad_values_are_named(path, value, msg):
    raw = copy.deepcopy(RAW)
    raw[path[0]][path[1]] = value
    with pytest.raises(Exception) as ei:
        HicemParams(raw)
    assert msg in str(ei.value)


def test_missing_key_and_unreadable_file(tmp_path):
    raw = copy.deepcopy(RAW)
    del raw["locem"]["safe_commands"]
    with pytest.raises(ConfigError) as ei:
        HicemParams(raw)
    assert "locem.safe_commands: missing key" in str(ei.value)
    bad = tmp_path / "p.yaml"
    bad.write_text("hhlc: [unclosed")
    with pytest.raises(ConfigError) as ei:
        load_params(str(bad))
    assert "not valid YAML" in str(ei.value)
    with pytest.raises(ConfigError) as ei:
        load_params(str(tmp_path / "none.yaml"))
    assert str(ei.value) == "%s: cannot be read: No such file or directory" % (tmp_path / "none.yaml")


def test_a_bad_parameter_file_is_one_line_naming_the_file_and_the_key(tmp_path):
    import yaml
    raw = copy.deepcopy(RAW)
    raw["locem"]["command_timeout_s"] = "soon"
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError) as ei:
        load_params(str(path))
    assert str(ei.value) == "%s: locem.command_timeout_s: must be a finite number, got 'soon'" % path
    raw = copy.deepcopy(RAW)
    raw["health"]["modules"][0] = {"name": "x", "timeout": 1}
    path.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError) as ei:
        load_params(str(path))
    assert str(ei.value).startswith("%s: health.modules[0]: " % path) and "\n" not in str(ei.value)
    path.write_text("hhlc:\n  tick_period_s: [1,\n")
    with pytest.raises(ConfigError) as ei:
        load_params(str(path))
    assert str(ei.value).startswith("%s: line 3: not valid YAML" % path)
