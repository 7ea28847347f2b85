"""Integrator tests: the HICEM test doubles (test/hicem) importable here (pytest runs with --import-mode=importlib)."""
import os
import sys

_HICEM = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "hicem")
if _HICEM not in sys.path:
    sys.path.insert(0, _HICEM)
