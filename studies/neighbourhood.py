"""Neighbourhood size (9x9, 11x11) crossed with 1/8 vs 8/8 up-sampling.

Usage: python studies/neighbourhood.py [--quick] [--out DIR] [--scheduler ADDRESS|local|serial] ...
(the same as 'npmrf3d study neighbourhood ...'; --help lists every option). See studies/README.md.
"""

import pathlib
import sys

try:
    import npmrf3d  # noqa: F401
except ImportError:  # running from a source checkout that is not installed
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from npmrf3d.studies.cli import study_main

if __name__ == "__main__":
    sys.exit(study_main("neighbourhood"))
