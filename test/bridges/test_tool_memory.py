"""LOCEM's memory of the mounted tool on disk (``~tool_file``): what a LOCEM started after a power loss (no ROS
master to ask) knows is on the flange."""
import os

from locem_bridge.bridges.tool_memory import read_tool_file, write_tool_file


def test_the_kept_tool_reads_back_and_a_new_one_replaces_it_whole(tmp_path):
    path = str(tmp_path / "state" / "run_locem_tool.json")
    assert read_tool_file(path) == ""                         # nothing kept yet: no tool
    write_tool_file(path, "spray_gun")
    assert read_tool_file(path) == "spray_gun"
    write_tool_file(path, "")                                  # put back in the rack: nothing on the flange
    assert read_tool_file(path) == "" and not os.path.exists(path + ".tmp")


def test_a_file_that_cannot_be_read_means_no_tool(tmp_path):
    path = tmp_path / "tool.json"
    for text in ("{half", "[1, 2]", '{"tool": 3}'):
        path.write_text(text)
        assert read_tool_file(str(path)) == ""
