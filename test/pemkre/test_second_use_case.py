"""A new use case is modelled, not programmed: a tile-inspection loop defined only in Turtle runs unchanged."""
import os

from pemkre_testkit import run_process

from locem_bridge.pemkre import compute_kpis
from locem_bridge.pemkre.ontology import default_ontology_dir

DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data")


def test_tile_inspection_loop_runs_from_turtle_alone(make_engine):
    files = [os.path.join(default_ontology_dir(), "process.ttl"),
             os.path.join(DATA, "tile_inspection.ttl"), os.path.join(DATA, "tile_site.ttl")]
    e = make_engine(ontology_files=files)
    assert e.processes() == ["https://example.org/tiles#InspectionProcess"]
    e.start_process("https://example.org/tiles#InspectionProcess")
    defects = {"tile_b", "tile_d"}

    def decide(a):
        if a.action_type == "INSPECT_TILE":
            return "succeeded", "defect" if a.params()["tile"] in defects else "ok"
        return "succeeded", ""
    seen = run_process(e, decide)
    assert seen == [("INSPECT_TILE", {"tile": "tile_a"}), ("INSPECT_TILE", {"tile": "tile_b"}),
                    ("REPLACE_TILE", {"tile": "tile_b"}), ("INSPECT_TILE", {"tile": "tile_c"}),
                    ("INSPECT_TILE", {"tile": "tile_d"}), ("REPLACE_TILE", {"tile": "tile_d"}),
                    ("INSPECT_TILE", {"tile": "tile_e"}), ("PARK_ROBOT", {"robot": "rover"}),
                    ("ENDED", {"message": "all tiles inspected"})]
    states = {str(r["tile"]).rsplit("/", 1)[1]: str(r["state"]).rsplit("#", 1)[1]
              for r in e.query("tile_states").rows}
    assert states == {"tile_a": "good", "tile_b": "replaced", "tile_c": "good", "tile_d": "replaced", "tile_e": "good"}
    kpis = {r["actionType"]: r for r in compute_kpis(e)["task_types"]}
    assert kpis["REPLACE_TILE"]["manualFallbacks"] == 2 and kpis["INSPECT_TILE"]["count"] == 5
    assert e.check_consistency(full_inference=True) == []
