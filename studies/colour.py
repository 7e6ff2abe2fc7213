"""Colour exemplars with annealing and ML_H2b.

Usage: python studies/colour.py [--quick] [--out DIR] [--scheduler ADDRESS|local|serial] ...
(the same as 'npmrf3d study colour ...'; --help lists every option). See studies/README.md.
"""

import pathlib
import sys

try:
    import npmrf3d  # noqa: F401
except ImportError:  # running from a source checkout that is not installed
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from npmrf3d.studies.cli import study_main

if __name__ == "__main__":
    sys.exit(study_main("colour"))
