"""docs/locem_api.md is generated from the registry; it must never go stale."""
import os

from locem_bridge.locem import apidoc
from locem_bridge.locem.catalogue import all_specs

DOC = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "docs", "locem_api.md")


def test_api_documentation_is_up_to_date():
    with open(DOC, encoding="utf-8") as handle:
        current = handle.read()
    assert current == apidoc.render(all_specs()), \
        "docs/locem_api.md is stale: run python3 -m locem_bridge.locem.apidoc --write"


def test_every_declared_command_and_argument_is_documented_with_units_and_ranges():
    text = apidoc.render(all_specs())
    for spec in all_specs():
        assert "### %s" % spec.name in text and spec.usage in text
        for arg in spec.args:
            assert arg.allowed() in text


def test_check_mode_detects_a_stale_file(tmp_path):
    stale = tmp_path / "api.md"
    stale.write_text("old")
    assert apidoc.main(["--check", "--path", str(stale)]) == 1
    assert apidoc.main(["--write", "--path", str(stale)]) == 0
    assert apidoc.main(["--check", "--path", str(stale)]) == 0
