"""The package's own data files: package.xml is a valid catkin manifest, launch files are documented."""
import glob
import os
import xml.etree.ElementTree as ET

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAUNCH_FILES = sorted(glob.glob(os.path.join(REPO, "launch", "*.launch")))


def test_package_xml_is_a_valid_manifest():
    catkin_pkg = pytest.importorskip("catkin_pkg.package")
    package = catkin_pkg.parse_package(os.path.join(REPO, "package.xml"))
    package.validate()
    assert package.name == "locem_bridge"
    assert "message_generation" in [d.name for d in package.build_depends]


@pytest.mark.parametrize("path", LAUNCH_FILES, ids=[os.path.basename(p) for p in LAUNCH_FILES])
def test_every_launch_argument_is_documented(path):
    root = ET.parse(path).getroot()
    assert root.tag == "launch"
    undocumented = [a.get("name") for a in root.iter("arg") if a.get("value") is None and not a.get("doc")]
    assert not undocumented, "%s: arguments without doc=: %s" % (os.path.basename(path), undocumented)
