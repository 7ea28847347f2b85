"""``python -m locem_bridge.skills export --robot FILE [--trees DIR ...] [--ontologies FILE ...] --out FILE.ttl``

Writes the robot's generated resource model as Turtle. The file imports ``skill.ttl``, ``ppr.ttl`` and the ontologies
declaring its capabilities (``plasterboard.ttl``) by IRI;
a Protégé catalog (``catalog-v001.xml``) written beside it maps those IRIs (and the other shipped ontologies') to
the files, so Protégé opens it without a network. A bad robot file, command declaration or tree declaration
prints one line ``FILE: KEY: PROBLEM`` and exits 2; nothing is written then.
"""
import argparse
import os
import sys
from typing import List, Optional
from xml.sax.saxutils import quoteattr

from rdflib import Graph
from rdflib.namespace import OWL, RDF

from .build import build_resource_model, default_tree_dirs
from .errors import SkillModelError

CATALOG = "catalog-v001.xml"


def _catalog(ontology_files: List[str]) -> str:
    rows = []
    for path in ontology_files:
        g = Graph().parse(path, format="turtle")
        for onto in g.subjects(RDF.type, OWL.Ontology):
            rows.append('  <uri name=%s uri=%s/>' % (quoteattr(str(onto)), quoteattr("file://" + os.path.abspath(path))))
    return ('<?xml version="1.0" encoding="UTF-8" standalone="no"?>\n'
            '<catalog prefer="public" xmlns="urn:oasis:names:tc:entity:xmlns:xml:catalog">\n%s\n</catalog>\n'
            % "\n".join(sorted(rows)))


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m locem_bridge.skills",
                                     description="The robot's resource model (skills, capabilities, devices, tools).")
    sub = parser.add_subparsers(dest="command")
    exp = sub.add_parser("export", help="write the resource model of a robot file as Turtle")
    exp.add_argument("--robot", required=True, help="robot file (config/robots/*.yaml)")
    exp.add_argument("--trees", action="append", default=[], metavar="DIR",
                     help="folder of action trees (repeatable; default: the shipped trees/)")
    exp.add_argument("--ontologies", action="append", default=None, metavar="FILE",
                     help="ontology file declaring capabilities and tool classes (repeatable; default: the shipped "
                          "ontologies/*.ttl)")
    exp.add_argument("--out", required=True, help="Turtle file to write")
    exp.add_argument("--no-catalog", action="store_true", help="do not write catalog-v001.xml beside the file")
    args = parser.parse_args(argv)
    if args.command != "export":
        parser.print_help()
        return 2
    try:
        model = build_resource_model(args.robot, args.trees or default_tree_dirs(), ontology_files=args.ontologies)
    except SkillModelError as exc:
        print(exc.one_line(), file=sys.stderr)
        return 2
    text = model.to_graph().serialize(format="turtle")
    out = os.path.abspath(args.out)
    os.makedirs(os.path.dirname(out), exist_ok=True)
    with open(out, "w", encoding="utf-8") as handle:
        handle.write(text if isinstance(text, str) else text.decode("utf-8"))
    if not args.no_catalog:
        from ..pemkre.ontology import default_ontology_files
        with open(os.path.join(os.path.dirname(out), CATALOG), "w", encoding="utf-8") as handle:
            handle.write(_catalog(list(args.ontologies or default_ontology_files())))
    offered = model.offered_skills()
    print("%s: %d skills (%d basic, %d composite; %d offered), %d devices, %d tools -> %s"
          % (model.robot_name, len(model.skills()), len(model.basic_skills), len(model.composite_skills),
             len(offered), len(model.devices), len(model.tools), out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
