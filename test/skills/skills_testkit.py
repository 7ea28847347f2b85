"""Paths of the shipped robot file and trees, shared by the resource-model tests."""
import os

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ROBOT = os.path.join(REPO, "config", "robots", "rbkairos_ur10e.yaml")
TREES = os.path.join(REPO, "trees")
ONTOLOGIES = os.path.join(REPO, "ontologies")
