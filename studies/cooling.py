"""ICM cooling, xi = -1 vs -3 and full vs 95 % stop, with global temperature curves.

Usage: python studies/cooling.py [--quick] [--out DIR] [--scheduler ADDRESS|local|serial] ...
(the same as 'npmrf3d study cooling ...'; --help lists every option). See studies/README.md.
"""

import pathlib
import sys

try:
    import npmrf3d  # noqa: F401
except ImportError:  # running from a source checkout that is not installed
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from npmrf3d.studies.cli import study_main

if __name__ == "__main__":
    sys.exit(study_main("cooling"))
