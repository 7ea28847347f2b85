"""The ROS adapters' parameter helper: a typed default types the value (with a one-line error naming the
parameter), list parameters come as YAML lists or comma texts, and the package folder holds what the nodes read.
(``param`` itself reads the master: every rostest suite's nodes go through it.)"""
import os

import pytest

from locem_bridge.ros.params import as_list, package_share, typed


@pytest.mark.parametrize("value, default, expected", [
    ("8088", 8088, 8088), (8088.0, 1, 8088), (3, 5.0, 3.0), ("0.25", 1.0, 0.25), ("true", False, True),
    ("No", True, False), (1, False, True), (True, "", "True"), ({"a": 1}, {}, {"a": 1}), ([1, 2], None, [1, 2]),
    ("web", "auto", "web"),
])
def test_a_typed_default_types_the_value(value, default, expected):
    got = typed("~x", value, default)
    assert got == expected and type(got) is type(expected)


@pytest.mark.parametrize("value, default, message", [
    ("eighty", 8088, "~port must be an integer, got 'eighty'"),
    (80.5, 8088, "~port must be an integer, got 80.5"),
    (True, 8088, "~port must be an integer, got True"),
    ("fast", 1.0, "~port must be a number, got 'fast'"),
    ("maybe", False, "~port must be true or false, got 'maybe'"),
])
def test_a_value_of_the_wrong_type_is_refused_naming_the_parameter(value, default, message):
    with pytest.raises(ValueError) as err:
        typed("~port", value, default)
    assert str(err.value) == message


def test_list_parameters_as_yaml_lists_or_comma_texts():
    assert as_list("arm, compressor,,base ") == ["arm", "compressor", "base"]
    assert as_list(["wall_1_joint_2", 3]) == ["wall_1_joint_2", "3"]
    assert as_list("") == [] and as_list(None) == []


def test_the_package_folder_holds_what_the_nodes_read():
    share = package_share()
    for part in ("package.xml", "config/robots/rbkairos_ur10e.yaml", "config/jobs/plasterboard.yaml", "trees",
                 "ontologies", "launch"):
        assert os.path.exists(os.path.join(share, part)), part
